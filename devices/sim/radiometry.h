// Radiometric models of the simulated rig: the projector response prf (thesis 4.3.1, eq. 4.6 and
// 5.1) and the camera response crf with exposure, saturation, noise and quantisation (eq. 4.2,
// 5.3, 5.4). Plain data plus pure functions, so tests can check each curve on its own.
#pragma once

#include <array>
#include <cstdint>
#include <opencv2/core.hpp>

#include "core/util/status.h"

namespace inspection {

// prf: 8-bit projector grey -> relative irradiance on the focal plane (1.0 at grey 255).
// A display gamma with a black floor (finite DMD contrast), monotonic like thesis Fig. 4.10.
struct ProjectorResponse {
  double gamma = 2.0;               // E ~ (Z/255)^gamma
  double black_irradiance = 0.002;  // irradiance at grey 0 (contrast 500:1)

  Status Validate() const;
  double Irradiance(int grey) const;     // eq. 5.1 for one grey level
  std::array<float, 256> Table() const;  // Irradiance() for every grey level
};

// Camera: exposure X = E_c * dt (eq. 5.3) in electrons, shot and read noise, then the non-linear
// response Z_c = f_c(X) (eq. 5.4): y = (X / full_well)^response_exponent, scaled to the output
// range above a black level, clipped (saturation) and rounded.
struct CameraResponse {
  int bit_depth = 8;             // 8 -> CV_8UC1, 12 -> CV_16UC1 in 0..4095
  double full_well_e = 10000.0;  // electrons at which the output saturates
  // Electrons per microsecond for unit irradiance (grey 255 of the projector) on reflectance 1.
  double sensitivity_e_per_us = 10.0;
  double response_exponent = 0.8;  // < 1: a mild log-like crf as in thesis Fig. 4.9
  double black_level_dn8 = 2.0;    // black level in 8-bit grey levels (scaled for 12 bit)
  double read_noise_dn8 = 0.8;     // read noise in 8-bit grey levels (before the response)
  bool shot_noise = true;

  Status Validate() const;
  int max_dn() const { return (1 << bit_depth) - 1; }
  int output_type() const { return bit_depth == 8 ? CV_8UC1 : CV_16UC1; }
  // Noise-free grey value (not rounded, clipped to [black, max]) for a relative exposure
  // x = electrons / full_well.
  double GreyForRelativeExposure(double x) const;
  // Inverse of GreyForRelativeExposure on the unsaturated range.
  double RelativeExposureForGrey(double grey) const;
};

// Converts a camera irradiance image (CV_32FC1, relative units) into the camera's output frame:
// exposure, gain, shot + read noise (seeded by noise_seed; deterministic for any thread count),
// response, black level, saturation and quantisation. Precondition (a programming error
// otherwise, checked by CV_Assert): irradiance is CV_32FC1; ImageFormation::Render validates
// user input before calling it.
cv::Mat ExposeAndDigitise(const cv::Mat& irradiance, double exposure_us, double gain_db, const CameraResponse& response,
                          uint64_t noise_seed);

// Mixes two 64-bit values into a well-distributed seed (splitmix64 finaliser).
uint64_t MixSeed(uint64_t a, uint64_t b);

}  // namespace inspection
