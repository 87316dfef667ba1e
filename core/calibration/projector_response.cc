// Projector response function (thesis 4.3.1 eq. 4.8-4.9): per-level mean of the per-pixel
// radiance ratio to the full-white level, radiance from the camera response (eq. 4.5).
#include "core/calibration/projector_response.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <string>

namespace inspection {

Status ProjectorResponseFunction::Validate() const {
  if (relative_irradiance.size() != 256) {
    return Status::InvalidArgument("projector_response.relative_irradiance must have 256 entries");
  }
  for (int i = 0; i < 256; ++i) {
    const double v = relative_irradiance[i];
    if (!std::isfinite(v) || v < 0) {
      return Status::InvalidArgument("projector_response.relative_irradiance[" + std::to_string(i) +
                                     "] must be finite and >= 0");
    }
    if (i > 0 && v < relative_irradiance[i - 1]) {
      return Status::InvalidArgument("projector_response.relative_irradiance decreases at grey " + std::to_string(i));
    }
  }
  if (std::abs(relative_irradiance[255] - 1.0) > 1e-9) {
    return Status::InvalidArgument("projector_response.relative_irradiance[255] must be 1");
  }
  return Status::Ok();
}

double ProjectorResponseFunction::Irradiance(double grey) const {
  grey = std::clamp(grey, 0.0, 255.0);
  const int g0 = std::min(static_cast<int>(grey), 254);
  const double t = grey - g0;
  return (1 - t) * relative_irradiance[g0] + t * relative_irradiance[g0 + 1];
}

double ProjectorResponseFunction::GreyForIrradiance(double e) const {
  if (e <= relative_irradiance.front()) return 0.0;
  if (e >= relative_irradiance.back()) return 255.0;
  const auto it = std::upper_bound(relative_irradiance.begin(), relative_irradiance.end(), e);
  const int g1 = static_cast<int>(it - relative_irradiance.begin());
  const int g0 = g1 - 1;
  const double d = relative_irradiance[g1] - relative_irradiance[g0];
  return d > 0 ? g0 + (e - relative_irradiance[g0]) / d : g0;
}

cv::Mat ProjectorResponseFunction::IrradianceImage(const cv::Mat& pattern) const {
  cv::Mat out(pattern.size(), CV_32FC1);
  for (int y = 0; y < pattern.rows; ++y) {
    const uint8_t* p = pattern.ptr<uint8_t>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < pattern.cols; ++x) o[x] = static_cast<float>(relative_irradiance[p[x]]);
  }
  return out;
}

double ProjectorCalibrationExposureUs(int grey, double exposure_min_us, double exposure_max_us) {
  const double a = std::log(exposure_max_us), b = std::log(exposure_min_us);
  return std::exp(a + (b - a) / 255.0 * grey);
}

