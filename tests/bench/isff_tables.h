// The integral SFF evaluation of thesis 6.4 on the simulated rig (Table 6.8, Table 6.9, Fig. 6.17,
// calibration and reconstruction times), printed by isff-evaluate and inspect-evaluate.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>

namespace inspection {

struct IsffTablesOptions {
  cv::Size camera_size{512, 384};  // the projector is sized to light the whole field
  uint64_t seed = 5;
  int repeats = 7;  // alternating timing runs per ISFF-FAST threshold (Table 6.9), medians
};

// Calibrates, scans and prints everything to stdout; false (and a line on stderr) when the rig,
// a calibration or a scan fails.
bool PrintIsffTables(const IsffTablesOptions& options);

}  // namespace inspection
