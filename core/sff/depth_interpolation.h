// Depth interpolation of thesis 3.1.4: where along z one pixel's focus curve F(z) peaks, from
// the samples around its discrete maximum (maximum eq. 3.23-3.24, Malik & Choi line fit
// eq. 3.25-3.29, three-point Gaussian eq. 3.30-3.34), all for non-uniform z steps; and how far
// the peak can be trusted (confidence in [0, 1]).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/sff/sff_options.h"

namespace inspection {

struct FocusPeak {
  double z_um = 0.0;          // interpolated peak position
  double sigma_um = 0.0;      // Gaussian: standard deviation sigma_F (eq. 3.33); 0 for other methods
  double height = 0.0;        // Gaussian: F_max of eq. 3.34; otherwise the sampled maximum
  bool interpolated = false;  // false when the method fell back to the discrete maximum
};

// Three-point Gaussian through (z1, f1), (z2, f2), (z3, f3) with z1 < z2 < z3 or z1 > z2 > z3 and
// f2 the sampled maximum. Generalises eq. 3.32-3.33 to unequal steps: with u = z - z2,
// a = ln f2 - ln f1, b = ln f2 - ln f3:
//   mu = (a u3^2 - b u1^2) / (2 (a u3 - b u1)),  sigma^2 = u1 u3 (u1 - u3) / (2 (a u3 - b u1)),
// which for u1 = -dz, u3 = dz reduces to the thesis' equations. Falls back to z2 when a value is
// not positive or the denominator vanishes.
FocusPeak GaussianPeak(double z1, double z2, double z3, double f1, double f2, double f3);
// The same peak position without sigma and height (the engine's per-pixel hot path; inline).
inline double GaussianPeakZ(double z1, double z2, double z3, double f1, double f2, double f3) {
  if (!(f1 > 0.0 && f2 > 0.0 && f3 > 0.0)) return z2;
  const double u1 = z1 - z2, u3 = z3 - z2;
  const double a = std::log(f2 / f1), b = std::log(f2 / f3);
  const double den = a * u3 - b * u1;
  // sigma^2 = u1 u3 (u1 - u3) / (2 den) must be positive: den must have the sign of u1 u3 (u1 - u3).
  const double num_var = u1 * u3 * (u1 - u3);
  if (!(den * num_var > 0.0) || !std::isfinite(den)) return z2;
  const double mu = (a * u3 * u3 - b * u1 * u1) / (2.0 * den);
  if (!(mu >= std::min(u1, u3) && mu <= std::max(u1, u3))) return z2;  // also rejects NaN
  return z2 + mu;
}

// Defocus parabola: the vertex of the parabola through (z1, f1^-1/2), (z2, f2^-1/2), (z3, f3^-1/2)
// (f2 the sampled maximum, so the vertex is a minimum of f^-1/2).
// Why f^-1/2: a gradient-energy focus measure (Tenengrad, eq. 3.14) of a texture with a flat
// spectrum, blurred by a PSF of second moment sigma_b^2, falls as sigma_b^-4, and sigma_b^2 =
// sigma_0^2 + k^2 (z - z_f)^2 (the in-focus blur plus the defocus blur, which grows linearly in
// |z - z_f|). So F^-1/2 = c (sigma_0^2 + k^2 (z - z_f)^2) is exactly a parabola in z with its
// vertex at the focus z_f, whatever sigma_0, k and the texture's contrast; ln F (the Gaussian of
// eq. 3.30) is not, and its error depends on where the focus lies between two frames, which on
// a flat part (every pixel between the same two frames) is a bias of the whole depth map.
// With u = z - z2 and the drops a = sqrt(f2/f1) - 1, b = sqrt(f2/f3) - 1 (f^-1/2 scaled by
// sqrt(f2), which leaves the vertex unchanged) the vertex is the Gaussian's mu formula with these
// a and b. Falls back to z2 like GaussianPeakZ.
inline double DefocusParabolaPeakZ(double z1, double z2, double z3, double f1, double f2, double f3) {
  if (!(f1 > 0.0 && f2 > 0.0 && f3 > 0.0)) return z2;
  const double u1 = z1 - z2, u3 = z3 - z2;
  const double a = std::sqrt(f2 / f1) - 1.0, b = std::sqrt(f2 / f3) - 1.0;
  const double den = a * u3 - b * u1;
  const double num_var = u1 * u3 * (u1 - u3);
  if (!(den * num_var > 0.0) || !std::isfinite(den)) return z2;
  const double mu = (a * u3 * u3 - b * u1 * u1) / (2.0 * den);
  if (!(mu >= std::min(u1, u3) && mu <= std::max(u1, u3))) return z2;
  return z2 + mu;
}

// The three-point peak position of `method` (kGaussian or kDefocusParabola; the engines' per-pixel
// hot path for those two methods).
inline double ThreePointPeakZ(DepthInterpolation method, double z1, double z2, double z3, double f1, double f2,
                              double f3) {
  return method == DepthInterpolation::kDefocusParabola ? DefocusParabolaPeakZ(z1, z2, z3, f1, f2, f3)
                                                        : GaussianPeakZ(z1, z2, z3, f1, f2, f3);
}
inline bool IsThreePointMethod(DepthInterpolation method) {
  return method == DepthInterpolation::kGaussian || method == DepthInterpolation::kDefocusParabola;
}

// Malik & Choi line fit (eq. 3.25-3.29). z/f hold the samples m - before .. m + after around the
// maximum at position `before` (so count = before + after + 1). DS1 = the `before` samples and
// the maximum, DS2 = the maximum and the `after` samples; a least-squares line through each,
// intersecting at d_i. d_c is the sample of DS1 u DS2 other than d_max closest to d_i (taking
// d_max itself would make eq. 3.29 return d_max unchanged); the result is w1 d_c + w2 d_max.
// Needs before >= 1 and after >= 1, otherwise returns the maximum.
FocusPeak LineFitPeak(const double* z, const double* f, int before, int after);

// Dispatches on the method; z/f/before/after as for LineFitPeak. kMaximum returns z[before];
// kGaussian and kDefocusParabola use the direct neighbours of the maximum.
FocusPeak InterpolatePeak(DepthInterpolation method, const double* z, const double* f, int before, int after);

// Whole-curve convenience (tests, offline use): finds the first discrete maximum of f and
// interpolates with up to `linefit_half_width` samples on each side.
FocusPeak InterpolateFocusCurve(DepthInterpolation method, const std::vector<double>& z_um,
                                const std::vector<double>& f, int linefit_half_width = 2);

// What the streaming engine knows about a pixel's focus curve at the end of a stack, all from
// O(1) state: the peak, the mean, and the curve's roughness from its second differences.
struct FocusCurveSummary {
  double peak = 0.0;  // F_max, the sampled maximum
  double mean = 0.0;  // mean of F over all frames
  // Sum of t_k^2, t_k = F_k - 2 F_(k-1) + F_(k-2), over the k whose t_k does not involve the
  // maximum (m not in {k-2, k-1, k}), and how many terms that is.
  double curvature_sq_sum = 0.0;
  int curvature_count = 0;
  bool peak_at_end = false;  // the maximum is on the first or last frame
  // How many of the counted t_k involve a direct neighbour of the maximum (FlankTermCount).
  int flank_terms = 0;
};

// How many of the t_k counted in FocusCurveSummary (those not involving the maximum m, of n
// frames) involve one of its direct neighbours: t_(m-1) (frames m-3..m-1) and t_(m+3) (frames
// m+1..m+3); both are counted where they exist.
inline int FlankTermCount(int m, int n) { return (m >= 3 ? 1 : 0) + (m + 3 <= n - 1 ? 1 : 0); }

// Confidence in [0, 1] that the peak is real focus rather than noise ("the peak against the
// curve's residual"). A focused, textured pixel has a smooth curve whose peak stands far above
// its mean; a textureless pixel has a curve of independent noise whose maximum is only a few
// noise levels above the mean. The noise level comes from the curve's second differences away
// from the peak, which cancel the smooth flanks of a real peak but not noise (var t = 6 var F):
// sigma = sqrt(curvature_sq_sum / (6 (curvature_count + kFlankTermExtraWeight flank_terms))),
// floored at 1e-3 F_max. The (at most two) flank terms t_(m-1) and t_(m+3) hold the peak's own
// curvature besides noise, so each counts as 1 + kFlankTermExtraWeight terms. That matters on
// short stacks, where they are most or all of the terms: a noiseless defocus peak sampled as
// the thesis rig samples it (F / F_max = 0.05, 0.12, 0.45, 1, 0.45, 0.12, 0.05) gets s = 6.4
// counted plainly, which min_confidence 0.4 (s >= 6.7) rejects. Measured on the simulated rig
// (5 um steps): 7 frames centred on a flat part (plane, step1um; STD) kept 3-64 % of it plainly
// and 91-100 % weighted; 9 frames over skew5 (4 steps tall) 87 % -> 99.5 %; the lens under
// TEXTURE at 11 frames 93 % -> 100 %; stacks of >= 13 frames through textured parts the same.
// The price is in noise: a grey + noise stack (tests/core/sff/sff_engine_test.cc) keeps 11 % of its
// pixels at 7 frames (5.8 % plainly) and 0.8 % at 21 (test bound 1 %).
// With the peak's signal-to-noise ratio s = (F_max - mean) / sigma:
//   confidence = clamp(1 - kConfidenceSnrZero / s, 0, 1),
// halved when the peak is on the first or last frame (the true peak may lie outside the stack).
inline constexpr double kConfidenceSnrZero = 4.0;
inline constexpr double kFlankTermExtraWeight = 2.0;
inline float FocusConfidence(const FocusCurveSummary& s) {
  const double prominence = s.peak - s.mean;
  if (!(prominence > 0.0) || !(s.peak > 0.0)) return 0.f;
  const double weighted_count = s.curvature_count + kFlankTermExtraWeight * s.flank_terms;
  double sigma = s.curvature_count > 0 ? std::sqrt(std::max(s.curvature_sq_sum, 0.0) / (6.0 * weighted_count)) : 0.0;
  sigma = std::max(sigma, 1e-3 * s.peak);
  // 1 - kConfidenceSnrZero / snr with snr = prominence / sigma, in one division.
  double c = std::clamp(1.0 - kConfidenceSnrZero * sigma / prominence, 0.0, 1.0);
  if (s.peak_at_end) c *= 0.5;
  return float(c);
}

}  // namespace inspection
