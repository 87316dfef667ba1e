// Per-frame grey-value statistics reported in scan progress events, so that a user sees
// saturation and under-exposure (thesis 4.1, Fig. 4.1) and watches compensation converge.
#pragma once

#include <opencv2/core.hpp>

namespace inspection {

struct FrameStatistics {
  double mean_grey = 0.0;             // in 8-bit units (0..255) whatever the bit depth
  double stddev_grey = 0.0;           // in 8-bit units
  double saturated_percent = 0.0;     // share of pixels at the sensor maximum (2^bit_depth - 1)
  double underexposed_percent = 0.0;  // share of pixels below 2 % of full scale
};

// frame: CV_8UC1 or CV_16UC1; bit_depth: significant bits (8..16); a CV_16UC1 frame with
// bit_depth 8 (not stated) is taken at 16.
FrameStatistics ComputeFrameStatistics(const cv::Mat& frame, int bit_depth);

}  // namespace inspection
