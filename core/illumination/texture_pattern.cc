// Checkerboard texture patterns of thesis 5.2-5.3 (eq. 5.15-5.18).
#include "core/illumination/texture_pattern.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace inspection {

StatusOr<TexturePeriod> ChooseTexturePeriod(double influence_radius_px, double camera_px_per_projector_px,
                                            int focus_window_px) {
  if (!(influence_radius_px > 0.0) || !std::isfinite(influence_radius_px)) {
    return Status::InvalidArgument("influence_radius_px must be > 0");
  }
  if (!(camera_px_per_projector_px > 0.0) || !std::isfinite(camera_px_per_projector_px)) {
    return Status::InvalidArgument("camera_px_per_projector_px must be > 0");
  }
  if (focus_window_px < 3 || focus_window_px % 2 == 0) {
    return Status::InvalidArgument("focus_window_px must be odd and >= 3");
  }
  const double lower = 2.0 * influence_radius_px;
  const double upper = double(focus_window_px) + 2.0;
  int cell = int(std::floor(lower / camera_px_per_projector_px)) + 1;
  cell = std::max(cell, 1);
  const double half = cell * camera_px_per_projector_px;
  if (!(half < upper)) {
    return Status::FailedPrecondition(
        "no checkerboard period satisfies eq. 5.15: 2 sigma_p = " + std::to_string(lower) +
        " px needs t/2 = " + std::to_string(half) + " px, not below window + 2 = " + std::to_string(upper) +
        " px; enlarge the focus window");
  }
  return TexturePeriod{cell, half};
}

cv::Mat CheckerboardMask(cv::Size projector_size, int cell_projector_px) {
  cv::Mat cb(projector_size, CV_8UC1);
  const int c = std::max(cell_projector_px, 1);
  for (int y = 0; y < cb.rows; ++y) {
    uint8_t* row = cb.ptr<uint8_t>(y);
    for (int x = 0; x < cb.cols; ++x) row[x] = ((x / c + y / c) % 2 == 0) ? 1 : 0;
  }
  return cb;
}

StatusOr<cv::Mat> MakeHfPattern(cv::Size projector_size, int cell_projector_px, double gamma) {
  if (!(gamma >= 0.0 && gamma <= 0.5)) return Status::InvalidArgument("gamma must be in [0, 0.5]");
  if (cell_projector_px < 1) return Status::InvalidArgument("cell_projector_px must be >= 1");
  if (projector_size.width <= 0 || projector_size.height <= 0) {
    return Status::InvalidArgument("projector_size must be positive");
  }
  const cv::Mat cb = CheckerboardMask(projector_size, cell_projector_px);
  const uint8_t on = cv::saturate_cast<uint8_t>(255.0 * gamma);
  const uint8_t off = cv::saturate_cast<uint8_t>(255.0 * (1.0 - gamma));
  cv::Mat out(projector_size, CV_8UC1);
  for (int y = 0; y < out.rows; ++y) {
    const uint8_t* c = cb.ptr<uint8_t>(y);
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int x = 0; x < out.cols; ++x) o[x] = c[x] ? on : off;
  }
  return out;
}

StatusOr<cv::Mat> AddHfPattern(const cv::Mat& adapted, const cv::Mat& cb, double psi) {
  if (!(psi >= 0.0 && psi <= 1.0)) return Status::InvalidArgument("psi must be in [0, 1]");
  if (adapted.empty() || (adapted.type() != CV_8UC1 && adapted.type() != CV_32FC1)) {
    return Status::InvalidArgument("adapted pattern must be CV_8UC1 or CV_32FC1");
  }
  if (cb.size() != adapted.size() || cb.type() != CV_8UC1) {
    return Status::InvalidArgument("checkerboard mask must be CV_8UC1 of the pattern's size");
  }
  cv::Mat a;
  adapted.convertTo(a, CV_32FC1);
  cv::Mat out(adapted.size(), CV_8UC1);
  const float d = float(255.0 * psi);
  for (int y = 0; y < out.rows; ++y) {
    const float* ar = a.ptr<float>(y);
    const uint8_t* c = cb.ptr<uint8_t>(y);
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int x = 0; x < out.cols; ++x) o[x] = cv::saturate_cast<uint8_t>(ar[x] + (c[x] ? d : -d));
  }
  return out;
}

StatusOr<cv::Mat> AddHfPatternToIrradiance(const cv::Mat& adapted_irradiance, const cv::Mat& cb, double psi,
                                           const ProjectorResponseFunction& prf) {
  if (!(psi >= 0.0 && psi <= 1.0)) return Status::InvalidArgument("psi must be in [0, 1]");
  if (adapted_irradiance.empty() || adapted_irradiance.type() != CV_32FC1) {
    return Status::InvalidArgument("adapted irradiance must be CV_32FC1");
  }
  if (cb.size() != adapted_irradiance.size() || cb.type() != CV_8UC1) {
    return Status::InvalidArgument("checkerboard mask must be CV_8UC1 of the irradiance's size");
  }
  INSPECT_RETURN_IF_ERROR(prf.Validate());
  // Mean irradiance of the grey pair around g; non-decreasing in g since the prf is. g stops at
  // 255 - d: above it the clamp at 255 would shrink the pair's swing (at g = 255 to 255 / 191,
  // 0.44 of full irradiance instead of 0.75 with the simulated gamma-2 projector), and the pixels
  // asking for that much light are the darkest, where texture is needed most. The pair keeps its
  // full 2d swing there and gives up mean light the projector could not supply anyway.
  const int d = int(std::lround(255.0 * psi));
  const int g_max = 255 - d;
  double pair_mean[256];
  for (int g = 0; g <= g_max; ++g) {
    pair_mean[g] = 0.5 * (prf.relative_irradiance[size_t(g + d)] + prf.relative_irradiance[size_t(std::max(g - d, 0))]);
  }
  const double* end = pair_mean + g_max + 1;
  cv::Mat out(adapted_irradiance.size(), CV_8UC1);
  for (int y = 0; y < out.rows; ++y) {
    const float* e = adapted_irradiance.ptr<float>(y);
    const uint8_t* c = cb.ptr<uint8_t>(y);
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int x = 0; x < out.cols; ++x) {
      const double* hi = std::lower_bound(static_cast<const double*>(pair_mean), end, double(e[x]));
      int g = int(hi - pair_mean);
      if (g > g_max || (g > 0 && double(e[x]) - pair_mean[g - 1] <= *hi - double(e[x]))) --g;  // nearer neighbour
      o[x] = uint8_t(std::clamp(c[x] ? g + d : g - d, 0, 255));
    }
  }
  return out;
}

cv::Mat CameraCheckerboard(cv::Size camera_size, double half_period_camera_px, double low_grey, double high_grey) {
  cv::Mat out(camera_size, CV_32FC1);
  const double h = std::max(half_period_camera_px, 1.0);
  for (int y = 0; y < out.rows; ++y) {
    float* o = out.ptr<float>(y);
    const long cy = long(std::floor(y / h));
    for (int x = 0; x < out.cols; ++x) {
      const long cx = long(std::floor(x / h));
      o[x] = float(((cx + cy) % 2 == 0) ? high_grey : low_grey);
    }
  }
  return out;
}

}  // namespace inspection
