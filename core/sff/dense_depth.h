// A dense depth map from the confident measurements and the all-in-focus image: the
// confidence-weighted, edge-aware least-squares fit that variational depth from focus solves,
// by OpenCV contrib's Fast Global Smoother (Min et al. 2014, cv::ximgproc) with one guide applied
// to weighted moments of the measured depth (w = the confidence of the measured pixels, 0
// elsewhere). FGS is a linear filter with positive weights K(p, q) that fall with the guide's
// colour difference along the path from p to q, so the normalised filter F(w d) / F(w) is the
// weighted mean of the measured depths around p with weights K(p, q) w_q: depth spreads along a
// surface of one colour and stops at an edge of the image.
//
// Local planes (local_planes): the same weights fit d = a + b (x - x_p) + c (y - y_p) at every p
// (nine filtered moments, a 3 x 3 solve per pixel) and a is the depth at p. A constant model
// flattens a sloped surface across an untextured hole and extrapolates a surface that leaves the
// measured area (sky, walls, a receding ground plane) as the value at its rim; the plane carries
// the slope of the surrounding measurements into the hole.
//
// Robust fit (robust_iterations): measured depths that disagree with the fit (a wrong peak on a
// weakly textured patch, a halo next to an occlusion edge) are down-weighted by a Cauchy weight of
// their residual and the fit is repeated (iteratively reweighted least squares), so that a few
// outliers do not smear over a region; after the last fit a measured depth whose residual exceeds
// the Cauchy scale is replaced by the fit and counted as inferred (without it: reject_scale).
//
// For imported stacks (photography), where a user expects a value at every pixel. Measured vs
// inferred stays readable from the confidence map: an inferred pixel is one whose confidence is
// below the post-processing's min_confidence (core/sff/depth_postprocess.h). Measured pixels keep
// their measured depth (keep_measured) unless the caller asks for the fitted value everywhere.
// Pixels the filter's support does not reach (weight sum below 1e-6 of the largest) are filled by
// the guided push-pull (core/sff/depth_fill.h).
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"

