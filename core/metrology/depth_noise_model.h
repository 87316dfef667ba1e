// Error model of an SFF depth map, for the uncertainty of every measurement
// (core/metrology/measurement_uncertainty.h). Three components, each from what the scan itself provides:
//
// 1. Random depth noise, per pixel, correlated over the focus window. The focus value of a
//    pixel is summed over the window U of eq. 3.12/3.14, so neighbouring depths share most of
//    their data: the error field is modelled as e(p) = sigma(p) (B * w)(p), w white unit noise,
//    B a window_px x window_px box normalised to unit energy; its autocorrelation is the
//    triangle (1 - |dx| / w)(1 - |dy| / w), which is what the simulated rig's depth errors show
//    (lags 1..8 at w = 7: 0.88 0.72 0.57 0.43 0.29 0.15 0.03 0.00; box: 0.86 0.71 0.57 0.43 0.29 0.14 0 0).
//    sigma(p) is estimated from the depth map itself: second differences at a lag L = window + 1
//    (beyond the correlation, so the three samples are independent and var = 6 sigma^2, while a
//    plane, and nearly any form at that scale, cancels), averaged over a neighbourhood, taking
//    the smaller of the x and y directions (a surface lay raises only one of them).
//    Why not the engine's confidence (core/sff/depth_interpolation.h, the focus peak's SNR against
//    its curve's second differences): on the simulated rig the depth error of confidently
//    measured pixels does not follow it (rms error 0.058 / 0.055 / 0.055 / 0.064 um for
//    confidence 0.4-0.5 / 0.6-0.7 / 0.7-0.8 / 0.8-0.9 on PLANE-NORM), because the curve's
//    second differences are dominated by its shape, not by noise; only its low range flags
//    outliers, and those raise the local second differences as well. Surfaces with genuine
//    structure at 1-3 windows in both directions make sigma conservative (too large).
// 2. z linearity (core/metrology/z_linearity.h): a bias b(f) * step that depends on each height's
//    fractional position f in the z grid. It is known in shape but its phase relative to a
//    given specimen's heights is treated as unknown: the model draws the table shifted by a
//    uniform phase. For a region at one height it is a common offset (it cancels in form and
//    roughness), for two heights (a step) it is not. Not characterised at the scan's step, the
//    table is a prior: for a three-point peak its interpolation's analytic error
//    (ZLinearity::UncharacterisedThreePointPeak), for the maximum / line fit the sawtooth.
// 3. Stage repeatability: each frame's z is off by a uniform +-r (devices: stage
//    repeatability), one independent error d_i per frame. A depth interpolated through three
//    samples (Gaussian eq. 3.30-3.34 or the defocus parabola: both the vertex of a parabola
//    fitted to a function exactly quadratic in z - h) takes, with x = (h - z_n) / step in
//    [-1/2, 1/2] from its nearest frame n (linearised, equal steps; independent of the curve's
//    width), e = a_-1 d_n-1 + a_0 d_n + a_+1 d_n+1 with
//      a_-1 = (2x - 1)(1 + x) / 2,  a_0 = -2 x^2,  a_+1 = (1 + 2x)(x - 1) / 2   (sum -1),
//    so a depth at a frame is moved by the mean of its neighbours' errors and one midway by the
//    mean of its two frames': the rms sensitivity is ~0.7, and neighbouring heights share two
//    frames, not one. Before, each depth took its nearest frame's error in full (sensitivity 1,
//    a staircase in height), which made curvature (radius) ~3.5x too uncertain: sphere radius
//    U 93 um against an RMS deviation of 13 um (tests/bench/uncertainty_evaluate_output.md).
//    three_point_peak = false (maximum or line fit) keeps the full nearest-frame error.
#pragma once

#include <cstdint>
#include <optional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "core/metrology/z_linearity.h"

