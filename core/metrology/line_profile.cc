// Extracted line profiles with a band average and per-sample uncertainty.
#include "core/metrology/line_profile.h"

#include <cmath>
#include <cstdio>

namespace inspection {
namespace {

constexpr size_t kMaxProfileSamples = 100000;
constexpr double kEdgeSlackPx = 1e-6;

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// Bilinear depth at image coordinates (px); false when outside or a contributing pixel has no depth.
bool SampleBilinear(const cv::Mat& depth, double x, double y, double* z, cv::Point* nearest) {
  const double fx = x - 0.5, fy = y - 0.5;  // continuous pixel index
  const int x0 = int(std::floor(fx)), y0 = int(std::floor(fy));
  const double wx = fx - x0, wy = fy - y0;
  double acc = 0.0;
  for (int dy = 0; dy <= 1; ++dy) {
    for (int dx = 0; dx <= 1; ++dx) {
      const double w = (dx ? wx : 1.0 - wx) * (dy ? wy : 1.0 - wy);
      if (w <= 0.0) continue;
      const int c = x0 + dx, r = y0 + dy;
      // Half a pixel beyond the outermost centres the edge pixel stands in (clamped).
      const int cc = std::clamp(c, 0, depth.cols - 1), rc = std::clamp(r, 0, depth.rows - 1);
      if (std::abs(cc - c) > 1 || std::abs(rc - r) > 1) return false;
      const float v = depth.at<float>(rc, cc);
      if (!std::isfinite(v)) return false;
      acc += w * double(v);
    }
  }
  *z = acc;
  *nearest =
      cv::Point(std::clamp(int(std::floor(x)), 0, depth.cols - 1), std::clamp(int(std::floor(y)), 0, depth.rows - 1));
  return true;
}

}  // namespace

Status LineProfileOptions::Validate(cv::Size image_size, double pixel_size_um, const std::string& field) const {
  double scale = 1.0;
  if (unit == RoiUnit::kMicrometre) {
    if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um)) {
      return Status::InvalidArgument(field + ": coordinates in um need a pixel size > 0");
    }
    scale = 1.0 / pixel_size_um;
  }
  for (const auto& [name, p] : {std::pair<const char*, RoiPoint>{"start", start}, {"end", end}}) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y))
      return Status::InvalidArgument(field + "." + name + " is not a finite point");
    const double x = p.x * scale, y = p.y * scale;
    if (x < -kEdgeSlackPx || y < -kEdgeSlackPx || x > image_size.width + kEdgeSlackPx ||
        y > image_size.height + kEdgeSlackPx) {
      return Status::InvalidArgument(field + "." + name + " = (" + Num(x) + ", " + Num(y) +
                                     ") px lies outside the image " + std::to_string(image_size.width) + "x" +
                                     std::to_string(image_size.height) + " px");
    }
  }
  if (!(width_px >= 1.0 && width_px <= 1001.0)) {
    return Status::InvalidArgument(field + ".width_px must be in 1..1001, got " + Num(width_px));
  }
  if (!(spacing_px >= 0.1 && spacing_px <= 100.0)) {
    return Status::InvalidArgument(field + ".spacing_px must be in 0.1..100, got " + Num(spacing_px));
  }
  const double length_px = std::hypot(end.x - start.x, end.y - start.y) * scale;
  if (!(length_px >= spacing_px)) {
    return Status::InvalidArgument(field + ": the line is " + Num(length_px) +
                                   " px long, shorter than one sample spacing (" + Num(spacing_px) + " px)");
  }
  if (length_px / spacing_px + 1 > double(kMaxProfileSamples)) {
    return Status::InvalidArgument(field + ": more than " + std::to_string(kMaxProfileSamples) + " samples");
  }
  return Status::Ok();
}

double LineProfile::coverage_percent() const {
  if (height_um.empty()) return 0.0;
  size_t n = 0;
  for (double h : height_um) n += std::isfinite(h);
  return 100.0 * double(n) / double(height_um.size());
}

StatusOr<LineProfile> ExtractLineProfile(const cv::Mat& depth_um, double pixel_size_um,
                                         const LineProfileOptions& options, const DepthNoiseModel* noise,
                                         const std::string& field) {
  if (depth_um.empty() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument(field + ": the depth map must be a non-empty CV_32FC1 image");
  }
  if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um)) {
    return Status::InvalidArgument(field + ": pixel_size_um must be > 0");
  }
  INSPECT_RETURN_IF_ERROR(options.Validate(depth_um.size(), pixel_size_um, field));
  const double scale = options.unit == RoiUnit::kMicrometre ? 1.0 / pixel_size_um : 1.0;
  const double x0 = options.start.x * scale, y0 = options.start.y * scale;
  const double x1 = options.end.x * scale, y1 = options.end.y * scale;
  const double length_px = std::hypot(x1 - x0, y1 - y0);
  const double ux = (x1 - x0) / length_px, uy = (y1 - y0) / length_px;  // along
  const double nx = -uy, ny = ux;                                       // across
  const int count = int(std::floor(length_px / options.spacing_px + 1e-9)) + 1;
  const int cross = std::max(1, int(std::floor(options.width_px + 1e-9)));
  LineProfile prof;
  prof.length_um = length_px * pixel_size_um;
  // Correlation of two cross samples k px apart under the box model.
  const double w = noise ? double(noise->correlation_px) : 1.0;
  std::vector<double> rho(cross, 0.0);
  for (int k = 0; k < cross; ++k) {
    rho[k] = std::max(0.0, 1.0 - std::abs(k * nx) / w) * std::max(0.0, 1.0 - std::abs(k * ny) / w);
  }
  std::vector<int> used;
  for (int i = 0; i < count; ++i) {
    const double s = i * options.spacing_px;
    const double cx = x0 + s * ux, cy = y0 + s * uy;
    double sum = 0.0, sigma_sum = 0.0;
    used.clear();
    for (int k = 0; k < cross; ++k) {
      const double t = k - 0.5 * (cross - 1);
      double z;
      cv::Point nearest;
      if (!SampleBilinear(depth_um, cx + t * nx, cy + t * ny, &z, &nearest)) continue;
      sum += z;
      used.push_back(k);
      if (noise) {
        const float sg = noise->sigma_um.at<float>(nearest);
        sigma_sum += std::isfinite(sg) ? double(sg) : noise->global_sigma_um;
      }
    }
    prof.position_um.push_back(s * pixel_size_um);
    prof.x_um.push_back(cx * pixel_size_um);
    prof.y_um.push_back(cy * pixel_size_um);
    prof.cross_samples.push_back(int(used.size()));
    if (used.empty()) {
      prof.height_um.push_back(std::nan(""));
      prof.uncertainty_um.push_back(std::nan(""));
      continue;
    }
    const double m = double(used.size()), h = sum / m;
    prof.height_um.push_back(h);
    if (!noise) {
      prof.uncertainty_um.push_back(std::nan(""));
      continue;
    }
    double corr = 0.0;
    for (int a : used) {
      for (int b : used) corr += rho[std::abs(a - b)];
    }
    const double sigma = sigma_sum / m;
    const ZGrid::Position p = noise->grid.Locate(h);
    const double lin = noise->linearity.Rms() * p.step_um;
    prof.uncertainty_um.push_back(
        std::sqrt(sigma * sigma * corr / (m * m) + lin * lin + noise->stage_u_um * noise->stage_u_um));
  }
  return prof;
}

}  // namespace inspection
