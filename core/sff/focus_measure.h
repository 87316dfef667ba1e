// Focus measure operators of thesis 3.1.3 (eq. 3.6-3.22) as whole-frame maps: the reference
// implementation every SFF path is checked against, and the per-frame path of the streaming
// engine for operators without a fused kernel.
//
// Border handling (all operators): the image is extended by mirroring without repeating the
// edge pixel (OpenCV BORDER_REFLECT_101: ... I(2) I(1) | I(0) I(1) I(2) ...), both for the
// derivative masks and for the summation window U. A pixel on the border therefore sees the
// same statistics as if the specimen continued symmetrically.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/sff/sff_options.h"
#include "core/util/status.h"

namespace inspection {

// Computes the focus map of `frame` (CV_8UC1, CV_16UC1 or CV_32FC1, grey values as stored) with
// the square summation window U of side window_px (odd, 3..31). Output: CV_32FC1, >= 0.
//
//  kModifiedLaplacian     sum over U of |Ixx| + |Iyy| (Nayar's modified Laplacian, the unsquared
//                         form of eq. 3.8; Ixx, Iyy from the masks of eq. 3.11).
//  kSumModifiedLaplacian  eq. 3.12: sum over U of Ixx^2 + Iyy^2 (eq. 3.9-3.10).
//  kTenengrad             eq. 3.14: sum over U of Gx^2 + Gy^2 with the Sobel masks of eq. 3.13.
//  kGreyLevelVariance     eq. 3.15: 1/(N-1) sum over U of (I - mu_U)^2, N = window_px^2.
//  kHelmliMean            eq. 3.16 as Helmli & Scherer define it: at every pixel p the ratio
//                         R(p) = mu(p)/I(p) if mu(p) > I(p), else I(p)/mu(p), with mu(p) the mean
//                         of the window around p; FM = sum of R over U. Scale-free: both terms
//                         of a ratio are floored at kHelmliFloorOfMean times the frame's mean
//                         grey value (one grey level of an 8-bit frame of mean 128), so the map
//                         of s * I equals that of I for any s > 0 (8-bit, 16-bit or float in
//                         [0, 1] alike), zero grey values give finite ratios and a constant (or
//                         all-zero) image gives exactly N. Grey values must be >= 0.
//  kChebyshevMoments      Yap & Raveendran, eq. 3.17-3.22: moments T_mn of the window with the
//                         orthonormal Chebyshev polynomials; FM = ||T_high|| / ||T_low||, low =
//                         orders m + n <= 2 (T_00 included), high = all others. ||T_high||^2 is
//                         sum(I^2) - ||T_low||^2 over U (Parseval: the basis is orthonormal).
//                         0 where ||T_low|| = 0.
//  kGreyLevelLocalVariance GLVM: 1/N sum over U of (I(p) - mu(p))^2, the deviation of every
//                         pixel from the mean of its own window (a local, moving mean), unlike
//                         eq. 3.15 whose mean is the one of the centre's window.
Status ComputeFocusMeasure(const cv::Mat& frame, FocusMeasure measure, int window_px, cv::Mat* focus);

// Whether rows [y0, y1) of the focus map of `measure` (and of its NormaliseFocusByIllumination)
// can be computed from frame rows [y0 - FocusMeasureHaloRows, y1 + FocusMeasureHaloRows) alone,
// bit for bit equal to the whole-frame map's rows, on CV_8UC1 / CV_16UC1 frames. True where every
// step is exact or per pixel: Tenengrad, the (sum) modified Laplacian and the grey-level variance
// take integer grey values through integer-valued Sobel / second differences and OpenCV's box
// filter, whose float input is summed in double, exactly (sums of integers below 2^53), so the
// running sums do not depend on the row they start from. False for the Helmli mean (its floor
// is the whole frame's mean), the local variance (its box filters sum non-integer values: the
// rounding depends on where the running sum starts) and the Chebyshev moments (not verified).
// Why: the streaming engine computes the map in row bands, so its full-frame float temporaries
// (about 28 bytes per pixel for Tenengrad) become band-sized.
bool FocusMeasureIsRowLocal(FocusMeasure measure);
// Rows a band needs on each side: the derivative's radius (1) plus the window's (window_px / 2).
inline int FocusMeasureHaloRows(int window_px) { return window_px / 2 + 1; }

// How a measure of `measure` scales with the illumination: a frame lit s times brighter has a
// focus map s^power times larger. 2 for Tenengrad, SML and the variances, 1 for the modified
// Laplacian, 0 for the scale-free ratios (Helmli mean, Chebyshev moments).
int IlluminationPower(FocusMeasure measure);

// Makes a focus map of `measure` independent of how brightly its frame was lit: divides it in
// place by the frame's window mean (same window_px, same borders) to IlluminationPower(measure).
// Why: the ADAPT family (thesis 5.1) lights every z with its own compensation pattern, predicted
// from the frame before, so the light on a point changes from frame to frame while it passes
// through focus; a measure that grows with the square of the light then takes that change into
// the focus curve and moves its peak (on the coin the window mean fell from 145 to 112 grey
// across the three frames around focus: a factor 1.7 in Tenengrad, and the field's depth moved
// by -0.5 to -1.4 um). The ratio is the same for any scale of the light. Means below 1/256 of
// the frame type's full scale (one grey level at 8 bit; 1/256 for float frames) are taken as
// that floor: there the grey value is noise. frame: CV_8UC1, CV_16UC1 or CV_32FC1; focus:
// CV_32FC1 of the frame's size.
Status NormaliseFocusByIllumination(const cv::Mat& frame, FocusMeasure measure, int window_px, cv::Mat* focus);

// kHelmliMean's floor of a ratio's terms, relative to the frame's mean grey value.
inline constexpr double kHelmliFloorOfMean = 1.0 / 128.0;

// Tenengrad (eq. 3.13-3.14) of an 8-bit frame in exact integer arithmetic with the SFF engine's
// fused SIMD kernel (CV_32SC1; fits int32 for every window up to 31). Same values as
// ComputeFocusMeasure(kTenengrad) up to that function's float rounding. Implemented in
// core/sff/internal/tenengrad_kernel_dispatch.cc, beside the kernel. use_simd = false forces the portable
// kernel (the AVX2 one is used when the CPU has it); both give identical values.
Status ComputeTenengradU8(const cv::Mat& frame, int window_px, cv::Mat* focus, bool use_simd = true);

// Normalised discrete Chebyshev polynomial t~_m(x; N) for x = 0..N-1 (eq. 3.18-3.22, normalised
// by sqrt(rho(m, N)) of eq. 3.20). Valid for 0 <= m < N.
std::vector<double> ChebyshevPolynomial(int m, int n_points);
// rho(m, N) = (2m)! * binomial(N + m, 2m + 1), eq. 3.20.
double ChebyshevNorm(int m, int n_points);

}  // namespace inspection
