// Re-positioning the part on the simulated stage (SetSimulatedPlacement): the ground truth moves
// by exactly the placement, and the random placements are repeatable with the asked spread.
#include <gtest/gtest.h>

#include <cmath>

#include "devices/sim/simulated_rig.h"

namespace inspection {
namespace {

TEST(SimulatedPlacementTest, TheGroundTruthMovesByThePlacement) {
  SimulatedRigOptions o;
  o.specimen = "skew5";  // 5 deg about y: height rises along x
  o.camera_size = {64, 48};
  auto created = CreateSimulatedRig(o);
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  Rig& rig = **created;
  const cv::Mat before = rig.simulation()->GroundTruthDepthUm();
  SimulatedPlacement p;
  p.dx_um = 3 * o.pixel_size_um;  // 3 px right
  p.dy_um = 2 * o.pixel_size_um;  // 2 px down
  p.dz_um = 1.5;
  ASSERT_TRUE(SetSimulatedPlacement(rig, p).ok());
  const cv::Mat after = rig.simulation()->GroundTruthDepthUm();
  for (int y = 0; y < 40; y += 7) {
    for (int x = 0; x < 55; x += 9) {
      EXPECT_NEAR(after.at<float>(y + 2, x + 3), before.at<float>(y, x) + 1.5, 1e-3) << x << "," << y;
    }
  }
  // Kept across a specimen switch; {} puts the part back.
  ASSERT_TRUE(rig.simulation()->SetSpecimen("skew5").ok());
  EXPECT_NEAR(rig.simulation()->GroundTruthDepthUm().at<float>(12, 13), before.at<float>(10, 10) + 1.5, 1e-3);
  ASSERT_TRUE(SetSimulatedPlacement(rig, {}).ok());
  EXPECT_EQ(cv::norm(rig.simulation()->GroundTruthDepthUm(), before, cv::NORM_INF), 0.0);
}

TEST(SimulatedPlacementTest, BadPlacementsAreRefusedAndChangeNothing) {
  SimulatedRigOptions o;
  o.camera_size = {32, 32};
  auto created = CreateSimulatedRig(o);
  ASSERT_TRUE(created.ok());
  Rig& rig = **created;
  const cv::Mat before = rig.simulation()->GroundTruthDepthUm();
  SimulatedPlacement p;
  p.dz_um = NAN;
  EXPECT_EQ(SetSimulatedPlacement(rig, p).code(), StatusCode::kInvalidArgument);
  p.dz_um = -1e6;  // below the stage travel
  const Status far = SetSimulatedPlacement(rig, p);
  EXPECT_EQ(far.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(cv::norm(rig.simulation()->GroundTruthDepthUm(), before, cv::NORM_INF), 0.0);
}

TEST(SimulatedPlacementTest, RandomPlacementsAreRepeatableWithTheAskedSpread) {
  const SimulatedPlacement a = RandomSimulatedPlacement(7, 3, 5.0, 2.0);
  const SimulatedPlacement b = RandomSimulatedPlacement(7, 3, 5.0, 2.0);
  EXPECT_EQ(a.dx_um, b.dx_um);
  EXPECT_EQ(a.dz_um, b.dz_um);
  EXPECT_NE(RandomSimulatedPlacement(7, 4, 5.0, 2.0).dx_um, a.dx_um);
  double sxx = 0, szz = 0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    const SimulatedPlacement p = RandomSimulatedPlacement(11, i, 5.0, 2.0);
    sxx += p.dx_um * p.dx_um;
    szz += p.dz_um * p.dz_um;
  }
  EXPECT_NEAR(std::sqrt(sxx / n), 5.0, 0.2);  // standard error of s ~ 5 / sqrt(2 n) = 0.056
  EXPECT_NEAR(std::sqrt(szz / n), 2.0, 0.08);
  const SimulatedPlacement none = RandomSimulatedPlacement(11, 0, 0.0, 0.0);
  EXPECT_EQ(none.dx_um, 0.0);
  EXPECT_EQ(none.dz_um, 0.0);
}

}  // namespace
}  // namespace inspection
