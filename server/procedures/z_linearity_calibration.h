// The z-linearity calibration step (core/metrology/z_linearity.h): a smooth tilted flat scanned
// through z at the step scans use, reconstructed with the default SFF options, and the depth's
// periodic error between frames tabulated. Measurement uncertainties then use this table
// instead of the +-1/2 step peak-locking bound (core/metrology/depth_noise_model.h), which is safe but
// 2-20x too wide.
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/sff/sff_options.h"
#include "core/util/status.h"
#include "core/metrology/z_linearity.h"

namespace inspection {

struct ZLinearityScan {
  ZLinearity linearity;
  int frames = 0;
  double valid_percent = 0.0;  // of the field, the pixels the table was fitted on
};

// Captures a frame at each of z_um (ascending or descending, >= 3, the scan step) through
// `capture_at`, reconstructs the depth with `sff` and characterises the linearity on the valid
// pixels away from the focus window's border. FAILED_PRECONDITION when the flat is not tilted
// enough for its heights to span a z step (a bin stays empty), naming the bin.
StatusOr<ZLinearityScan> ScanZLinearity(const std::function<StatusOr<cv::Mat>(double z_um)>& capture_at,
                                        const std::vector<double>& z_um, double pixel_size_um, const SffOptions& sff,
                                        const std::string& source);

}  // namespace inspection
