// Confidence-aware depth refinement guided by the all-in-focus image: post-processing of the
// SFF depth map (thesis 3.1.4 interpolates each pixel alone; here neighbours that the
// confidence trusts and that look alike in the all-in-focus image vote). Depth edges of natural
// scenes follow colour edges, while the focus window smears them by its half-width, and single
// pixels with a spurious focus peak disagree with similar-looking neighbours.
//
//  kWeightedMedian  per measured pixel p, the weighted median of the measured depths d(q) in the
//                   (2 radius_px + 1)^2 window, weights w(q) = confidence(q) *
//                   exp(-|g(p) - g(q)|^2 / (2 guide_sigma^2)), g the guide scaled to [0, 1] per
//                   channel. Edge-preserving, robust to outliers, never invents a depth that no
//                   neighbour measured.
//  kGuidedFilter    He et al.'s guided filter with confidence weights: in every window a
//                   confidence-weighted least-squares fit d ~ a g + b on the luminance g of the
//                   guide (regulariser guided_filter_eps on a), the fits averaged over the
//                   windows covering p (weighted by their confidence mass). O(pixels) with box
//                   sums; smoother than the median, sub-step values.
//
// Pixels without depth (NaN) stay NaN: refinement does not fill (core/sff/depth_fill.h does).
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"

namespace inspection {

enum class DepthRefinement { kNone, kWeightedMedian, kGuidedFilter };

const char* DepthRefinementName(DepthRefinement r);  // "none", "weighted-median", "guided-filter"
StatusOr<DepthRefinement> ParseDepthRefinement(const std::string& name);

struct DepthRefinementOptions {
  DepthRefinement method = DepthRefinement::kWeightedMedian;
  int radius_px = 4;  // window side 2 radius_px + 1; 1..31
  // Weighted median: the window is sampled every sample_step_px pixels in x and y (0 = auto:
  // max(1, radius_px / 4), so a wide window costs no more than ~81 samples per pixel).
  int sample_step_px = 0;
  int iterations = 1;               // passes, each on the previous result; 1..5
  double guide_sigma = 0.06;        // weighted median: guide difference (fraction of full scale) of weight e^-1/2; > 0
  double guided_filter_eps = 1e-3;  // guided filter: regulariser (guide variance units, guide in [0, 1]); > 0
  int threads = 0;                  // 0 = OpenCV's default parallelism

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

// depth_um: CV_32FC1, NaN = no depth. confidence: CV_32FC1 in [0, 1] of the same size (weights;
// NaN or negative counts as 0), or empty for equal weights. guide: the all-in-focus image of the
// same size, CV_8U or CV_16U, 1 or 3 channels (a colour guide separates equal-luminance colours).
// Returns the refined depth (CV_32FC1), NaN exactly where depth_um is NaN.
StatusOr<cv::Mat> RefineDepth(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& guide,
                              const DepthRefinementOptions& options);

// The guide as float in [0, 1] per channel (CV_32FC1 or CV_32FC3); shared by refinement and fill.
StatusOr<cv::Mat> NormalisedGuide(const cv::Mat& guide, cv::Size expected_size);

}  // namespace inspection
