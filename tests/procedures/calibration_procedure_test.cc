// Calibration procedure against the simulated rig: every recovered model is compared with the
// simulator's true parameters (crf, prf, projector->camera geometry), the scatter matrix's
// prediction error is bounded, and step selection, dependencies and cancellation behave.
#include "server/procedures/calibration_procedure.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include <gtest/gtest.h>

#include "devices/sim/image_formation.h"
#include "devices/sim/projector_camera_geometry.h"
#include "devices/sim/simulated_rig.h"

namespace inspection {
namespace {

SimulatedRigOptions SmallRig() {
  SimulatedRigOptions o;
  o.camera_size = {256, 192};
  o.projector_size = {96, 72};
  o.seed = 3;
  return o;
}

CalibrationOptions FastOptions() {
  CalibrationOptions o;
  o.crf_exposure_count = 16;
  o.prf_level_step = 15;
  o.geometry_grid_spacing_px = 6;
  o.psf_defocus_um = {-10.0, 0.0, 10.0};
  o.psf_grid_spacing_px = 12;
  o.scatter_grid_spacing_px = 6;
  o.ipsf_half_range_um = 20.0;
  return o;
}

class CalibrationProcedureTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto rig = CreateSimulatedRig(SmallRig());
    ASSERT_TRUE(rig.ok()) << rig.status().ToString();
    std::atomic<bool> cancel{false};
    std::vector<CalibrationProgress> events;
    auto b = RunCalibration(**rig, FastOptions(), nullptr,
                            [&](const CalibrationProgress& p) { events.push_back(p); }, cancel);
    ASSERT_TRUE(b.ok()) << b.status().ToString();
    bundle_ = new CalibrationBundle(std::move(b).value());
    events_ = new std::vector<CalibrationProgress>(std::move(events));
    std::printf("%s", bundle_->Summary().c_str());
  }
  static void TearDownTestSuite() {
    delete bundle_;
    delete events_;
  }
  static ImageFormationOptions Truth() { return ImageFormationOptionsFor(SmallRig()).value(); }

  static CalibrationBundle* bundle_;
  static std::vector<CalibrationProgress>* events_;
};
CalibrationBundle* CalibrationProcedureTest::bundle_ = nullptr;
std::vector<CalibrationProgress>* CalibrationProcedureTest::events_ = nullptr;

TEST_F(CalibrationProcedureTest, AllStepsRunInOrderWithProgress) {
  ASSERT_NE(bundle_, nullptr);
  for (CalibrationStep s : AllCalibrationSteps()) {
    EXPECT_TRUE(bundle_->HasModel(s)) << CalibrationStepName(s);
    const auto* r = bundle_->Report(s);
    ASSERT_NE(r, nullptr);
    EXPECT_GT(r->frames_captured, 0);
    EXPECT_GT(r->duration_s, 0.0);
  }
  ASSERT_FALSE(events_->empty());
  EXPECT_EQ(events_->front().step, "camera_response");
  EXPECT_EQ(events_->back().step, "integral_psf");
  EXPECT_EQ(events_->back().step_index, 5);
  EXPECT_EQ(events_->back().step_count, 6);
  EXPECT_TRUE(bundle_->Validate().ok());
}

TEST_F(CalibrationProcedureTest, CameraResponseMatchesSimulator) {
  ASSERT_NE(bundle_, nullptr);
  const CameraResponse truth = Truth().camera;
  const CameraResponseFunction& crf = *bundle_->camera_response;
  const double t128 = std::log(truth.RelativeExposureForGrey(128));
  double worst = 0;
  for (int z = 16; z <= 240; ++z) {
    const double t = std::log(truth.RelativeExposureForGrey(z)) - t128;
    worst = std::max(worst, std::abs(crf.log_exposure[z] - t));
  }
  std::printf("crf worst |error| z 16..240: %.4f ln\n", worst);
  EXPECT_LT(worst, 0.05);
}

TEST_F(CalibrationProcedureTest, ProjectorResponseMatchesSimulator) {
  ASSERT_NE(bundle_, nullptr);
  const ProjectorResponse truth = Truth().projector;
  const ProjectorResponseFunction& prf = *bundle_->projector_response;
  double worst = 0;
  for (int i = 0; i < 256; ++i) {
    worst = std::max(worst, std::abs(prf.relative_irradiance[i] - truth.Irradiance(i) / truth.Irradiance(255)));
  }
  std::printf("prf worst |error|: %.4f of full irradiance\n", worst);
  EXPECT_LT(worst, 0.02);
}

TEST_F(CalibrationProcedureTest, LookUpTableWithinAThirdOfAPixelOfTrueGeometry) {
  ASSERT_NE(bundle_, nullptr);
  const ImageFormationOptions f = Truth();
  const ProjectorCameraGeometry truth(f.geometry, f.camera_size, f.projector_size);
  const GeometricCalibration& g = *bundle_->geometry;
  double sum = 0, worst = 0;
  int n = 0;
  for (int v = 0; v < f.projector_size.height; ++v)
    for (int u = 0; u < f.projector_size.width; ++u) {
      const cv::Vec2f c = g.projector_to_camera.at<cv::Vec2f>(v, u);
      if (!std::isfinite(c[0])) continue;
      const double e = cv::norm(cv::Point2d(c[0], c[1]) - truth.ProjectorToCamera({double(u), double(v)}));
      sum += e;
      worst = std::max(worst, e);
      ++n;
    }
  std::printf("LUT vs truth: mean %.3f px, max %.3f px over %d entries\n", sum / n, worst, n);
  EXPECT_GT(n, 60 * 45);
  EXPECT_LT(sum / n, 0.3);
  EXPECT_NEAR(g.camera_px_per_projector_px, f.geometry.camera_px_per_projector_px, 0.05);
}

TEST_F(CalibrationProcedureTest, PsfGrowsWithDefocusAndScatterPredictsTheCamera) {
  ASSERT_NE(bundle_, nullptr);
  const PsfCalibration& psf = *bundle_->psf;
  ASSERT_EQ(psf.steps.size(), 3u);
  EXPECT_GT(psf.steps[0].sigma_px, psf.steps[1].sigma_px + 1.0);
  EXPECT_GT(psf.steps[2].sigma_px, psf.steps[1].sigma_px + 1.0);
  EXPECT_GT(psf.influence_radius_px, 1.0);
  const auto* rep = bundle_->Report(CalibrationStep::kScatterMatrix);
  ASSERT_NE(rep, nullptr);
  EXPECT_LT(rep->figures.at("prediction_mae_percent"), 3.0);
  EXPECT_GT(rep->figures.at("density"), 0.0);
  const IntegralPsf& ipsf = *bundle_->integral_psf;
  EXPECT_LT(ipsf.restored_rms_error, 0.8 * ipsf.integral_rms_error);
}

}  // namespace
}  // namespace inspection
