// Geometric calibration (thesis 4.3.2, eq. 4.10): Gray-code coarse map, dot-grid sub-pixel LUT
// against a synthetic rig with known homography + barrel distortion.
#include "core/calibration/geometric_calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tests/core/calibration_synthetic.h"

namespace inspection {
namespace {
using testing_synthetic::SyntheticRig;

TEST(HomographyTest, FitsExactHomographyAndTrimsOutliers) {
  const cv::Matx33d h(2.5, 0.1, 10, -0.05, 2.4, 7, 1e-4, -2e-4, 1);
  std::vector<cv::Point2d> src, dst;
  for (int v = 0; v < 20; ++v)
    for (int u = 0; u < 30; ++u) {
      src.emplace_back(u * 3, v * 3);
      dst.push_back(ApplyHomography(h, src.back()));
    }
  dst[5] += cv::Point2d(40, -30);  // two gross outliers
  dst[77] += cv::Point2d(-25, 12);
  auto fit = FitHomography(src, dst, 3, 0.5);
  ASSERT_TRUE(fit.ok());
  for (int k : {0, 100, 599}) {
    EXPECT_NEAR(cv::norm(ApplyHomography(*fit, src[k]) - ApplyHomography(h, src[k])), 0.0, 1e-6);
  }
  EXPECT_FALSE(FitHomography({{0, 0}}, {{0, 0}}).ok());
}

TEST(GrayCodeTest, DecodesProjectorCellsAndGivesCoarseHomography) {
  SyntheticRig rig;
  rig.k_radial = 0;
  const auto patterns = MakeGrayCodePatterns(rig.projector, 2);
  std::vector<cv::Mat> caps;
  for (const auto& p : patterns) caps.push_back(rig.CaptureSharp(p.pattern));
  auto decoded = DecodeGrayCode(patterns, caps, rig.projector, 20.0);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  // Camera pixel at the true image of projector pixel (17, 11) decodes to that cell (+-1).
  const cv::Point2d c = rig.Map(17, 11);
  const cv::Vec2f d = decoded->at<cv::Vec2f>(static_cast<int>(std::lround(c.y)), static_cast<int>(std::lround(c.x)));
  EXPECT_NEAR(d[0], 17, 1.0);
  EXPECT_NEAR(d[1], 11, 1.0);
  // Outside the projector's footprint nothing decodes.
  EXPECT_TRUE(std::isnan(decoded->at<cv::Vec2f>(0, 0)[0]));
  auto h = CoarseHomographyFromGrayCode(*decoded);
  ASSERT_TRUE(h.ok()) << h.status().ToString();
  EXPECT_LT(cv::norm(ApplyHomography(*h, {20, 15}) - rig.Map(20, 15)), 1.5);
}

TEST(DotCentroidTest, SubPixelCentreOfGaussianDot) {
  cv::Mat img(40, 40, CV_32FC1, cv::Scalar(0));
  const cv::Point2d truth(19.37, 21.81);
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 40; ++x)
      img.at<float>(y, x) =
          100.0f * std::exp(-((x - truth.x) * (x - truth.x) + (y - truth.y) * (y - truth.y)) / (2 * 1.3 * 1.3));
  CentroidOptions o;
  o.patch_threshold = 0.0;
  auto c = DotCentroid(img, {18, 23}, o);
  ASSERT_TRUE(c.has_value());
  EXPECT_NEAR(c->x, truth.x, 0.01);
  EXPECT_NEAR(c->y, truth.y, 0.01);
  EXPECT_FALSE(DotCentroid(cv::Mat(40, 40, CV_32FC1, cv::Scalar(1)), {20, 20}, o).has_value());
}

TEST(GeometricCalibrationTest, LutMatchesTrueMappingAndDeviationShowsDistortion) {
  SyntheticRig rig;
  std::mt19937 rng(7);
  const auto patterns = MakeGrayCodePatterns(rig.projector, 2);
  std::vector<cv::Mat> caps;
  for (const auto& p : patterns) caps.push_back(rig.CaptureSharp(p.pattern));
  auto decoded = DecodeGrayCode(patterns, caps, rig.projector, 20.0);
  ASSERT_TRUE(decoded.ok());
  auto coarse = CoarseHomographyFromGrayCode(*decoded);
  ASSERT_TRUE(coarse.ok());

  GeometricCalibrationOptions o;
  o.grid_spacing_px = 6;
  std::vector<DotGridCapture> grids;
  for (int oy = 0; oy < o.grid_spacing_px; ++oy)
    for (int ox = 0; ox < o.grid_spacing_px; ++ox)
      grids.push_back({ox, oy, rig.Capture(MakeDotGridPattern(rig.projector, o.grid_spacing_px, ox, oy), 0.5, rng)});
  const cv::Mat black = rig.Capture(cv::Mat::zeros(rig.projector, CV_8UC1), 0.5, rng);
  auto g = EstimateGeometricCalibration(grids, black, *coarse, rig.projector, o);
  ASSERT_TRUE(g.ok()) << g.status().ToString();
  ASSERT_TRUE(g->Validate().ok());

  // LUT vs ground truth.
  double sum = 0, worst = 0;
  int n = 0;
  for (int v = 0; v < rig.projector.height; ++v)
    for (int u = 0; u < rig.projector.width; ++u) {
      const cv::Vec2f c = g->projector_to_camera.at<cv::Vec2f>(v, u);
      if (std::isnan(c[0])) continue;
      const double e = cv::norm(cv::Point2d(c[0], c[1]) - rig.Map(u, v));
      sum += e;
      worst = std::max(worst, e);
      ++n;
    }
  EXPECT_GT(n, rig.projector.area() * 9 / 10);
  EXPECT_LT(sum / n, 0.1);
  EXPECT_LT(worst, 0.3);
  // The barrel distortion is what the homography cannot follow: mean deviation well above the
  // centroid noise, and the scale/rotation of the rig come back.
  EXPECT_GT(g->lut_vs_homography_mean_px, 0.05);
  EXPECT_LT(g->lut_vs_homography_mean_px, 1.0);
  EXPECT_NEAR(g->camera_px_per_projector_px, rig.scale, 0.05);
  EXPECT_NEAR(g->projector_rotation_deg, rig.angle_rad * 180 / CV_PI, 0.1);

  // camera -> projector inverts the forward LUT.
  for (const cv::Point2d p : {cv::Point2d(10.3, 7.6), cv::Point2d(25.5, 20.2), cv::Point2d(33.1, 5.9)}) {
    const cv::Point2d cam = rig.Map(p.x, p.y);
    const cv::Point ci(static_cast<int>(std::lround(cam.x)), static_cast<int>(std::lround(cam.y)));
    const auto back = g->ProjectorFromCamera(ci);
    ASSERT_TRUE(back.has_value());
    const cv::Point2d want = rig.Unmap(ci.x, ci.y);
    EXPECT_NEAR(back->x, want.x, 0.05);
    EXPECT_NEAR(back->y, want.y, 0.05);
    const auto fwd = g->CameraFromProjector(p);
    ASSERT_TRUE(fwd.has_value());
    EXPECT_LT(cv::norm(*fwd - cam), 0.15);
  }
}

TEST(GeometricCalibrationTest, NoDotsIsFailedPrecondition) {
  SyntheticRig rig;
  std::vector<DotGridCapture> grids{{0, 0, cv::Mat(rig.camera, CV_8UC1, cv::Scalar(3))}};
  auto g = EstimateGeometricCalibration(grids, cv::Mat(rig.camera, CV_8UC1, cv::Scalar(3)),
                                        cv::Matx33d(2.6, 0, 12, 0, 2.6, 9, 0, 0, 1), rig.projector, {});
  EXPECT_EQ(g.status().code(), StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace inspection
