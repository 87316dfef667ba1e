// Physics of the simulated rig as the thesis's rig shows it: sharp in-focus frames, projected
// patterns sharp only in focus, saturation on the cutter, standard SFF failing on the
// textureless lens where a projected checkerboard succeeds (thesis 5.2, 6.1, 6.2), the
// projector-to-camera mapping seen through the camera, and the 1 um step resolved.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

#include "core/sff/sff_engine.h"
#include "devices/sim/simulated_rig.h"

namespace inspection {
namespace {

// Standard SFF of the thesis (STD): Tenengrad 7x7, three-point Gaussian interpolation.
SffOptions TenengradGaussian() {
  SffOptions o;
  o.focus_measure = FocusMeasure::kTenengrad;
  o.window_px = 7;
  o.interpolation = DepthInterpolation::kGaussian;
  // The physics is under test here, not the engine's confidence threshold: keep every depth.
  o.min_confidence = 0.0;
  return o;
}

std::unique_ptr<Rig> MakeRig(const std::string& specimen, cv::Size size = {256, 192}, bool noise = true) {
  SimulatedRigOptions o;
  o.specimen = specimen;
  o.camera_size = size;
  if (!noise) {
    o.shot_noise = false;
    o.read_noise_dn = 0.0;
  }
  auto rig = CreateSimulatedRig(o);
  EXPECT_TRUE(rig.ok()) << rig.status().ToString();
  return rig.ok() ? std::move(rig).value() : nullptr;
}

cv::Mat CaptureAt(Rig& rig, double z_um) {
  EXPECT_TRUE(rig.stage().MoveTo(z_um).ok());
  auto frame = rig.camera().Capture();
  EXPECT_TRUE(frame.ok()) << frame.status().ToString();
  return frame.ok() ? *frame : cv::Mat();
}

// Mean squared gradient (Tenengrad energy) of a region.
double GradientEnergy(const cv::Mat& img) {
  cv::Mat f, gx, gy;
  img.convertTo(f, CV_32F);
  cv::Sobel(f, gx, CV_32F, 1, 0);
  cv::Sobel(f, gy, CV_32F, 0, 1);
  return cv::mean(gx.mul(gx) + gy.mul(gy))[0];
}

cv::Mat Checkerboard(cv::Size size, int square_px) {
  cv::Mat p(size, CV_8UC1);
  for (int r = 0; r < size.height; ++r) {
    for (int c = 0; c < size.width; ++c) p.at<uint8_t>(r, c) = ((r / square_px + c / square_px) % 2) ? 255 : 0;
  }
  return p;
}

DepthResult ScanSff(Rig& rig, const cv::Mat& pattern) {
  const ScanDefaults d = rig.scan_defaults();
  EXPECT_TRUE(rig.projector().Show(pattern).ok());
  EXPECT_TRUE(rig.camera().SetExposure(d.exposure_us).ok());
  auto engine = SffEngine::Create(TenengradGaussian(), rig.camera().frame_size(), CV_8UC1);
  EXPECT_TRUE(engine.ok());
  for (double z = d.z_start_um; z <= d.z_end_um + 1e-9; z += d.z_step_um) {
    EXPECT_TRUE((*engine)->PushFrame(CaptureAt(rig, z), z).ok());
  }
  auto result = (*engine)->Finish();
  EXPECT_TRUE(result.ok());
  return result.ok() ? *result : DepthResult{};
}

// Share of interior pixels whose depth is within tolerance of the ground truth.
double ReliableFraction(const cv::Mat& depth, const cv::Mat& truth, double tolerance_um, int border = 8) {
  int good = 0, total = 0;
  for (int r = border; r < depth.rows - border; ++r) {
    for (int c = border; c < depth.cols - border; ++c) {
      ++total;
      const float d = depth.at<float>(r, c);
      good += std::isfinite(d) && std::abs(d - truth.at<float>(r, c)) < tolerance_um ? 1 : 0;
    }
  }
  return static_cast<double>(good) / total;
}

TEST(SimulatedPhysicsTest, InFocusFrameIsSharpestAndBlurGrowsWithDefocus) {
  auto rig = MakeRig("plane");
  ASSERT_TRUE(rig);
  const double h = rig->simulation()->SpecimenZRangeUm().first;
  double previous = GradientEnergy(CaptureAt(*rig, h));
  for (double dz : {2.5, 5.0, 10.0, 15.0, 30.0}) {
    const double above = GradientEnergy(CaptureAt(*rig, h + dz));
    const double below = GradientEnergy(CaptureAt(*rig, h - dz));
    EXPECT_LT(above, previous) << dz;
    EXPECT_NEAR(above / below, 1.0, 0.1) << "defocus is symmetric, dz " << dz;
    previous = above;
  }
  // Two steps away the texture's gradient energy has dropped by more than 5x.
  EXPECT_LT(GradientEnergy(CaptureAt(*rig, h + 10.0)), 0.2 * GradientEnergy(CaptureAt(*rig, h)));
}

TEST(SimulatedPhysicsTest, HigherApertureHasShallowerDepthOfField) {
  auto relative_sharpness = [](double na) {
    SimulatedRigOptions o;
    o.specimen = "plane";
    o.camera_size = {128, 96};
    o.numerical_aperture = na;
    auto rig = CreateSimulatedRig(o);
    EXPECT_TRUE(rig.ok());
    return GradientEnergy(CaptureAt(**rig, 205.0)) / GradientEnergy(CaptureAt(**rig, 200.0));
  };
  EXPECT_LT(relative_sharpness(0.6), 0.5 * relative_sharpness(0.3));
}

TEST(SimulatedPhysicsTest, ProjectedCheckerboardIsSharpOnlyWhereInFocus) {
  // The lens has no texture of its own; its height varies across x (apex at the centre).
  auto rig = MakeRig("lens", {512, 96}, /*noise=*/false);
  ASSERT_TRUE(rig);
  ASSERT_TRUE(rig->projector().Show(Checkerboard(rig->projector().resolution(), 2)).ok());
  const cv::Mat truth = rig->simulation()->GroundTruthDepthUm();
  const cv::Rect edge(32, 24, 24, 48), centre(244, 24, 24, 48);
  const double z = truth.at<float>(48, 44);  // in focus at the edge window
  const double d_centre = truth.at<float>(48, 256) - z;
  ASSERT_GT(d_centre, 10.0);
  const cv::Mat frame = CaptureAt(*rig, z);
  EXPECT_GT(GradientEnergy(frame(edge)), 5.0 * GradientEnergy(frame(centre)))
      << "defocus " << d_centre << " um at the centre";
  // Focusing on the apex reverses it.
  const cv::Mat frame2 = CaptureAt(*rig, truth.at<float>(48, 256));
  EXPECT_GT(GradientEnergy(frame2(centre)), 5.0 * GradientEnergy(frame2(edge)));
}

TEST(SimulatedPhysicsTest, CutterSaturatesUnderUniformLight) {
  auto rig = MakeRig("cutter");
  ASSERT_TRUE(rig);
  const ScanDefaults d = rig->scan_defaults();
  ASSERT_TRUE(rig->projector().ShowUniform(128).ok());
  ASSERT_TRUE(rig->camera().SetExposure(d.exposure_us).ok());
  const auto range = rig->simulation()->SpecimenZRangeUm();
  for (double z = range.first; z <= range.second; z += 5.0) {
    const cv::Mat frame = CaptureAt(*rig, z);
    const double saturated = cv::countNonZero(frame == 255) / static_cast<double>(frame.total());
    EXPECT_GT(saturated, 0.05) << "z " << z;
    // Calibrated to mean 128 in focus; defocus spreads the clipped excess of the glints.
    EXPECT_NEAR(cv::mean(frame)[0], 140.0, 30.0) << "z " << z;
  }
}

TEST(SimulatedPhysicsTest, CoinFieldSaturatesWhileItsReliefIsDim) {
  auto rig = MakeRig("coin");
  ASSERT_TRUE(rig);
  ASSERT_TRUE(rig->camera().SetExposure(rig->scan_defaults().exposure_us).ok());
  const cv::Mat truth = rig->simulation()->GroundTruthDepthUm();
  const cv::Mat frame = CaptureAt(*rig, truth.at<float>(96, 128));  // disc top in focus
  EXPECT_GT(cv::countNonZero(frame == 255) / static_cast<double>(frame.total()), 0.2);
  EXPECT_LT(cv::mean(frame(cv::Rect(100, 80, 20, 20)))[0], 80.0);  // frosted relief
}

// Textureless specimens (thesis 6.2.1: HF-LENS, HF-MIRROR): uniform light gives no depth,
// a projected 2x2-projector-pixel checkerboard (6.8 camera px, fits the 7x7 window) does.
class TexturelessTest : public ::testing::TestWithParam<std::string> {};

TEST_P(TexturelessTest, NeedsProjectedTexture) {
  auto rig = MakeRig(GetParam());
  ASSERT_TRUE(rig);
  const cv::Mat truth = rig->simulation()->GroundTruthDepthUm();
  const double step = rig->scan_defaults().z_step_um;
  const cv::Mat uniform(rig->projector().resolution(), CV_8UC1, cv::Scalar(128));
  const DepthResult std_result = ScanSff(*rig, uniform);
  const DepthResult hf_result = ScanSff(*rig, Checkerboard(rig->projector().resolution(), 2));
  const double std_reliable = ReliableFraction(std_result.depth_um, truth, 0.5 * step);
  const double hf_reliable = ReliableFraction(hf_result.depth_um, truth, 0.5 * step);
  std::printf("%s: depth within half a step: uniform %.3f, checkerboard %.3f (valid %.3f)\n", GetParam().c_str(),
              std_reliable, hf_reliable, hf_result.valid_fraction);
  EXPECT_LT(std_reliable, 0.4);
  EXPECT_GT(hf_reliable, 0.95);
}

INSTANTIATE_TEST_SUITE_P(LensAndMirror, TexturelessTest, ::testing::Values("lens", "mirror"));

TEST(SimulatedPhysicsTest, MirrorMappingSeenByTheCameraMatchesTheGeometry) {
  auto rig = MakeRig("mirror", {256, 192}, /*noise=*/false);
  ASSERT_TRUE(rig);
  const cv::Mat truth = rig->simulation()->GroundTruthDepthUm();
  // Sparse grid of single projector pixels (thesis Fig. 4.14), mirror in focus.
  cv::Mat grid(rig->projector().resolution(), CV_8UC1, cv::Scalar(0));
  std::vector<cv::Point> lit;
  for (int y = 330; y <= 390; y += 10) {  // the 256x192 camera sees ~56 x 75 projector px
    for (int x = 620; x <= 660; x += 10) {
      grid.at<uint8_t>(y, x) = 128;
      lit.emplace_back(x, y);
    }
  }
  ASSERT_TRUE(rig->projector().Show(grid).ok());
  ASSERT_TRUE(rig->camera().SetExposure(rig->scan_defaults().exposure_us).ok());
  const cv::Mat frame = CaptureAt(*rig, truth.at<float>(96, 128));
  cv::Mat f;
  frame.convertTo(f, CV_64F);
  // Background: black level plus the projector's black floor.
  cv::Mat dark_pattern(rig->projector().resolution(), CV_8UC1, cv::Scalar(0));
  ASSERT_TRUE(rig->projector().Show(dark_pattern).ok());
  const double background = cv::mean(CaptureAt(*rig, truth.at<float>(96, 128)))[0];
  ProjectorCameraGeometry geometry(ProjectorCameraGeometryOptions{}, {256, 192}, rig->projector().resolution());
  int checked = 0;
  for (const cv::Point& p : lit) {
    const cv::Point2d expected = geometry.ProjectorToCamera(p);
    const cv::Rect window(static_cast<int>(expected.x) - 7, static_cast<int>(expected.y) - 7, 15, 15);
    if ((window & cv::Rect(0, 0, 256, 192)) != window) continue;
    cv::Mat patch = cv::max(f(window) - background, 0.0);
    const cv::Moments m = cv::moments(patch);
    ASSERT_GT(m.m00, 0.0);
    EXPECT_NEAR(window.x + m.m10 / m.m00, expected.x, 0.15) << p;
    EXPECT_NEAR(window.y + m.m01 / m.m00, expected.y, 0.15) << p;
    ++checked;
  }
  EXPECT_EQ(checked, 35);
}

TEST(SimulatedPhysicsTest, OneMicrometreStepIsResolved) {
  auto rig = MakeRig("step1um");
  ASSERT_TRUE(rig);
  const DepthResult r = ScanSff(*rig, cv::Mat(rig->projector().resolution(), CV_8UC1, cv::Scalar(128)));
  auto mean_depth = [&](int c0, int c1) {
    double sum = 0;
    int n = 0;
    for (int r0 = 16; r0 < 176; ++r0) {
      for (int c = c0; c < c1; ++c) {
        const float d = r.depth_um.at<float>(r0, c);
        if (std::isfinite(d)) sum += d, ++n;
      }
    }
    return sum / n;
  };
  const double step = mean_depth(140, 240) - mean_depth(16, 116);
  std::printf("step1um: measured step %.3f um\n", step);
  EXPECT_NEAR(step, 1.0, 0.35);
}

}  // namespace
}  // namespace inspection
