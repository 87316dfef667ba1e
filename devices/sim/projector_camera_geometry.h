// Geometric mapping between projector and camera pixels of the simulated rig (thesis 4.3.2):
// ~3.4 camera pixels per projector pixel, projector x along the inverted camera y axis and
// projector y along the inverted camera x axis (Fig. 4.12), a 0.1 degree skew and a mild
// radial (barrel) distortion growing towards the image corners (Fig. 4.15).
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"

namespace inspection {

struct ProjectorCameraGeometryOptions {
  double camera_px_per_projector_px = 3.4;  // thesis 4.3.2: 1x1 projector px ~ 3.4x3.4 camera px
  double skew_deg = 0.1;                    // residual rotation of the projector grid
  // Radial distortion of the projector image in the camera: a camera pixel at radius r (camera
  // px from the image centre) sees the projector at radius r * (1 + k1 * r^2) (barrel: the
  // projector grid looks compressed towards the corners). 1.5 px at r = 640 px.
  double barrel_k1_per_px2 = 5.7e-9;
  // Projector pixel seen at the camera centre, relative to the projector centre.
  cv::Point2d projector_offset_px{0.0, 0.0};

  Status Validate() const;
};

// Pixel centres are at integer coordinates in both devices. Immutable; thread-safe.
class ProjectorCameraGeometry {
 public:
  ProjectorCameraGeometry(const ProjectorCameraGeometryOptions& options, cv::Size camera_size, cv::Size projector_size);

  // Projector coordinate seen by the camera pixel (x, y) (the thesis's camera LUT).
  cv::Point2d CameraToProjector(cv::Point2d camera) const;
  // Camera coordinate of the centre of projector pixel (x, y) (the thesis's projector LUT);
  // inverts CameraToProjector by Newton iteration (to < 1e-6 px).
  cv::Point2d ProjectorToCamera(cv::Point2d projector) const;

  // Maps for cv::remap (CV_32FC1, camera size) that sample a projector image with the exact
  // overlap of each camera pixel's footprint with the square projector pixels (box pixels, not
  // bilinear blur): the fractional part of the sampling coordinate is the overlap fraction.
  void BuildSamplingMaps(cv::Mat* map_x, cv::Mat* map_y) const;

  cv::Size camera_size() const { return camera_size_; }
  cv::Size projector_size() const { return projector_size_; }
  const ProjectorCameraGeometryOptions& options() const { return options_; }

 private:
  ProjectorCameraGeometryOptions options_;
  cv::Size camera_size_, projector_size_;
  cv::Point2d camera_centre_, projector_centre_;
  double cos_skew_, sin_skew_;
};

}  // namespace inspection
