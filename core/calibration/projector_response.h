// Projector response function prf(i): relative irradiance a projector grey level i produces on
// the specimen, normalised to prf(255) = 1 (thesis 3.3.2 eq. 3.48, 4.3.1 eq. 4.6-4.9). Estimated
// from uniform patterns on a plane, each captured at the exposure of eq. 4.8 and converted to
// radiance through the camera response (eq. 4.5).
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/calibration/camera_response.h"
#include "core/util/status.h"

namespace inspection {

// Plain data. relative_irradiance[i] = mean(E_c,i / E_c,255) (eq. 4.9), for i = 0..255.
struct ProjectorResponseFunction {
  std::vector<double> relative_irradiance;  // size 256, non-decreasing, last entry 1
  std::vector<int> measured_levels;         // grey levels actually projected; others interpolated
  double exposure_min_us = 0.0;             // dt_min and dt_max of eq. 4.8
  double exposure_max_us = 0.0;
  // Spread of the per-pixel ratio E_c,i / E_c,255 around its mean, averaged over levels:
  // mean over i of stddev/mean (a measure of how uniform the plane and the illumination are).
  double pixel_ratio_cv = 0.0;

  Status Validate() const;
  // prf at a fractional grey (linear interpolation).
  double Irradiance(double grey) const;
  // Inverse prf: fractional grey in [0, 255] producing the relative irradiance e.
  double GreyForIrradiance(double e) const;
  // Relative irradiance image prf(Z_p) (eq. 5.1) of an 8-bit pattern, CV_32FC1.
  cv::Mat IrradianceImage(const cv::Mat& pattern) const;
};

// The exposure of eq. 4.8 for grey level i: exp(a + (b - a) / 255 * i), a = ln dt_max,
// b = ln dt_min, so level 0 gets dt_max and level 255 gets dt_min.
double ProjectorCalibrationExposureUs(int grey, double exposure_min_us, double exposure_max_us);

// One uniform pattern of grey `grey` captured at exposure_us.
struct ProjectorResponseCapture {
  int grey = 0;
  double exposure_us = 0.0;
  cv::Mat image;  // CV_8UC1 or CV_16UC1
};

struct ProjectorResponseOptions {
  // Only pixels whose grey lies in [min_valid_grey, max_valid_grey] (in the camera's levels)
  // of both image i and image 255 enter eq. 4.9: saturated or near-black pixels do not
  // measure radiance. Defaults are for 8-bit cameras and are scaled for deeper ones.
  int min_valid_grey = 8;
  int max_valid_grey = 247;
  // Optional region of interest in camera pixels (empty = whole frame), e.g. the part of the
  // image the projector lights.
  cv::Rect roi;
};

// captures must contain grey 255 and at least one other level; levels are sorted and missing
// levels are linearly interpolated. Errors name the capture.
StatusOr<ProjectorResponseFunction> EstimateProjectorResponse(const std::vector<ProjectorResponseCapture>& captures,
                                                              const CameraResponseFunction& camera_response,
                                                              const ProjectorResponseOptions& options);

}  // namespace inspection
