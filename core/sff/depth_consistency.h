// Local depth consistency: a confidence from the neighbourhood, not the pixel alone. Thesis 3.1.3
// sums focus over a window U that is assumed to lie on one surface, and 6.3 counts outliers as
// depth jumps between neighbours. Here, in the (2 radius + 1)^2 window around each pixel, the
// depths of all pixels (the engine's depth before any confidence threshold) are fitted by a
// least-squares plane; the residual standard deviation is small where the window lies on one
// textured surface (the neighbours' focus peaks agree up to the slope, which the plane absorbs, so
// steep flanks pass), and large where the window straddles a depth discontinuity (the focus
// window mixes two surfaces: the halo beside occluding edges of natural scenes, the
// see-through of a defocused edge) or covers textureless area (each pixel's peak is noise,
// whatever its own signal-to-noise ratio says).
//
// Evaluated on natural focal stacks (tests/bench/natural_evaluate.cc): rejecting pixels whose
// residual exceeds 1 z step, with the window one pixel wider than the focus window, cut the
// RMSE of Tenengrad 11x11 from ~5.9 to ~0.7 frames at 43 % coverage (from 79 %).
//
// Window mixing: the plane check passes a smooth but wrong transition. Beside a steep
// flank the focus window's energy is often dominated by one strong edge away from the pixel (a
// clipped or bright border next to a dark flank), and the pixel gets that edge's depth: the
// measured map is a smooth ramp, displaced. To first order a pixel's depth is the true depth at
// the centroid of the focus energy in its window, so its error is slope . offset, with the slope
// from the same local plane and the offset of the energy centroid measured on the all-in-focus
// image (its squared Sobel gradient, the Tenengrad of the frames at focus). Pixels where that
// estimate exceeds max_window_mixing_z_steps lose their depth. On a level surface or with the
// energy centred it is ~0, so textured parts keep their pixels. Measured (docs/reconstruction.md "Depth
// post-processing"): on the coin (20 um relief, dark 80 degree flanks) the HF+ADAPT bias went
// from -0.62 to +0.04 um and its RMSE from 2.79 to 0.80 um at 88 % instead of 97 % valid; the
// natural scenes' RMSE from 1.70 to 1.49 frames at 37.2 % instead of 37.5 % coverage; on the
// chamfer's 45 degree flank STD went from 0.59 to 0.49 um at 98.7 % valid, and the other textured
// microscope specimens moved by <= 0.001 um.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/util/status.h"

namespace inspection {

struct DepthConsistencyOptions {
  // Window (2 radius_px + 1)^2; 0 = focus window / 2 + 1 (DefaultConsistencyRadius), i.e. the
  // focus window plus one pixel on each side. 1..31.
  int radius_px = 0;
  // Pixels whose residual exceeds this many z steps lose their depth. > 0.
  double max_residual_z_steps = 1.0;
  // Pixels whose estimated window-mixing error |slope . energy offset| exceeds this many z steps
  // lose their depth (needs the all-in-focus image); 0 = off. 0.25 cut more (coin RMSE 0.70 um
  // at 85 % valid, natural scenes 1.31 frames at 36.8 %) but also 2 % of the chamfer's flank.
  double max_window_mixing_z_steps = 0.5;

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

inline int DefaultConsistencyRadius(int focus_window_px) { return focus_window_px / 2 + 1; }

// Residual standard deviation (depth units) of raw_depth_um (CV_32FC1) about the least-squares
// plane in the window around each pixel (window mirrored at the image border like the focus
// measures). +inf where the window holds a NaN. CV_32FC1.
StatusOr<cv::Mat> LocalDepthResidual(const cv::Mat& raw_depth_um, int radius_px);

// The same fit with its slopes (depth units per pixel; NaN where the window holds a NaN).
struct LocalDepthPlane {
  cv::Mat residual_um;  // CV_32FC1, as LocalDepthResidual
  cv::Mat slope_x;      // CV_32FC1
  cv::Mat slope_y;      // CV_32FC1
};
Status FitLocalDepthPlanes(const cv::Mat& raw_depth_um, int radius_px, LocalDepthPlane* plane);

// Where in its focus window a pixel's focus energy sits: the offset (px, CV_32FC2: x, y) of the
// centroid of the all-in-focus image's squared Sobel gradient over the focus_window_px window
// (odd, >= 3). 0 where the window holds no gradient. all_in_focus: grey or BGR (its luminance
// is used), any depth; the offset does not depend on its scale.
StatusOr<cv::Mat> FocusEnergyCentroidOffset(const cv::Mat& all_in_focus, int focus_window_px);

// depth_um with NaN also where the local residual of raw_depth_um exceeds
// max_residual_z_steps * z_step_um, and, when all_in_focus (the engine's, same size) is given,
// where the window-mixing estimate exceeds max_window_mixing_z_steps * z_step_um.
// raw_depth_um: the same engine run's depth without a confidence threshold
// (SffOptions::min_confidence = 0); depth_um: its thresholded depth (or raw_depth_um itself).
// focus_window_px resolves radius_px = 0. z_step_um > 0 (MedianZStep of the stack).
StatusOr<cv::Mat> RejectInconsistentDepth(const cv::Mat& depth_um, const cv::Mat& raw_depth_um, double z_step_um,
                                          int focus_window_px, const DepthConsistencyOptions& options,
                                          const cv::Mat& all_in_focus = cv::Mat());

// Median of |z[k+1] - z[k]|; 0 for fewer than two values.
double MedianZStep(const std::vector<double>& z_um);

}  // namespace inspection
