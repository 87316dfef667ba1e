// Options of the shape-from-focus engine (thesis 3.1): the focus measure (3.1.3), the depth
// interpolation (3.1.4), the confidence threshold and how the work is run, with the names the
// API and the CLI use for them.
#pragma once

#include <string>

#include "core/util/status.h"

namespace inspection {

// Focus measure operators of thesis 3.1.3.
// Exact definitions and border handling: core/sff/focus_measure.h.
enum class FocusMeasure {
  kModifiedLaplacian,       // ML: |Ixx| + |Iyy| (masks of eq. 3.11, unsquared eq. 3.8) summed over the window
  kSumModifiedLaplacian,    // SML, eq. 3.12
  kTenengrad,               // eq. 3.14
  kGreyLevelVariance,       // eq. 3.15
  kHelmliMean,              // Helmli-Scherer mean ratio, eq. 3.16
  kChebyshevMoments,        // Yap & Raveendran ratio, eq. 3.17-3.22
  kGreyLevelLocalVariance,  // GLVM: local variance from the mean
};

// Depth interpolation of thesis 3.1.4.
enum class DepthInterpolation {
  kMaximum,   // eq. 3.23-3.24
  kLineFit,   // Malik & Choi, eq. 3.25-3.29
  kGaussian,  // three-point Gaussian, eq. 3.30-3.34
  // Three-point parabola through F^(-1/2) (core/sff/depth_interpolation.h, DefocusParabolaPeakZ):
  // exact for a gradient-energy measure of a blurred texture, whose F ~ 1 / sigma_blur^4 with
  // sigma_blur^2 growing quadratically in the defocus; the Gaussian is not, and its sub-step
  // error does not average out on flat parts.
  kDefocusParabola,
};

const char* FocusMeasureName(FocusMeasure m);  // "tenengrad", "sml", ...
StatusOr<FocusMeasure> ParseFocusMeasure(const std::string& name);
// "maximum", "linefit", "gaussian", "defocus_parabola"
const char* DepthInterpolationName(DepthInterpolation i);
StatusOr<DepthInterpolation> ParseDepthInterpolation(const std::string& name);

struct SffOptions {
  FocusMeasure focus_measure = FocusMeasure::kTenengrad;
  int window_px = 7;  // odd, 3..31: side of the square summation window U of eq. 3.12/3.14
  DepthInterpolation interpolation = DepthInterpolation::kDefocusParabola;
  // Line fit only: samples j on each side of the maximum in DS1/DS2 (eq. 3.25-3.26), 1..4.
  int linefit_half_width = 2;
  // Pixels whose confidence (0..1, see FocusConfidence in core/sff/depth_interpolation.h) is below
  // this get NaN depth. The default keeps > 99 % of a textured specimen scanned through its
  // focus (also on 7 frames centred on a flat part) and rejects > 99 % of textureless (grey +
  // noise) pixels on 21 frames; with fewer frames the noise level is less certain (7 frames:
  // ~89 % rejected). tests/core/sff/sff_engine_test.cc.
  double min_confidence = 0.4;
  // For frames lit differently from one another (each z its own projected pattern, as the ADAPT
  // family's scans; flicker): every frame's focus map is divided by its window mean to the
  // measure's illumination power (NormaliseFocusByIllumination, core/sff/focus_measure.h), so the
  // change of light from frame to frame does not move the focus curve's peak. Off by default:
  // on glinting parts the window mean is not the light (docs/illumination.md "Bias and the default,
  // re-checked"). Runs the whole-frame focus map path (not the fused 8-bit Tenengrad kernel).
  bool illumination_invariant = false;
  // Worker threads for the per-frame pass; 0 = all hardware threads.
  int threads = 0;
  // AVX2 kernels when the CPU has them (chosen at run time); false forces the portable kernels.
  // Both give bit-identical results.
  bool use_simd = true;
  // With use_simd: AVX-512 for the state update of 8-bit Tenengrad (maximum or Gaussian) when
  // the CPU has it (false keeps AVX2). Bit-identical either way.
  bool use_avx512 = true;

  // INVALID_ARGUMENT naming the field when out of range.
  Status Validate() const;
};

}  // namespace inspection
