// Projector <-> camera pixel mapping of the simulated rig (thesis 4.3.2, Fig. 4.12 and 4.15).
#include "devices/sim/projector_camera_geometry.h"

#include <algorithm>
#include <cmath>

namespace inspection {

Status ProjectorCameraGeometryOptions::Validate() const {
  if (!(camera_px_per_projector_px >= 0.5 && camera_px_per_projector_px <= 20.0)) {
    return Status::InvalidArgument("camera_px_per_projector_px must be in [0.5, 20]");
  }
  if (!(std::abs(skew_deg) <= 10.0)) return Status::InvalidArgument("skew_deg must be within +-10");
  if (!(std::abs(barrel_k1_per_px2) <= 1e-6)) {
    return Status::InvalidArgument("barrel_k1_per_px2 must be within +-1e-6");
  }
  return Status::Ok();
}

ProjectorCameraGeometry::ProjectorCameraGeometry(const ProjectorCameraGeometryOptions& options, cv::Size camera_size,
                                                 cv::Size projector_size)
    : options_(options),
      camera_size_(camera_size),
      projector_size_(projector_size),
      camera_centre_((camera_size.width - 1) / 2.0, (camera_size.height - 1) / 2.0),
      projector_centre_((projector_size.width - 1) / 2.0 + options.projector_offset_px.x,
                        (projector_size.height - 1) / 2.0 + options.projector_offset_px.y),
      cos_skew_(std::cos(options.skew_deg * CV_PI / 180.0)),
      sin_skew_(std::sin(options.skew_deg * CV_PI / 180.0)) {}

cv::Point2d ProjectorCameraGeometry::CameraToProjector(cv::Point2d camera) const {
  const double dx = camera.x - camera_centre_.x;
  const double dy = camera.y - camera_centre_.y;
  const double g = 1.0 + options_.barrel_k1_per_px2 * (dx * dx + dy * dy);
  const double ex = g * dx, ey = g * dy;
  const double rx = cos_skew_ * ex - sin_skew_ * ey;
  const double ry = sin_skew_ * ex + cos_skew_ * ey;
  const double s = options_.camera_px_per_projector_px;
  // Axes swapped and inverted (thesis Fig. 4.12).
  return {projector_centre_.x - ry / s, projector_centre_.y - rx / s};
}

cv::Point2d ProjectorCameraGeometry::ProjectorToCamera(cv::Point2d projector) const {
  const double s = options_.camera_px_per_projector_px;
  // Initial guess from the undistorted, unskewed mapping.
  cv::Point2d c(camera_centre_.x - (projector.y - projector_centre_.y) * s,
                camera_centre_.y - (projector.x - projector_centre_.x) * s);
  for (int it = 0; it < 20; ++it) {
    const cv::Point2d p = CameraToProjector(c);
    const cv::Point2d r = p - projector;
    if (std::abs(r.x) + std::abs(r.y) < 1e-9) break;
    // Numerical Jacobian d(projector)/d(camera).
    const double h = 1e-3;
    const cv::Point2d px = (CameraToProjector(c + cv::Point2d(h, 0)) - p) * (1.0 / h);
    const cv::Point2d py = (CameraToProjector(c + cv::Point2d(0, h)) - p) * (1.0 / h);
    const double det = px.x * py.y - py.x * px.y;
    c.x -= (py.y * r.x - py.x * r.y) / det;
    c.y -= (-px.y * r.x + px.x * r.y) / det;
  }
  return c;
}

void ProjectorCameraGeometry::BuildSamplingMaps(cv::Mat* map_x, cv::Mat* map_y) const {
  map_x->create(camera_size_, CV_32FC1);
  map_y->create(camera_size_, CV_32FC1);
  // Footprint of one camera pixel on the projector grid, per axis (distortion scales it).
  const double s = options_.camera_px_per_projector_px;
  auto box_coordinate = [](double u, double a) {
    // Projector pixel k covers [k - 0.5, k + 0.5). The footprint [u - a/2, u + a/2] overlaps
    // pixels k and (at most) k + 1 for a < 1; bilinear sampling at k + w with w the overlap
    // fraction of pixel k + 1 gives the exact area average.
    const double left = u - a / 2.0;
    const double k = std::floor(left + 0.5);
    const double w = std::clamp((u + a / 2.0 - (k + 0.5)) / a, 0.0, 1.0);
    return static_cast<float>(k + w);
  };
  for (int y = 0; y < camera_size_.height; ++y) {
    float* mx = map_x->ptr<float>(y);
    float* my = map_y->ptr<float>(y);
    for (int x = 0; x < camera_size_.width; ++x) {
      const cv::Point2d p = CameraToProjector({static_cast<double>(x), static_cast<double>(y)});
      const double dx = x - camera_centre_.x, dy = y - camera_centre_.y;
      const double a = (1.0 + options_.barrel_k1_per_px2 * (dx * dx + dy * dy)) / s;
      if (a >= 1.0) {
        mx[x] = static_cast<float>(p.x);
        my[x] = static_cast<float>(p.y);
      } else {
        mx[x] = box_coordinate(p.x, a);
        my[x] = box_coordinate(p.y, a);
      }
    }
  }
}

}  // namespace inspection
