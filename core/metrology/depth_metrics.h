// Depth accuracy against a reference (thesis 6.1.3: standard deviation of the height
// difference; 6.2: outlier percentage). Used for simulated ground truth and evaluations.
#pragma once

#include <opencv2/core.hpp>

namespace inspection {

struct DepthErrorStats {
  size_t compared_pixels = 0;    // finite in both maps
  double valid_percent = 0.0;    // share of measured pixels with finite depth
  double mean_error_um = 0.0;    // measured - reference
  double stddev_error_um = 0.0;  // thesis Table 6.3's sigma
  double rmse_um = 0.0;
  double mean_abs_error_um = 0.0;
  double outlier_percent = 0.0;  // |error| > outlier_threshold_um, among compared pixels
};

// depth_um, reference_um: CV_32FC1 of equal size; NaN = no value. border_px pixels at each edge
// are left out (focus windows there see the image border).
DepthErrorStats CompareDepth(const cv::Mat& depth_um, const cv::Mat& reference_um, double outlier_threshold_um,
                             int border_px = 0);
// The same on a footprint: only pixels where mask (CV_8UC1, same size) is non-zero count, e.g.
// the pixels several methods all measured, so one that leaves hard pixels empty gains nothing.
DepthErrorStats CompareDepth(const cv::Mat& depth_um, const cv::Mat& reference_um, const cv::Mat& mask,
                             double outlier_threshold_um, int border_px = 0);

// Thesis 6.3's outlier measure, which needs no reference ("a significant change in depth between
// consecutive pixels"), made robust: the percentage of measured pixels (outside border_px) whose
// depth differs by more than jump_threshold_um from the median of their measured 8-neighbours
// (at least 3 of them). A lone spike counts once, and the pixels along a true step of the
// surface do not count, since most of their neighbours lie on their own side. 0 when nothing is
// measured.
double LocalOutlierPercent(const cv::Mat& depth_um, double jump_threshold_um, int border_px = 0);

// Min and max over finite values; {NaN, NaN} when there are none.
std::pair<double, double> FiniteRange(const cv::Mat& depth_um);

}  // namespace inspection
