// Standard uncertainty of measurements on an SFF depth map (GUM, JCGM 100): the depth error model
// of core/metrology/depth_noise_model.h propagated
//  - exactly through linear functionals of the depth map (least-squares fits, step heights,
//    mean heights): L = sum_p a(p) z(p), var L from the correlated noise, the z-linearity table
//    averaged over its unknown phase, and the per-frame stage error;
//  - by Monte Carlo (JCGM 101 style, fixed sample count and seed, so results are repeatable) for
//    non-linear values (Sa..Sku, flatness, volumes): each sample re-runs the whole measurement on
//    depth + one draw of the error model.
// Extremes (Sp, Sv, Sz, flatness) and norms (Sa, Sq) of a noisy surface are biased upwards by the
// noise itself, and that bias, not the spread, dominates when the surface is smooth: the reported
// value is not corrected (ISO 25178 values are reported as measured), and the bias estimate
// enters the uncertainty (u^2 = spread^2 + bias^2). The bias is estimated from three noise
// levels: the measured map holds the noise once (variance v = 1), each Monte Carlo sample twice
// (v = 2), and the sample with a second independent draw added three times (v = 3). With
// f(v) = f(0) + c v^p, the measured value's bias is c = d1 / (2^p - 1), d1 = mean f(2) - f(1), and
// p follows from d2 / d1 = (3^p - 2^p) / (2^p - 1), d2 = mean f(3) - f(2) (NoiseBiasExponent).
// p = 1/2 for a value proportional to the noise level (Sa, Sq of a surface of noise only: exact
// noise doubling, d1 / (sqrt 2 - 1)); p = 1 for a value whose bias grows with the noise variance
// (moments of a surface well above the noise: Sq^2 = Sq0^2 + sigma^2, so Sq, Ssk, Sku): there
// the doubling rule overstated the bias 2.4x (cosine Sku: bias estimate 0.078 against a
// deviation of 0.016 on the bench). p is clamped to [1/2, 1] and taken as 1/2 (the larger
// estimate) when d1 is not significant (|d1| <= 3 standard errors).
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/metrology/areal_parameters.h"
#include "core/metrology/depth_noise_model.h"
#include "core/metrology/form_removal.h"
#include "core/util/status.h"

