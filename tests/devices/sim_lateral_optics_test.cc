// Focus breathing and lateral drift of the simulated rig (devices/sim/image_formation.h,
// LateralOptics): frames move exactly as configured, the default changes nothing, the ground
// truth follows into any frame's grid, and the rig config names bad keys.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

#include "core/registration/frame_registration.h"
#include "devices/rig_config.h"
#include "devices/sim/simulated_rig.h"

namespace inspection {
namespace {

SimulatedRigOptions Options(double breathing_percent, double drift_x, double drift_y, double reference_z) {
  SimulatedRigOptions o;
  o.specimen = "skew5";
  o.camera_size = {320, 240};
  o.shot_noise = false;
  o.read_noise_dn = 0.0;
  o.stage_repeatability_um = 0.0;
  o.focus_breathing_percent_per_100um = breathing_percent;
  o.lateral_drift_x_px_per_100um = drift_x;
  o.lateral_drift_y_px_per_100um = drift_y;
  o.breathing_reference_z_um = reference_z;
  return o;
}

cv::Mat FrameAt(Rig& rig, double z_um) {
  EXPECT_TRUE(rig.stage().MoveTo(z_um).ok());
  auto f = rig.camera().Capture();
  EXPECT_TRUE(f.ok());
  return f.ok() ? *f : cv::Mat();
}

TEST(SimLateralOpticsTest, FramesBreatheAndDriftAsConfigured) {
  auto plain = CreateSimulatedRig(Options(0, 0, 0, 0));
  ASSERT_TRUE(plain.ok());
  const ScanDefaults d = (*plain)->scan_defaults();
  const double z = 0.5 * (d.z_start_um + d.z_end_um);  // the middle of skew5's heights
  // Reference 100 um below z: the frame at z is 2.5 % larger and moved by (6, -4) px.
  auto breathing = CreateSimulatedRig(Options(2.5, 6.0, -4.0, z - 100.0));
  ASSERT_TRUE(breathing.ok());
  const cv::Mat a = FrameAt(**plain, z), b = FrameAt(**breathing, z);
  auto r = RegisterFrame(a, b, {});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_NEAR(r->transform.scale, 1.025, 1e-3);
  EXPECT_NEAR(r->transform.rotation_rad, 0.0, 1e-3);
  EXPECT_NEAR(r->transform.shift_x_px, 6.0, 0.15);
  EXPECT_NEAR(r->transform.shift_y_px, -4.0, 0.15);
}

TEST(SimLateralOpticsTest, AtTheReferenceZTheFramesAreTheUnperturbedOnes) {
  auto plain = CreateSimulatedRig(Options(0, 0, 0, 0));
  ASSERT_TRUE(plain.ok());
  const ScanDefaults d = (*plain)->scan_defaults();
  auto breathing = CreateSimulatedRig(Options(3.0, 5.0, 5.0, d.z_start_um));
  ASSERT_TRUE(breathing.ok());
  cv::Mat diff;
  cv::absdiff(FrameAt(**plain, d.z_start_um), FrameAt(**breathing, d.z_start_um), diff);
  double hi = 0;
  cv::minMaxLoc(diff, nullptr, &hi);
  EXPECT_LE(hi, 1.0);  // identity resampling; at most one grey level of float rounding
}

TEST(SimLateralOpticsTest, GroundTruthFollowsIntoTheFrameGrid) {
  auto rig = CreateSimulatedRig(Options(0.0, 4.0, -2.0, 0.0));
  ASSERT_TRUE(rig.ok());
  const cv::Mat truth = (*rig)->simulation()->GroundTruthDepthUm();
  const cv::Mat at0 = GroundTruthInCameraGrid(**rig, 0.0);
  EXPECT_EQ(cv::norm(truth, at0, cv::NORM_INF), 0.0);
  // At z = 100 um the drift is (4, -2) px: camera pixel (x + 4, y - 2) shows specimen (x, y).
  const cv::Mat at100 = GroundTruthInCameraGrid(**rig, 100.0);
  for (cv::Point p : {cv::Point(50, 60), cv::Point(200, 150), cv::Point(300, 30)}) {
    EXPECT_FLOAT_EQ(at100.at<float>(p.y - 2, p.x + 4), truth.at<float>(p.y, p.x)) << p;
  }
  auto plain = CreateSimulatedRig(Options(0, 0, 0, 0));
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(
      cv::norm(GroundTruthInCameraGrid(**plain, 250.0), (*plain)->simulation()->GroundTruthDepthUm(), cv::NORM_INF),
      0.0);
}

TEST(SimLateralOpticsTest, RigConfigTakesTheKeysAndNamesBadOnes) {
  auto c = ParseRigConfig(R"({"simulation": {"focus_breathing_percent_per_100um": 2.0,
      "lateral_drift_x_px_per_100um": 3, "lateral_drift_y_px_per_100um": -1, "breathing_reference_z_um": 40}})");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(c->simulation.focus_breathing_percent_per_100um, 2.0);
  EXPECT_EQ(c->simulation.lateral_drift_x_px_per_100um, 3.0);
  EXPECT_EQ(c->simulation.lateral_drift_y_px_per_100um, -1.0);
  EXPECT_EQ(c->simulation.breathing_reference_z_um, 40.0);
  auto bad = ParseRigConfig(R"({"simulation": {"focus_breathing_percent_per_100um": 50}})");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), ::testing::HasSubstr("simulation.focus_breathing_percent_per_100um"));
  auto drift = ParseRigConfig(R"({"simulation": {"lateral_drift_y_px_per_100um": -500}})");
  ASSERT_FALSE(drift.ok());
  EXPECT_THAT(drift.status().message(), ::testing::HasSubstr("simulation.lateral_drift_y_px_per_100um"));
}

}  // namespace
}  // namespace inspection
