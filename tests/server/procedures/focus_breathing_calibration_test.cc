// Calibration step focus_breathing on the simulated rig: the model it stores matches
// the rig's configured breathing and drift, and is ~0 on a rig without them.
#include <gtest/gtest.h>

#include <atomic>

#include "devices/sim/simulated_rig.h"
#include "server/procedures/calibration_procedure.h"

namespace inspection {
namespace {

SimulatedRigOptions Rig(double breathing_percent, double drift_x, double drift_y) {
  SimulatedRigOptions o;
  o.camera_size = {320, 240};
  o.seed = 5;
  o.focus_breathing_percent_per_100um = breathing_percent;
  o.lateral_drift_x_px_per_100um = drift_x;
  o.lateral_drift_y_px_per_100um = drift_y;
  return o;
}

StatusOr<CalibrationBundle> Calibrate(const SimulatedRigOptions& options) {
  auto rig = CreateSimulatedRig(options);
  if (!rig.ok()) return rig.status();
  CalibrationOptions o;
  o.steps = {CalibrationStep::kFocusBreathing};
  std::atomic<bool> cancel{false};
  return RunCalibration(**rig, o, nullptr, nullptr, cancel);
}

TEST(FocusBreathingCalibrationTest, RecoversTheRigsBreathingAndDrift) {
  auto b = Calibrate(Rig(2.0, 5.0, -3.0));
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  ASSERT_TRUE(b->focus_breathing.has_value());
  const FocusBreathingModel& m = *b->focus_breathing;
  std::printf("focus breathing: %.4f %%/100um (true 2), drift %.3f, %.3f px/100um (true 5, -3), fit %.3f px\n",
              100 * m.scale_change_per_100um, m.shift_x_px_per_100um, m.shift_y_px_per_100um, m.fit_rms_px);
  // The plane target's frames share one texture, so the neighbour registrations' small errors
  // (~5e-5 in scale per 5 um pair) are correlated: ~-0.1 %/100 um of bias remain.
  EXPECT_NEAR(100 * m.scale_change_per_100um, 2.0, 0.15);
  EXPECT_NEAR(m.shift_x_px_per_100um, 5.0, 0.3);
  EXPECT_NEAR(m.shift_y_px_per_100um, -3.0, 0.3);
  EXPECT_NEAR(m.rotation_rad_per_100um, 0.0, 1e-3);
  EXPECT_EQ(m.frame_size, cv::Size(320, 240));
  const CalibrationStepReport* r = b->Report(CalibrationStep::kFocusBreathing);
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->figures.at("scale_change_percent_per_100um"), 100 * m.scale_change_per_100um);
  EXPECT_EQ(r->figures.at("stack_frames"), 17);
  EXPECT_TRUE(b->Validate().ok());
}

TEST(FocusBreathingCalibrationTest, ARigWithoutBreathingGivesANegligibleModel) {
  auto b = Calibrate(Rig(0.0, 0.0, 0.0));
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  const FocusBreathingModel& m = *b->focus_breathing;
  // Over 100 um the frame corner (200 px from the centre) moves by less than 0.5 px (the
  // threshold below which alignment leaves frames as they are, core/sff/stack_reconstruct.h).
  EXPECT_LT(std::abs(m.scale_change_per_100um) * 200, 0.5);
  EXPECT_LT(std::abs(m.shift_x_px_per_100um), 0.25);
  EXPECT_LT(std::abs(m.shift_y_px_per_100um), 0.25);
}

}  // namespace
}  // namespace inspection