StatusOr<ProjectorResponseFunction> EstimateProjectorResponse(const std::vector<ProjectorResponseCapture>& captures,
                                                              const CameraResponseFunction& camera_response,
                                                              const ProjectorResponseOptions& options) {
  INSPECT_RETURN_IF_ERROR(camera_response.Validate());
  std::map<int, const ProjectorResponseCapture*> by_level;
  for (size_t k = 0; k < captures.size(); ++k) {
    const auto& c = captures[k];
    const std::string name = "captures[" + std::to_string(k) + "]";
    if (c.grey < 0 || c.grey > 255) return Status::InvalidArgument(name + ".grey must be 0..255");
    if (!(c.exposure_us > 0)) return Status::InvalidArgument(name + ".exposure_us must be > 0");
    if (c.image.empty() || c.image.channels() != 1 || (c.image.depth() != CV_8U && c.image.depth() != CV_16U)) {
      return Status::InvalidArgument(name + ".image must be CV_8UC1 or CV_16UC1");
    }
    if (!captures.empty() && c.image.size() != captures[0].image.size()) {
      return Status::InvalidArgument(name + ".image differs in size from captures[0]");
    }
    by_level[c.grey] = &c;
  }
  if (!by_level.count(255)) return Status::InvalidArgument("captures: grey 255 is required (eq. 4.9)");
  if (by_level.size() < 2) return Status::InvalidArgument("captures: need at least 2 grey levels");

  const double scale = (camera_response.levels - 1) / 255.0;
  const int lo = static_cast<int>(std::lround(options.min_valid_grey * scale));
  const int hi = static_cast<int>(std::lround(options.max_valid_grey * scale));
  const cv::Size size = captures[0].image.size();
  const cv::Rect roi = options.roi.area() > 0 ? (options.roi & cv::Rect({0, 0}, size)) : cv::Rect({0, 0}, size);
  if (roi.area() == 0) return Status::InvalidArgument("options.roi lies outside the image");

  const ProjectorResponseCapture& white = *by_level.at(255);
  const cv::Mat e_white = camera_response.Radiance(white.image(roi), white.exposure_us);
  cv::Mat white_z;
  white.image(roi).convertTo(white_z, CV_32S);

  ProjectorResponseFunction out;
  std::vector<std::pair<int, double>> points;
  double cv_sum = 0;
  int cv_count = 0;
  for (const auto& [grey, cap] : by_level) {
    if (grey == 255) {
      points.emplace_back(255, 1.0);
      continue;
    }
    const cv::Mat e = camera_response.Radiance(cap->image(roi), cap->exposure_us);
    cv::Mat z;
    cap->image(roi).convertTo(z, CV_32S);
    double sum = 0, sum2 = 0;
    long n = 0;
    for (int y = 0; y < roi.height; ++y) {
      const float* pe = e.ptr<float>(y);
      const float* pw = e_white.ptr<float>(y);
      const int* pz = z.ptr<int>(y);
      const int* pzw = white_z.ptr<int>(y);
      for (int x = 0; x < roi.width; ++x) {
        if (pz[x] < lo || pz[x] > hi || pzw[x] < lo || pzw[x] > hi || pw[x] <= 0) continue;
        const double r = pe[x] / pw[x];
        sum += r;
        sum2 += r * r;
        ++n;
      }
    }
    if (n == 0) {
      // Entirely black even at dt_max (eq. 4.8): the level lies below what the camera can
      // resolve; record zero irradiance rather than fail (typically only grey 0 on a rig
      // without black-level leakage).
      if (cv::mean(z)[0] < lo) {
        points.emplace_back(grey, 0.0);
        continue;
      }
      return Status::InvalidArgument("capture of grey " + std::to_string(grey) +
                                     ": no pixel inside the valid grey range (check exposure)");
    }
    const double mean = sum / n;
    points.emplace_back(grey, mean);
    if (mean > 0) {
      cv_sum += std::sqrt(std::max(0.0, sum2 / n - mean * mean)) / mean;
      ++cv_count;
    }
    out.measured_levels.push_back(grey);
  }
  out.measured_levels.push_back(255);
  out.pixel_ratio_cv = cv_count ? cv_sum / cv_count : 0.0;
  // Interpolate every level between measured ones (flat extrapolation below the lowest).
  out.relative_irradiance.assign(256, 0.0);
  for (int i = 0; i < 256; ++i) {
    if (i <= points.front().first) {
      out.relative_irradiance[i] = points.front().second;
      continue;
    }
    size_t k = 1;
    while (k < points.size() && points[k].first < i) ++k;
    const auto& [g0, v0] = points[k - 1];
    const auto& [g1, v1] = points[k];
    out.relative_irradiance[i] = v0 + (v1 - v0) * (i - g0) / static_cast<double>(g1 - g0);
  }
  out.relative_irradiance[255] = 1.0;
  for (int i = 1; i < 256; ++i)
    out.relative_irradiance[i] = std::max(out.relative_irradiance[i], out.relative_irradiance[i - 1]);
  // A noisy level just below 255 may have exceeded 1 and been carried on; renormalise.
  for (int i = 0; i < 255; ++i) out.relative_irradiance[i] = std::min(out.relative_irradiance[i], 1.0);
  double emin = 1e300, emax = 0;
  for (const auto& c : captures) {
    emin = std::min(emin, c.exposure_us);
    emax = std::max(emax, c.exposure_us);
  }
  out.exposure_min_us = emin;
  out.exposure_max_us = emax;
  return out;
}

}  // namespace inspection
