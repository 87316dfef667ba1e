// Camera response function crf(Z) = ln f^-1(Z) = ln(E * dt) recovered from an exposure series
// (Debevec and Malik; thesis 3.2.1 eq. 3.38-3.42 and 4.3.1 eq. 4.3-4.5), and its use: radiance
// images (eq. 4.5), HDR merge (eq. 3.44) and the inverse mapping exposure -> grey value (eq. 5.4).
//
// The model (CameraResponseFunction) is plain data; EstimateCameraResponse is the estimator. A stored
// model can be loaded and checked (Validate) without the images it came from.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/util/status.h"

namespace inspection {

// crf sampled at every grey level 0..levels-1, in natural-log exposure units (ln(E * dt_us)),
// with the gauge crf(levels / 2) = 0 (thesis eq. 3.40; the same gauge as OpenCV's
// CalibrateDebevec). Exposure times are in microseconds throughout.
struct CameraResponseFunction {
  int levels = 256;                  // 2^bit_depth of the camera, 256 or 4096
  std::vector<double> log_exposure;  // crf(z), size levels, non-decreasing
  double smoothness_lambda = 0.0;    // lambda used in the fit (see CameraResponseOptions)
  int sample_pixel_count = 0;        // N of eq. 4.4
  int image_count = 0;               // P of eq. 4.4
  double fit_rms_residual = 0.0;     // weighted RMS of the data term of eq. 4.4, ln units

  // OK when levels >= 2, log_exposure has `levels` finite, non-decreasing entries.
  Status Validate() const;

  // crf at a (possibly fractional) grey level, linear interpolation, clamped to the range.
  double LogExposure(double z) const;
  // Inverse of crf: the fractional grey value whose crf equals log_exposure (eq. 5.4, before
  // quantisation). Clamped to [0, levels-1].
  double GreyForLogExposure(double log_exposure) const;
  // Irradiance image E = exp(crf(Z)) / dt (eq. 4.5), CV_32FC1. z: CV_8UC1 or CV_16UC1.
  cv::Mat Radiance(const cv::Mat& z, double exposure_us) const;
};

// Debevec-Malik triangle weight of eq. 3.41: w(z) = z - Zmin below the middle, Zmax - z above.
double DebevecWeight(int z, int levels);

struct CameraResponseOptions {
  // Row weight of the smoothness equations, as in Debevec's gsolve and OpenCV: the penalty is
  // lambda^2 * sum (w(z) crf''(z))^2, so sigma of eq. 4.4 equals lambda^2. Default 10.
  // Defined for 256 levels; deeper cameras use lambda * (levels / 256)^1.5 (see the solver).
  double smoothness_lambda = 10.0;
  int levels = 256;
  // Number of sample pixels N picked from the images (thesis 3.2.1: 50 suffice for 8 bit).
  int sample_pixel_count = 100;

  Status Validate() const;
};

// Solves eq. 4.4 for given samples. z[i][j] is the grey value of sample pixel i in image j;
// exposure_us[j] the exposure of image j. Weighted least squares, sparse normal equations
// (CHOLMOD), gauge crf(levels/2) = 0.
StatusOr<CameraResponseFunction> SolveCameraResponse(const std::vector<std::vector<int>>& z,
                                                     const std::vector<double>& exposure_us,
                                                     const CameraResponseOptions& options);

// Picks sample pixels whose grey values in the middle image of the series spread evenly over
// the grey range (thesis 3.2.1), then solves eq. 4.4. images: same size, CV_8UC1 or CV_16UC1,
// of a static scene; exposure_us strictly positive.
StatusOr<CameraResponseFunction> EstimateCameraResponse(const std::vector<cv::Mat>& images,
                                                        const std::vector<double>& exposure_us,
                                                        const CameraResponseOptions& options);

// HDR irradiance image, eq. 3.44 (weighted mean of crf(Z) - ln dt), returned as E (CV_32FC1,
// not the log). Pixels with zero total weight get the estimate from the least-saturated frame.
StatusOr<cv::Mat> MergeRadiance(const std::vector<cv::Mat>& images, const std::vector<double>& exposure_us,
                                const CameraResponseFunction& response);

}  // namespace inspection
