// z grid positions, the uncharacterised peak-locking bound, and the characterisation of a known
// periodic depth bias from a tilted flat.
#include "core/metrology/z_linearity.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

using testing::kPi;

TEST(ZLinearityTest, GridLocatesFractionStepAndNearestFrame) {
  auto g = ZGrid::Create({20.0, 0.0, 5.0, 10.0});  // any order, non-uniform
  ASSERT_TRUE(g.ok()) << g.status().ToString();
  ZGrid::Position p = g->Locate(7.5);
  EXPECT_EQ(p.lower, 1);
  EXPECT_DOUBLE_EQ(p.fraction, 0.5);
  EXPECT_DOUBLE_EQ(p.step_um, 5.0);
  EXPECT_EQ(p.nearest, 2);
  p = g->Locate(12.5);  // the 10 um step
  EXPECT_EQ(p.lower, 2);
  EXPECT_DOUBLE_EQ(p.fraction, 0.25);
  EXPECT_EQ(p.nearest, 2);
  p = g->Locate(-2.0);  // below: the first step continues
  EXPECT_DOUBLE_EQ(p.fraction, 0.6);
  EXPECT_DOUBLE_EQ(p.step_um, 5.0);
  EXPECT_EQ(p.nearest, 0);
  p = g->Locate(24.0);  // above: the last step (10 um) continues
  EXPECT_DOUBLE_EQ(p.fraction, 0.4);
  EXPECT_EQ(p.nearest, 3);
  EXPECT_DOUBLE_EQ(g->median_step_um(), 5.0);
  EXPECT_EQ(ZGrid::Create({1.0}).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ZGrid::Create({1.0, 1.0}).status().code(), StatusCode::kInvalidArgument);
}

TEST(ZLinearityTest, UncharacterisedIsTheSawtoothOfTheDiscreteMaximum) {
  const ZLinearity l = ZLinearity::Uncharacterised();
  // Error of reporting the nearest frame: -f below half a step, 1 - f above (zero-mean table).
  EXPECT_NEAR(l.At(0.25), -0.25, 0.01);
  EXPECT_NEAR(l.At(0.75), 0.25, 0.01);
  EXPECT_NEAR(l.At(1.25), l.At(0.25), 1e-12);  // periodic
  EXPECT_NEAR(l.Rms(), 1.0 / std::sqrt(12.0), 0.01);
  EXPECT_NEAR(l.MaxAbs(), 0.5, 0.02);
  EXPECT_EQ(l.characterised_step_um, 0.0);
}

TEST(ZLinearityTest, CharacterisationRecoversAKnownPeriodicBias) {
  // A flat tilted so its heights sweep 8 z steps of 5 um, measured with the bias
  // 0.04 step sin(2 pi f) (the simulated rig's shape, ~4 % of a step) plus correlated noise.
  const cv::Size size(400, 100);
  const double px = 0.74, step = 5.0;
  std::vector<double> z;
  for (int k = 0; k < 20; ++k) z.push_back(180.0 + step * k);
  auto grid = ZGrid::Create(z);
  ASSERT_TRUE(grid.ok());
  cv::Mat depth = testing::SampleSurface(size, px, [&](double x, double y) {
    const double h = 200.0 + 0.135 * x + 0.01 * y;
    return h + 0.04 * step * std::sin(2.0 * kPi * grid->Locate(h).fraction);
  });
  depth += testing::CorrelatedNoise(size, 0.05, 7, 5);
  const cv::Mat all(size, CV_8UC1, cv::Scalar(255));
  auto lin = CharacteriseZLinearity(depth, all, px, *grid);
  ASSERT_TRUE(lin.ok()) << lin.status().ToString();
  ASSERT_EQ(lin->bias_of_step.size(), 20u);
  double worst = 0.0;
  for (int i = 0; i < 20; ++i)
    worst = std::max(worst, std::abs(lin->bias_of_step[i] - 0.04 * std::sin(2 * kPi * i / 20.0)));
  // Each bin averages ~2000 pixels (~40 correlation areas) of 0.05 um noise: 0.008 um = 0.0016
  // of a step; the bound allows 3 of those plus the bin width's smoothing of the sine (0.4 %).
  EXPECT_LT(worst, 0.006) << "largest table error (fraction of a step)";
  EXPECT_NEAR(lin->MaxAbs(), 0.04, 0.006);
  EXPECT_DOUBLE_EQ(lin->characterised_step_um, 5.0);
  // An untilted flat samples one fractional position only: refused, naming the gap.
  const cv::Mat flat(size, CV_32FC1, cv::Scalar(201.0f));
  auto bad = CharacteriseZLinearity(flat, all, px, *grid);
  EXPECT_EQ(bad.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(bad.status().message().find("tilt the flat"), std::string::npos) << bad.status().message();
  // Stored and read back unchanged.
  auto back = ZLinearityFromJson(ZLinearityToJson(*lin));
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->bias_of_step, lin->bias_of_step);
  EXPECT_EQ(back->characterised_step_um, lin->characterised_step_um);
  EXPECT_EQ(back->source, lin->source);
  EXPECT_EQ(ZLinearityFromJson("{\"bias_of_step\": [0.1]}").status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(ZLinearityFromJson("{\"bias_of_step\": [0.1, 3]}").status().message().find("bias_of_step"),
            std::string::npos);
  EXPECT_EQ(ZLinearityFromJson("[").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