namespace inspection {

// The standard uncertainty (k = 1) of one measured value and where it comes from. Fields that a
// method does not produce stay NaN.
struct UncertaintyBudget {
  double standard_uncertainty = std::nan("");  // combined u
  // Analytic (linear functionals): components, u^2 = random^2 + linearity^2 + stage^2 (+ other).
  double random = std::nan("");
  double linearity = std::nan("");
  double stage = std::nan("");
  double other = std::nan("");  // e.g. volume: pixels without depth filled by the region's mean
  // Monte Carlo: spread of the perturbed values and the noise-bias estimate.
  double monte_carlo_spread = std::nan("");
  double noise_bias = std::nan("");
  int monte_carlo_samples = 0;
  // Height-dependent systematic error (HeightDependentErrorBoundUm), worst case over its shape.
  double height_dependent = std::nan("");
  // Estimated, uncorrected systematic error (signed), e.g. the focus window's flattening of a
  // curved surface (WindowAveragingError); enters u as |estimated_systematic|.
  double estimated_systematic = std::nan("");
  // Verified amplification alpha_z (VerifiedCharacteristics): sqrt(u^2 + (alpha_z - 1)^2) |value|.
  double amplification = std::nan("");
  std::string method;  // "analytic" or "monte-carlo"; empty without a noise model
};

// Extremes (Sp, Sv, Sz, flatness): heavy-tailed SFF errors make a Gaussian Monte Carlo
// overconfident, so their expanded uncertainty (k = 2) is a documented bound on how far the
// error field can move an extreme: U = extremes * E + R, with E = model.extreme_error_um (the
// largest plausible single-pixel error) and R the largest range of the z-linearity error over the
// region's pixels for any phase of the table (0 for a region at one height, where it is a common
// offset that the form removal takes out). extremes = 1 for Sp and Sv (one extreme moves),
// 2 for Sz and flatness (peak and valley can move apart). The budget's standard uncertainty is U / 2.
UncertaintyBudget ExtremeValueBudget(int extremes, double linearity_range_um, const DepthNoiseModel& model);
// The same with the errors' part given in um: U = extreme_error_um + R (Sp: ExtremeErrorUm of the
// peak; Sz: of the peak plus of the valley).
UncertaintyBudget ExtremeValueBudgetUm(double extreme_error_um, double linearity_range_um);
// How far the error field can move the highest (peak = true) or the lowest point of surface_um
// (the levelled surface, pixel for pixel with the map the model was estimated on): the largest
// E(p) - gap(p) over its finite pixels, E = model.extreme_error_map_um and gap(p) the height
// between p and the measured extreme. The measured peak moves up by at most its own error (gap 0);
// the true peak q, moved down by D, is measured at most E(q) - D below the measured peak, so D <=
// E(q) - gap(q). An error on a flank far below the peak cannot reach it: E over the whole region
// made Sz's U 3-10x its deviation on sines and rough surfaces, whose flanks hold the largest
// errors. model.extreme_error_um when the model has no map or no pixel has both.
double ExtremeErrorUm(const cv::Mat& surface_um, const DepthNoiseModel& model, bool peak);
// R of ExtremeValueBudget over the pixels where mask is non-zero and depth finite.
double LinearityRangeUm(const cv::Mat& depth_um, const cv::Mat& mask, const DepthNoiseModel& model);

// Covariance of linear functionals, by error component (add them for the total).
struct FunctionalCovariance {
  Eigen::MatrixXd random;     // correlated per-pixel noise
  Eigen::MatrixXd linearity;  // z-linearity table, mean over its phase
  Eigen::MatrixXd stage;      // per-frame stage error
  Eigen::MatrixXd Total() const { return random + linearity + stage; }
};

// Budget of the functional c^T L (c over the functionals of cov).
UncertaintyBudget AnalyticBudget(const FunctionalCovariance& cov, const Eigen::VectorXd& c);

// L_i = sum_p weights[i](p) z(p). weights: CV_64FC1 images of depth_um's size, zero where a
// functional does not use a pixel (it must be zero wherever the model's sigma is NaN).
StatusOr<FunctionalCovariance> LinearFunctionalCovariance(const std::vector<cv::Mat>& weights, const cv::Mat& depth_um,
                                                          const DepthNoiseModel& model);

// The weights of a least-squares fit's parameters: row j of (J^T J)^-1 J^T as an image over the
// fitted pixels (mask and finite depth), i.e. d(parameter j) / d(z(p)) (linearised at the
// solution for sphere/cylinder).
std::vector<cv::Mat> FormFitWeights(const FormFit& fit, const cv::Mat& depth_um, const cv::Mat& mask,
                                    double pixel_size_um);

// Covariance of a fit's parameters under the model: (J^T J)^-1 J^T Sigma J (J^T J)^-1.
StatusOr<FunctionalCovariance> FormFitCovariance(const FormFit& fit, const cv::Mat& depth_um, const cv::Mat& mask,
                                                 double pixel_size_um, const DepthNoiseModel& model);

struct MonteCarloOptions {
  int samples = 32;          // 8..10000; 32 gives the spread to ~13 % (1 / sqrt(2 (n - 1)))
  uint64_t seed = 0x25178u;  // fixed: the same map and measurement give the same uncertainty
  Status Validate() const;
};

struct MonteCarloEstimate {
  double spread = 0.0;                // standard deviation of f(z + e_k) over the samples
  double bias = 0.0;                  // noise-bias estimate d1 / (2^p - 1), signed
  double noise_exponent = 0.5;        // p of the header comment
  double standard_uncertainty = 0.0;  // sqrt(spread^2 + bias^2)
  int samples = 0;                    // samples that gave a finite value
};

// p in [1/2, 1] of the header comment from d1, d2 and the standard error of d1.
double NoiseBiasExponent(double d1, double d2, double d1_standard_error);

// Budget of a Monte Carlo estimate.
UncertaintyBudget MonteCarloBudget(const MonteCarloEstimate& e);

// values = measure(depth_um); measure is re-run on depth_um + model.SamplePerturbation(k, samples)
// and, for the noise-bias exponent, on depth_um + draw k + draw (k + samples / 2) % samples.
// Samples where measure fails or gives NaN are left out; FAILED_PRECONDITION when fewer than
// half of them remain for any output.
using DepthMeasureFunction = std::function<StatusOr<std::vector<double>>(const cv::Mat& depth_um)>;
StatusOr<std::vector<MonteCarloEstimate>> MonteCarloUncertainty(const cv::Mat& depth_um,
                                                                const std::vector<double>& values,
                                                                const DepthMeasureFunction& measure,
                                                                const DepthNoiseModel& model,
                                                                const MonteCarloOptions& options);

// Height-dependent systematic error of shape parameters (Ssk, Sku). The SFF error of a pixel
// depends on its height: where it falls between frames (z linearity) and, on a curved surface,
// the focus window's averaging (WindowAveragingError). The Monte Carlo draws the z-linearity
// table characterised on a tilted flat, at random phase; on a curved surface the error's shape
// over the heights differs from that table (on a 2 um cosine between two frames: valleys
// raised by ~0.03 um against the peaks, Ssk +0.057 against a truth of 0, which the Monte Carlo
// gave +-0.02 for). Its size is known, its shape is not, so shape parameters take the worst
// case of an error g(height) with |g| <= delta: g = +-delta sign(df/dz) (df/dz from the moments
// of the levelled surface, a function of height alone), delta = half the range the table takes
// over the region's heights (LinearityRangeUm / 2: ~0 for a region at one height) plus the
// 99th percentile of |WindowAveragingError| over the region. B = the larger change of the value,
// taken as a uniform bound: standard uncertainty B / sqrt 3 (component height_dependent).
// Recipe measurements (core/metrology/measurement.cc) now split delta: the flattening is
// estimated on the map and enters every moment parameter (Sa..Sku) as an estimated systematic
// (AddEstimatedSystematic, the value's change when the map's WindowAveragingError is removed),
// and only the linearity half-range stays a worst case for Ssk and Sku: the p99 flattening as a
// worst case made their U 3-10x wider than their deviations (median |dev|/U 0.02-0.13,
// tests/bench/uncertainty_evaluate_output.md). HeightDependentErrorBoundUm keeps the combined
// delta for callers that have no estimate.

// The focus window's flattening of a curved surface: the focus measure sums over the window U
// (eq. 3.12/3.14, plus the Sobel operator's support), so to second order the depth is the
// window's mean height z + (s2 / 2) lap z, s2 = (w^2 - 1) / 12 + 1/2 px^2 per axis. Estimated
// from the measured map (NaN-aware Gaussian of sigma w / 2 against noise). CV_32FC1, um, 0 where
// depth_um is NaN. window_px >= 1.
cv::Mat WindowAveragingError(const cv::Mat& depth_um, int window_px);

// delta of the comment above, for the pixels where mask is non-zero and depth finite;
// linearity_range_um is LinearityRangeUm over the same pixels (the caller has it already).
double HeightDependentErrorBoundUm(const cv::Mat& depth_um, const cv::Mat& mask, const DepthNoiseModel& model,
                                   double linearity_range_um);

// sign(d Ssk / d z_p) or sign(d Sku / d z_p) (+1 / -1 as CV_32FC1, 0 where surface_um is NaN)
// for the levelled surface of core/metrology/areal_parameters.h. parameter: kSsk or kSku, else
// INVALID_ARGUMENT.
StatusOr<cv::Mat> ShapeParameterSensitivitySign(const cv::Mat& surface_um, HeightParameter parameter);

// The worst case of a height-dependent error g that is periodic in the z grid, |g| <= delta:
// g(p) = delta sign(S(f(p))), where f(p) is the fractional grid position of depth_um(p) in
// `bins` equal bins and S(f) the sum of d parameter / d z over the pixels in f's bin
// (+1 / -1 as CV_32FC1, 0 where depth or surface is NaN). Why periodic: peak locking is a
// function of where a height falls between two frames, the same between every pair of frames,
// so it cannot follow sign(d parameter / d z) over a surface spanning several steps (the
// unconstrained worst case of ShapeParameterSensitivitySign): between its bins the sensitivities
// of pixels a step apart cancel. surface_um is the levelled surface the parameter is computed on,
// pixel for pixel with depth_um. parameter: kSsk or kSku, else INVALID_ARGUMENT.
StatusOr<cv::Mat> PeriodicWorstCaseSign(const cv::Mat& depth_um, const cv::Mat& surface_um, HeightParameter parameter,
                                        const DepthNoiseModel& model, int bins);

// Adds a uniform bound B: component height_dependent = B / sqrt 3, combined in quadrature.
void AddHeightDependentBound(UncertaintyBudget& budget, double bound);

// Adds an estimated systematic error b that the value is not corrected for (ISO 25178 values are
// reported as measured): GUM-style, u^2 += b^2 (component estimated_systematic = b).
void AddEstimatedSystematic(UncertaintyBudget& budget, double bias);

}  // namespace inspection
