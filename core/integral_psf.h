// Integral PSF (IPSF) of thesis 5.4.1: the kernel that, convolved with the integral image of a
// stack (the mean over all z, eq. 5.19-5.20 summed), restores the all-in-focus image (eq. 5.23).
// Estimated by regularised least squares, eq. 5.22:
//   argmin_k || I_int * k - I_t ||^2 + mu * R(k),
// R = squared gradient (Tikhonov, "TV-L2" side of Fig. 5.21) or total variation (IRLS).
// Solved matrix-free by conjugate gradients; convolutions through OpenCV (DFT for big kernels).
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/status.h"

namespace inspection {

enum class IpsfRegularisation { kGradientL2, kTotalVariation };

// Plain data.
struct IntegralPsf {
  cv::Mat kernel;  // CV_32FC1, odd square, a convolution kernel (eq. 5.23)
  IpsfRegularisation regularisation = IpsfRegularisation::kGradientL2;
  double regularisation_weight = 0.0;
  // On the calibration images, over the valid region: RMS of I_int - I_t (before) and of
  // I_int * k - I_t (after), in input grey units.
  double integral_rms_error = 0.0;
  double restored_rms_error = 0.0;
  int stack_frames = 0;

  Status Validate() const;
  // eq. 5.23: the restored focused image of an integral image (CV_32FC1 result, same size;
  // border pixels replicate the edge).
  cv::Mat Apply(const cv::Mat& integral_image) const;
};

const char* IpsfRegularisationName(IpsfRegularisation r);

struct IntegralPsfOptions {
  int radius_px = 7;  // kernel is (2r+1)^2
  IpsfRegularisation regularisation = IpsfRegularisation::kGradientL2;
  // mu of eq. 5.22 relative to the mean diagonal of the data term's normal matrix, so the
  // value does not depend on image size or grey scale.
  double regularisation_weight = 1e-3;
  int max_cg_iterations = 400;
  double cg_tolerance = 1e-8;        // on the relative residual norm
  int tv_reweight_iterations = 6;    // IRLS outer loops for total variation
  double tv_epsilon = 1e-4;          // smoothing of |grad k| in the TV weights

  Status Validate() const;
};

// The integral image: mean of the stack frames (CV_32FC1). Frames: CV_8UC1/CV_16UC1/CV_32FC1.
StatusOr<cv::Mat> IntegralImage(const std::vector<cv::Mat>& frames);

// Solves eq. 5.22. integral_image and focused_image: same size, single channel.
StatusOr<IntegralPsf> EstimateIntegralPsf(const cv::Mat& integral_image, const cv::Mat& focused_image,
                                          const IntegralPsfOptions& options);

}  // namespace inspection
