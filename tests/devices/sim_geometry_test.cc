// Projector-to-camera mapping of the simulated rig against its defined geometry (thesis 4.3.2):
// scale 3.4, axes swapped and inverted, 0.1 degree skew, barrel distortion, box pixels.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "devices/sim/projector_camera_geometry.h"

namespace inspection {
namespace {

TEST(ProjectorCameraGeometryTest, CentreScaleAndSwappedInvertedAxes) {
  ProjectorCameraGeometryOptions o;
  o.skew_deg = 0.0;
  o.barrel_k1_per_px2 = 0.0;
  const ProjectorCameraGeometry g(o, {1025, 769}, {1281, 721});
  const cv::Point2d c = g.CameraToProjector({512, 384});
  EXPECT_NEAR(c.x, 640.0, 1e-12);
  EXPECT_NEAR(c.y, 360.0, 1e-12);
  // +34 camera px along x -> projector y decreases by 10; along y -> projector x decreases.
  const cv::Point2d px = g.CameraToProjector({512 + 34, 384});
  EXPECT_NEAR(px.x, 640.0, 1e-12);
  EXPECT_NEAR(px.y, 350.0, 1e-12);
  const cv::Point2d py = g.CameraToProjector({512, 384 + 34});
  EXPECT_NEAR(py.x, 630.0, 1e-12);
  EXPECT_NEAR(py.y, 360.0, 1e-12);
}

TEST(ProjectorCameraGeometryTest, SkewAndBarrelDistortionAsDefined) {
  ProjectorCameraGeometryOptions o;  // defaults: 0.1 deg skew, 1.5 px at r = 640 px
  const ProjectorCameraGeometry g(o, {1025, 769}, {1281, 721});
  // A camera point at radius r: projector radius (times 3.4) is r (1 + k1 r^2).
  const double r = 600.0;
  const cv::Point2d p = g.CameraToProjector({512 + r * 0.6, 384 + r * 0.8});
  const double pr = std::hypot(p.x - 640.0, p.y - 360.0) * 3.4;
  EXPECT_NEAR(pr - r, o.barrel_k1_per_px2 * r * r * r, 1e-9);
  EXPECT_NEAR(o.barrel_k1_per_px2 * 640.0 * 640.0 * 640.0, 1.5, 0.01);
  // Skew: the camera x axis maps to a projector direction rotated by 0.1 degree.
  const cv::Point2d a = g.CameraToProjector({512 + 100, 384});
  const double angle_deg = std::atan2(640.0 - a.x, 360.0 - a.y) * 180.0 / CV_PI;
  EXPECT_NEAR(angle_deg, 0.1, 1e-3);
}

TEST(ProjectorCameraGeometryTest, ProjectorToCameraInvertsTheMapping) {
  const ProjectorCameraGeometry g(ProjectorCameraGeometryOptions{}, {1600, 1200}, {1280, 720});
  for (const cv::Point2d p : {cv::Point2d(640, 360), cv::Point2d(500.5, 200.25), cv::Point2d(780, 520)}) {
    const cv::Point2d c = g.ProjectorToCamera(p);
    const cv::Point2d back = g.CameraToProjector(c);
    EXPECT_NEAR(back.x, p.x, 1e-6);
    EXPECT_NEAR(back.y, p.y, 1e-6);
  }
}

TEST(ProjectorCameraGeometryTest, SamplingMapsAverageBoxPixels) {
  ProjectorCameraGeometryOptions o;
  o.barrel_k1_per_px2 = 0.0;
  o.skew_deg = 0.0;
  const cv::Size cam(200, 160), proj(128, 96);
  const ProjectorCameraGeometry g(o, cam, proj);
  cv::Mat mx, my;
  g.BuildSamplingMaps(&mx, &my);
  // One lit projector pixel: its light on the camera is its area, 3.4 x 3.4 camera pixels,
  // centred where the geometry puts it.
  cv::Mat p(proj, CV_32FC1, cv::Scalar(0));
  p.at<float>(50, 60) = 1.0f;
  cv::Mat c;
  cv::remap(p, c, mx, my, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  EXPECT_NEAR(cv::sum(c)[0], 3.4 * 3.4, 0.3);
  const cv::Moments m = cv::moments(c);
  const cv::Point2d expected = g.ProjectorToCamera({60, 50});
  EXPECT_NEAR(m.m10 / m.m00, expected.x, 0.05);
  EXPECT_NEAR(m.m01 / m.m00, expected.y, 0.05);
  // Box pixels, not bilinear tents: a camera pixel well inside the projector pixel sees it fully.
  EXPECT_FLOAT_EQ(c.at<float>(static_cast<int>(std::lround(expected.y)), static_cast<int>(std::lround(expected.x))),
                  1.0f);
}

}  // namespace
}  // namespace inspection