namespace inspection {

// Defaults: the best of a grid (lambda 1024/4096/16384 x sigma 4/8 x constant/planes x fallback
// 0/0.1/0.3/0.5/1) by RMSE at full coverage on the tuning scenes of natural-evaluate --held-out 8
// (seeds 1-8, colour guide), reported on seeds 9-16 and 101-108 (tests/bench/natural_heldout_output.md,
// docs/import-stacks.md). Robust reweighting, halo suppression and keep_measured = false were
// tried there too and stay off (no better, or within 1 %). The outlier rejection (reject_scale)
// came later, from the per-scene diagnosis of natural-evaluate --diagnose.
struct DenseDepthOptions {
  // FGS smoothness weight: larger spreads measured depth further across untextured regions.
  double lambda = 4096.0;
  // Guide colour difference (8-bit levels) at which smoothing across an edge is attenuated.
  double sigma_color = 4.0;
  // Fallback: a second, weakly edge-aware fit (guide colour scale fallback_sigma_color) takes
  // over where the edge-aware one has little support relative to it: with r = F(w) / F_wide(w)
  // (about 1 wherever measurements are spread alike for both, sparse or dense; near 0 inside a
  // region that guide edges wall off from every measurement), fit = t edge + (1 - t) fallback,
  // t = r^2 / (r^2 + fallback_support^2). Such a region (sky, a wall, untextured paint) would
  // otherwise take the depth of whichever neighbour's edge is weakest. 0: off.
  double fallback_support = 0.3;
  double fallback_sigma_color = 32.0;
  // Flat segments (with the fallback on): connected pixels of the guide whose grey gradient stays
  // below segment_gradient levels per pixel, covering at least segment_min_fraction of the map,
  // each get one plane fitted (Cauchy-weighted) to the measurements on and within
  // segment_band_px of them; on a segment the plane stands in for the fallback fit
  // (segment_override: for the edge-aware one too).
  bool segment_planes = false;
  double segment_gradient = 1.5;
  int segment_band_px = 2;
  double segment_min_fraction = 0.002;
  bool segment_override = false;
  // Measured pixels keep their measured depth (unless rejected by the robust fit); false: every
  // pixel gets the fitted value.
  bool keep_measured = true;
  // Fit a local plane instead of a local constant.
  bool local_planes = true;
  // Ridge on the plane's slope: the slope is shrunk as if the support had at least this radius
  // of measurements (pixels); keeps a plane fitted to a thin strip of measurements from tilting.
  double plane_ridge_px = 8.0;
  // Halo suppression: a measured pixel's weight is scaled by its own guide texture (gradient
  // energy over 3 x 3) relative to the strongest within this radius, so that a flat pixel that
  // took its depth from a sharp edge inside its focus window (the foreground's depth spread onto
  // the background beside it) counts little. 0: off. About the focus window's half width.
  int halo_radius_px = 0;
  // Reweighting passes of the robust fit (0: plain weighted least squares).
  int robust_iterations = 0;
  // Cauchy scale of the robust weights in robust standard deviations (1.4826 x median absolute
  // residual of the measured pixels, at least 1e-3 of the measured depth range); also the residual
  // above which a measured depth is replaced by the fit.
  double robust_scale = 3.0;
  // Without the robust fit (robust_iterations 0): a measured depth whose residual to the
  // edge-aware fit exceeds reject_scale robust standard deviations (1.4826 x the median absolute
  // residual of the measured pixels, as robust_scale's) is an outlier: replaced by the fit and
  // counted as inferred (keep_rejected_depth: keeps its depth, still counted as inferred). The fit
  // itself is not reweighted. 0: off. Default 12, chosen on the tuning scenes (seeds 1-8) of
  // natural-evaluate --experiments among 1.5..20: there the measured pixels' gross errors (a
  // flat pixel next to texture measured at the texture's depth, most of them in untextured
  // regions) otherwise lead the confidence ranking (RMSE over the most confident half 1.690 ->
  // 1.268 frames, at full coverage 3.981 -> 3.931; tests/bench/natural_heldout_output.md).
  double reject_scale = 12.0;
  bool keep_rejected_depth = false;
  // Solve grid: the fit runs on a grid reduced k times in each direction and is brought back by
  // joint bilateral upsampling with the full-resolution guide (measured pixels keep their
  // depth). 0 = auto: the smallest k of 1, 2, 4, 8 whose grid has at most auto_solve_max_pixels
  // (1 at 256 x 256 and 400 x 300, 4 at 1600 x 1200), so that the cost stays a few tens of
  // milliseconds at camera size; smoothness and ridge are scaled to the same reach in
  // full-resolution pixels.
  int solve_downscale = 0;
  double auto_solve_max_pixels = 200000.0;
  // Joint bilateral upsampling: guide colour difference (8-bit levels) between a pixel and a
  // solve-grid block's mean at which that block's fit counts e^-0.5 as much.
  double upsample_sigma_color = 8.0;

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

struct DenseDepth {
  cv::Mat depth_um;  // CV_32FC1, finite at every pixel (all NaN when nothing was measured)
  cv::Mat inferred;  // CV_8UC1: 255 where depth_um is the fit's (unmeasured or rejected), 0 where measured
  // CV_32FC1 in [0, 1]: the fit's measured weight at the pixel, F(w): near 1 amid confident
  // measurements, falling with the distance (along the guide) to them.
  cv::Mat support;
  // CV_32FC1 in [0, 1]: the Cauchy weight of a measured pixel's residual r to the (edge-aware)
  // fit, 1 / (1 + (r / scale)^2), scale as robust_scale's; 0 where nothing was measured.
  cv::Mat agreement;
  // CV_32FC1, depth units: how much the measured depths that the edge-aware fit draws on at the
  // pixel disagree with its local model there (their weighted RMS residual about the local plane,
  // or constant: sqrt(F(w (d - model)^2) / F(w))). Small amid one surface; large where the fit
  // mixes surfaces at different depths (an untextured region between them), so its value there
  // is uncertain. 0 where nothing was measured at all.
  cv::Mat spread_um;
};

// depth_um: CV_32FC1, NaN = not measured. confidence: CV_32FC1 (empty: all measured pixels
// weight 1). guide: the all-in-focus image (8/16-bit or float in [0, 1], 1 or 3 channels) of the
// same size.
StatusOr<DenseDepth> DensifyDepthWithSupport(const cv::Mat& depth_um, const cv::Mat& confidence,
                                             const cv::Mat& guide, const DenseDepthOptions& options);

// The solve grid's reduction factor k for a depth map of `size` (DenseDepthOptions::solve_downscale).
int DenseSolveDownscale(const cv::Size& size, const DenseDepthOptions& options);

// DensifyDepthWithSupport's depth map alone.
StatusOr<cv::Mat> DensifyDepth(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& guide,
                               const DenseDepthOptions& options);

}  // namespace inspection
