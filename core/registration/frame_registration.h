// Registration of one stack frame to another (lateral alignment before the focus
// measure of thesis 3.1.3): a similarity transform (scale, small rotation, translation) found by
// Gauss-Newton intensity alignment on an image pyramid, started from phase correlation.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/util/status.h"

namespace inspection {

// p_frame = c + scale * R(rotation_rad) * (p_reference - c) + (shift_x_px, shift_y_px), with c
// the centre of scale and rotation (the image centre unless said otherwise).
struct SimilarityTransform {
  double scale = 1.0;
  double rotation_rad = 0.0;
  double shift_x_px = 0.0;
  double shift_y_px = 0.0;
};

// The 2x3 matrix mapping reference pixels to frame pixels (cv::warpAffine with
// WARP_INVERSE_MAP takes it to resample the frame onto the reference grid).
cv::Matx23d FrameFromReference(const SimilarityTransform& t, cv::Point2d centre_px);
// The similarity part of an affine matrix about centre_px (scale and rotation from the mean of
// the rotation-like components: exact for a similarity).
SimilarityTransform SimilarityOf(const cv::Matx23d& frame_from_reference, cv::Point2d centre_px);
// a after b: p -> a(b(p)).
cv::Matx23d Compose(const cv::Matx23d& a, const cv::Matx23d& b);
cv::Matx23d Invert(const cv::Matx23d& m);

struct FrameRegistrationOptions {
  // The finest level the alignment runs on has at most this many pixels on its longer side:
  // sub-pixel accuracy there is still ~0.1 px of the full frame, at a quarter of the cost.
  int max_side_px = 512;
  int pyramid_levels = 3;  // 1..5; each level halves the size
  // Gaussian pre-smoothing (sigma in pixels of each level): frames at different defocus differ
  // in their finest detail; what they share is the coarser structure.
  double smoothing_sigma_px = 1.0;
  int max_iterations = 40;       // per level
  double convergence_px = 0.01;  // stop when the update moves no corner by more than this
  double min_correlation = 0.5;  // zero-mean NCC after alignment; below = not registered
  // The AVX2 kernel for the Gauss-Newton sums where the CPU has AVX2 and FMA (float lanes per
  // row; transforms agree with the portable double loop to ~1e-6 px); false: the portable loop.
  bool use_simd = true;
  Status Validate() const;
};

struct FrameRegistration {
  SimilarityTransform transform;  // reference -> frame, about the image centre
  double correlation = 0.0;       // zero-mean NCC of the aligned pair at the finest level
  int iterations = 0;             // Gauss-Newton iterations over all levels
};

// reference and frame: CV_8UC1 or CV_16UC1 (or CV_32FC1), same size, at least 32 x 32 px.
// INVALID_ARGUMENT for bad input; FAILED_PRECONDITION when the alignment does not converge or
// its correlation stays below min_correlation (e.g. a featureless or unrelated frame) - the
// message says which.
StatusOr<FrameRegistration> RegisterFrame(const cv::Mat& reference, const cv::Mat& frame,
                                          const FrameRegistrationOptions& options);

// RegisterFrame in two steps, for frames that take part in several registrations (each frame of
// a stack is registered to both neighbours): the working images of one frame (standardised,
// shrunk to max_side_px, smoothed pyramid), then the alignment of two such pyramids. The result
// is RegisterFrame's bit for bit; preparing a frame is most of a registration's cost.
struct RegistrationPyramid {
  cv::Size frame_size;          // of the frame it was prepared from
  std::vector<cv::Mat> levels;  // CV_32FC1, finest (the working size) first
};
StatusOr<RegistrationPyramid> PrepareRegistration(const cv::Mat& frame, const FrameRegistrationOptions& options);
// Both prepared with these options from frames of one size (else INVALID_ARGUMENT).
StatusOr<FrameRegistration> RegisterPyramids(const RegistrationPyramid& reference, const RegistrationPyramid& frame,
                                             const FrameRegistrationOptions& options);

}  // namespace inspection
