// Line profiles across a depth map (ISO 25178-2's extracted profile, for plots and profile
// checks): heights sampled along a segment between two points, averaged over a band of given
// width across it, returned as data (position along the line, height, its uncertainty).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/metrology/depth_noise_model.h"
#include "core/util/status.h"
#include "core/metrology/surface_roi.h"

namespace inspection {

struct LineProfileOptions {
  RoiPoint start;  // image coordinates (core/metrology/surface_roi.h), in `unit`
  RoiPoint end;
  RoiUnit unit = RoiUnit::kPixel;
  // Width of the averaging band across the line, px (>= 1, <= 1001): heights are averaged over
  // cross samples 1 px apart centred on the line (width 1 = the line itself).
  double width_px = 1.0;
  double spacing_px = 1.0;  // distance between samples along the line, px (0.1 .. 100)
  // INVALID_ARGUMENT naming `field` (e.g. "profiles[0]"): points outside the image, a line
  // shorter than one sample spacing, widths or spacings out of range, more than 100000 samples.
  Status Validate(cv::Size image_size, double pixel_size_um, const std::string& field) const;
};

struct LineProfile {
  std::vector<double> position_um;  // distance from `start` along the line
  std::vector<double> x_um, y_um;   // the sample's image coordinates
  std::vector<double> height_um;    // mean height over the band's cross samples with depth; NaN if none
  // Standard uncertainty of each height: correlated noise averaged over the band (box model of
  // core/metrology/depth_noise_model.h), plus the z-linearity table's rms and the stage term, which do not
  // average out across a band at one height. NaN without a noise model.
  std::vector<double> uncertainty_um;
  std::vector<int> cross_samples;  // how many of the band's cross samples had depth
  double length_um = 0.0;
  double coverage_percent() const;  // samples with a height, of all samples
};

// Samples bilinearly between pixel centres; a cross sample counts only where its (up to) four
// neighbouring pixels all have depth.
StatusOr<LineProfile> ExtractLineProfile(const cv::Mat& depth_um, double pixel_size_um,
                                         const LineProfileOptions& options, const DepthNoiseModel* noise,
                                         const std::string& field = "profile");

}  // namespace inspection