namespace inspection {

// Instrument characteristics from an ISO 25178-600 verification of this rig (the server passes
// those of the rig's latest accepted verification, core/metrology/verification.h; see
// docs). Each is optional; where one is given it replaces the model's worst-case bound:
//  - linearity_deviation_um (l_z, um: largest |deviation| of the z response from linear):
//    where the z linearity is not characterised at the scan's step, the uncharacterised prior
//    (the three-point interpolation's analytic error, +-0.11 step, or the discrete maximum's
//    sawtooth of +-step/2 without a three-point peak) is scaled down to +-l_z (same shape,
//    verified size; never up).
//  - amplification (alpha_z) and amplification_u (its standard uncertainty): the height scale
//    is off by alpha_z - 1 (uncorrected: values are reported as measured) known to u, so every
//    height-scale value H (step height, Sa, Sq, Sp, Sv, Sz, flatness, volume) gets
//    u_alpha = sqrt(u^2 + (alpha_z - 1)^2) |H|. Without it the model has no amplification term:
//    the SFF's z scale is the stage's, whose scale error the verification measures.
//  - noise_um (N_M) and flatness_um (z_FLT) are carried but not used: the model's random term is
//    estimated on the specimen's own map (its texture sets it; N_M is that of the verification
//    flat), and the extremes' bound grows with the region's size, which z_FLT (one region of the
//    reference flat) does not follow.
// The server fills it from the last full verification under the active calibration
// (server/jobs/rig_verification.h VerifiedFrom, for scans and Type-1 studies): amplification =
// alpha_z.value, amplification_u = alpha_z.standard_uncertainty, linearity_deviation_um =
// l_z.value + 2 l_z.standard_uncertainty (a bound), noise_um = N_M, flatness_um = z_FLT.
struct VerifiedCharacteristics {
  std::optional<double> noise_um;                // N_M
  std::optional<double> amplification;           // alpha_z, dimensionless (1 = ideal)
  std::optional<double> amplification_u;         // standard uncertainty of alpha_z (needs amplification)
  std::optional<double> linearity_deviation_um;  // l_z
  // The stage step (um) at which l_z was determined; unset: unknown (applied at any step). l_z
  // applies at this step and at finer ones (its size in um kept, as a characterised linearity's
  // is: DepthNoiseOptions::linearity_step_tolerance), not at a coarser step, whose interpolation
  // error it does not bound.
  std::optional<double> linearity_step_um;
  std::optional<double> flatness_um;             // z_FLT
  // INVALID_ARGUMENT naming the field (negative or non-finite; amplification outside 0.5..2).
  Status Validate() const;
  // sqrt(u^2 + (alpha_z - 1)^2), 0 without amplification.
  double RelativeAmplificationUncertainty() const;
};

struct DepthNoiseOptions {
  int window_px = 7;                   // SffOptions::window_px of the reconstruction (1..63)
  std::vector<double> z_positions_um;  // the stack's frame positions (stack.json frames[].z_um), >= 2
  ZLinearity linearity = ZLinearity::Uncharacterised();
  double stage_repeatability_um = 0.0;  // +- bound of the uniform per-move error (simulated rig: 0.1)
  // The reconstruction's depth interpolation is a three-point vertex fit (kGaussian or
  // kDefocusParabola, the default) — see component 3; false for kMaximum / kLineFit (the server
  // leaves the default: it should set it from plan.sff.interpolation).
  bool three_point_peak = true;
  // Side of the neighbourhood the local sigma averages over; 0 = 8 windows (~64 independent
  // samples per direction, so sigma is known to ~10 %).
  int neighbourhood_px = 0;
  // A characterised linearity applies at its own step; at a finer step (by more than this share)
  // it is transferred keeping its bias in um (the interpolation error does not grow as the focus
  // curve is sampled more densely); at a coarser one the uncharacterised bound is used.
  double linearity_step_tolerance = 0.05;
  VerifiedCharacteristics verified;  // optional (see VerifiedCharacteristics)
  // INVALID_ARGUMENT naming the field.
  Status Validate() const;
};

struct DepthNoiseModel {
  cv::Mat sigma_um;              // CV_32FC1: random standard uncertainty of each measured pixel; NaN elsewhere
  double global_sigma_um = 0.0;  // the same over the whole mask (used where a neighbourhood has too few samples)
  // Largest single-pixel error the map plausibly holds: max |second difference| / 2 over the
  // mask (same directions as sigma). A lone spike of height A gives a second difference of -2A
  // at its centre, so this is A; for Gaussian noise it is ~1.2x the largest error (sqrt(6) / 2).
  // SFF depth errors have heavier tails than Gaussian (wrong-peak clusters), which a Gaussian
  // Monte Carlo misses: extremes use a bound instead (flatness this; Sp, Sv, Sz the map below).
  double extreme_error_um = 0.0;
  // The same bound per pixel (CV_32FC1, NaN outside the mask; empty when not estimated): how far
  // an error near p can move it, from the second differences around p less the surface's own
  // curvature at the lag's scale (their local mean). Where no second difference reaches p (or the
  // region was too small), extreme_error_um. Never above extreme_error_um. Extremes use it with
  // each pixel's height (ExtremeErrorUm, core/metrology/measurement_uncertainty.h): an error on a
  // flank far below the peak cannot move the peak.
  cv::Mat extreme_error_map_um;
  int correlation_px = 1;  // side of the box B
  ZGrid grid;
  ZLinearity linearity;     // the table in use (maybe the uncharacterised bound, see its source)
  // The table was characterised at this scan's step (not transferred from another step, not a
  // bound): its shape is known, only its phase is not.
  bool linearity_shape_known = false;
  double stage_u_um = 0.0;  // standard uncertainty of one frame's z: r / sqrt 3
  bool three_point_peak = true;  // DepthNoiseOptions::three_point_peak
  double relative_amplification_u = 0.0;  // VerifiedCharacteristics::RelativeAmplificationUncertainty

  // How a depth at grid position p moves with the z errors of the frames around it (component 3):
  // depth error = sum_k weight[k] * d(frame[k]), k < count.
  struct StageSensitivity {
    int frame[3] = {0, 0, 0};
    double weight[3] = {0.0, 0.0, 0.0};
    int count = 0;
  };
  StageSensitivity StageSensitivityAt(const ZGrid::Position& p) const;

  // Perturbation k (0-based) of a Monte Carlo set of `count` drawn with `seed`: one realisation
  // of all three components on the pixels with depth and a sigma (CV_32FC1, 0 elsewhere). The
  // linearity phases are stratified over the set ((k + 0.5) / count plus one random offset), so
  // the set averages the table over its phase as the analytic propagation does. The same
  // (seed, k, count) always gives the same field.
  cv::Mat SamplePerturbation(const cv::Mat& depth_um, uint64_t seed, int k, int count) const;
};

// Estimates the model for depth_um (CV_32FC1, NaN = no depth) from the pixels where mask
// (CV_8UC1, empty = all) is non-zero: second differences are taken only where all three
// samples are in the mask, so a region's sigma is its own. When the mask holds fewer than ~8
// independent samples (8 window areas) the whole map's estimate is used instead.
// FAILED_PRECONDITION when no second difference can be formed anywhere (map too small or too
// sparse).
StatusOr<DepthNoiseModel> EstimateDepthNoise(const cv::Mat& depth_um, const cv::Mat& mask,
                                             const DepthNoiseOptions& options);

}  // namespace inspection
