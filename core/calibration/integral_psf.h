// Integral PSF (IPSF) of thesis 5.4.1: the kernel that, convolved with the integral image of a
// stack (the mean over all z, eq. 5.19-5.20 summed), restores the all-in-focus image (eq. 5.23).
// Estimated by regularised least squares, eq. 5.22:
//   argmin_k || I_int * k - I_t ||_p^p + mu * R(k),
// with (Fig. 5.21) p = 2 and R = squared gradient (Tikhonov), p = 2 and R = total variation
// (TV-L2), or p = 1 and R = total variation (TV-L1, the thesis's best: the L1 data term does not
// let a few badly matched pixels - glints, dust, saturated spots - bend the kernel).
// Solved matrix-free by conjugate gradients, L1 and TV through iteratively reweighted least
// squares (IRLS); convolutions through OpenCV (DFT for big kernels).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

enum class IpsfRegularisation {
  kGradientL2,        // L2 data term + squared gradient of the kernel (Tikhonov)
  kTotalVariation,    // L2 data term + total variation of the kernel (TV-L2)
  kTotalVariationL1,  // L1 data term + total variation of the kernel (TV-L1)
};

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
  // Noise (grey) of the calibration's integral image: frame noise / sqrt(stack_frames); 0 when
  // unknown. The least-squares kernel already damps this much noise (errors in the input of
  // eq. 5.22 shrink it like a Wiener filter), so restoration adds damping only for the noise a
  // scan has beyond it (core/sff/integral_sff.h).
  double integral_noise_sigma = 0.0;

  Status Validate() const;
  // eq. 5.23: the restored focused image of an integral image (CV_32FC1 result, same size;
  // border pixels replicate the edge).
  cv::Mat Apply(const cv::Mat& integral_image) const;
};

// "gradient_l2", "total_variation" (TV-L2; the name calibrations already store), "tv_l1".
const char* IpsfRegularisationName(IpsfRegularisation r);
// The names above; INVALID_ARGUMENT listing them otherwise.
StatusOr<IpsfRegularisation> ParseIpsfRegularisation(const std::string& name);

struct IntegralPsfOptions {
  int radius_px = 7;  // kernel is (2r+1)^2
  IpsfRegularisation regularisation = IpsfRegularisation::kGradientL2;
  // mu of eq. 5.22 relative to the mean diagonal of the data term's normal matrix, so the
  // value does not depend on image size or grey scale.
  double regularisation_weight = 1e-3;
  int max_cg_iterations = 400;
  double cg_tolerance = 1e-8;      // on the relative residual norm
  int tv_reweight_iterations = 6;  // IRLS outer loops for total variation and the L1 data term
  double tv_epsilon = 1e-4;        // smoothing of |grad k| in the TV weights (relative to the kernel peak)
  // TV-L1: smoothing of |residual| in the L1 weights, relative to the RMS residual of the
  // previous iterate (|r| ~ r^2 / sqrt(r^2 + eps^2)).
  double l1_epsilon = 0.05;
  // Recorded in IntegralPsf::integral_noise_sigma (>= 0; the caller measures it on the
  // calibration stack, e.g. IntegralImageAccumulator::FrameNoiseSigma() / sqrt(frames)).
  double integral_noise_sigma = 0.0;

  Status Validate() const;
};

// The integral image: mean of the stack frames (CV_32FC1). Frames: CV_8UC1/CV_16UC1/CV_32FC1.
StatusOr<cv::Mat> IntegralImage(const std::vector<cv::Mat>& frames);

// Solves eq. 5.22. integral_image and focused_image: same size, single channel.
StatusOr<IntegralPsf> EstimateIntegralPsf(const cv::Mat& integral_image, const cv::Mat& focused_image,
                                          const IntegralPsfOptions& options);

}  // namespace inspection
