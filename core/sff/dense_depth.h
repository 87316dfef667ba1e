// A dense depth map from the confident measurements and the all-in-focus image: the
// confidence-weighted, edge-aware least-squares fit that variational depth from focus solves,
// by OpenCV contrib's Fast Global Smoother (Min et al. 2014, cv::ximgproc) applied twice with one
// guide: once to depth * w and once to w (w = the confidence of the measured pixels, 0
// elsewhere), divided. That normalised filter is the weighted least-squares solution of
//   min sum_p w_p (d_p - z_p)^2 + lambda sum_(p,q) a_pq (d_p - d_q)^2
// up to FGS's separable approximation, with a_pq falling with the guide's colour difference,
// so depth spreads along a surface of one colour and stops at an edge of the image.
//
// For imported stacks (photography), where a user expects a value at every pixel. Measured vs
// inferred stays readable from the confidence map: an inferred pixel is one whose confidence is
// below the post-processing's min_confidence (the consistency step sets rejected pixels to 0).
// Measured pixels keep their measured depth (keep_measured) unless the caller asks for the
// smoothed value everywhere. Pixels the filter's support does not reach (weight sum below
// 1e-6 of the largest) are filled by the guided push-pull (core/sff/depth_fill.h).
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"

namespace inspection {

struct DenseDepthOptions {
  // FGS smoothness weight: larger spreads measured depth further across untextured regions.
  // lambda and sigma_color: the best of a 5 x 3 grid by RMSE at full coverage on the tuning
  // scenes (natural-evaluate --scenes 16 --held-out 8, seeds 1-8), reported on seeds 9-16.
  double lambda = 4096.0;
  // Guide colour difference (8-bit levels) at which smoothing across an edge is attenuated.
  double sigma_color = 4.0;
  // Measured pixels keep their measured depth; false: every pixel gets the fitted value.
  bool keep_measured = true;

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

// depth_um: CV_32FC1, NaN = not measured. confidence: CV_32FC1 (empty: all measured pixels
// weight 1). guide: the all-in-focus image (8/16-bit or float in [0, 1], 1 or 3 channels) of the
// same size. Returns a depth map finite at every pixel (unchanged all-NaN map when nothing was
// measured).
StatusOr<cv::Mat> DensifyDepth(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& guide,
                               const DenseDepthOptions& options);

}  // namespace inspection
