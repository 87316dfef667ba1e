// Step height (ISO 5436-1 type A style) on analytic steps and grooves on a tilted base, exact
// without noise, and with correlated noise and holes within the propagated uncertainty (k = 2
// covering >= 90 % of 100 realisations).
#include "core/metrology/step_height.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

constexpr double kPx = 0.74;
constexpr double kSx = 0.02, kSy = -0.01;  // base tilt

cv::Mat Rect(cv::Size s, cv::Rect r) {
  cv::Mat m(s, CV_8UC1, cv::Scalar(0));
  m(r).setTo(255);
  return m;
}

// Tilted base with the part right of x_step_px raised by h_um.
cv::Mat Step(cv::Size size, double h_um, int x_step_px) {
  return testing::SampleSurface(
      size, kPx, [&](double x, double y) { return 200.0 + kSx * x + kSy * y + (x >= x_step_px * kPx ? h_um : 0.0); });
}

DepthNoiseModel Known(const cv::Mat& depth, double sigma, int window) {
  DepthNoiseModel m;
  m.sigma_um = cv::Mat(depth.size(), CV_32FC1, cv::Scalar(float(sigma)));
  m.sigma_um.setTo(NAN, depth != depth);
  m.global_sigma_um = sigma;
  m.correlation_px = window;
  m.grid = *ZGrid::Create({0.0, 10000.0});
  m.linearity.bias_of_step = {0.0, 0.0};
  return m;
}

TEST(StepHeightTest, CommonSlopeAndSeparatePlanesGiveTheStepExactly) {
  const cv::Size size(160, 80);
  const cv::Mat z = Step(size, 2.5, 80);
  // Regions keep 10 px from the edge (ISO 5436-1 leaves out the edge zone).
  const cv::Mat ref = Rect(size, {5, 5, 65, 70}), mea = Rect(size, {90, 5, 65, 70});
  const double cos_tilt = 1.0 / std::sqrt(1.0 + kSx * kSx + kSy * kSy);
  for (StepHeightFit fit : {StepHeightFit::kCommonSlope, StepHeightFit::kSeparatePlanes}) {
    auto r = MeasureStepHeight(z, ref, mea, kPx, StepHeightOptions{fit}, nullptr);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    // Float depths (~200 um, rounding 1e-5 um) bound the agreement.
    EXPECT_NEAR(r->vertical_offset_um, 2.5, 1e-4) << StepHeightFitName(fit);
    EXPECT_NEAR(r->height_um, 2.5 * cos_tilt, 1e-4);
    EXPECT_NEAR(r->slope_x, kSx, 1e-6);
    EXPECT_NEAR(r->slope_y, kSy, 1e-6);
    EXPECT_TRUE(std::isnan(r->uncertainty.standard_uncertainty));  // no noise model given
  }
}

TEST(StepHeightTest, GrooveBetweenTwoLandsIsNegative) {
  // ISO 5436-1 A1: lands A and B (one reference mask) either side of a 1.2 um deep groove C.
  const cv::Size size(180, 60);
  const cv::Mat z = testing::SampleSurface(size, kPx, [](double x, double y) {
    return 300.0 + kSx * x + kSy * y - ((x >= 60 * kPx && x < 120 * kPx) ? 1.2 : 0.0);
  });
  const cv::Mat lands = Rect(size, {0, 0, 45, 60}) | Rect(size, {135, 0, 45, 60});
  const cv::Mat bottom = Rect(size, {75, 0, 30, 60});
  auto r = MeasureStepHeight(z, lands, bottom, kPx, StepHeightOptions{}, nullptr);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_NEAR(r->vertical_offset_um, -1.2, 1e-4);
}

TEST(StepHeightTest, NoisyStepsAreCoveredByTheirUncertainty) {
  // sigma 0.05 um, 7 px correlated, 10 holes: u ~ 3e-3 um. Over 100 realisations the k = 2
  // interval must hold >= 90 (95 % expected; 90 leaves room for the binomial scatter, sd 2.2).
  const cv::Size size(120, 60);
  const cv::Mat base = Step(size, 1.0, 60);
  const cv::Mat ref = Rect(size, {0, 0, 50, 60}), mea = Rect(size, {70, 0, 50, 60});
  int covered = 0;
  double u_mean = 0.0, dev_sum = 0.0, dev_sum2 = 0.0;
  const int n = 100;
  for (int k = 0; k < n; ++k) {
    cv::Mat z = base + testing::CorrelatedNoise(size, 0.05, 7, 500 + k);
    testing::PunchHoles(z, 10, 4, 900 + k);
    const DepthNoiseModel model = Known(z, 0.05, 7);
    auto r = MeasureStepHeight(z, ref, mea, kPx, StepHeightOptions{}, &model);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    const double dev = r->vertical_offset_um - 1.0;
    covered += std::abs(dev) <= 2.0 * r->uncertainty.standard_uncertainty;
    u_mean += r->uncertainty.standard_uncertainty / n;
    dev_sum += dev;
    dev_sum2 += dev * dev;
  }
  const double bias = dev_sum / n, sd = std::sqrt(dev_sum2 / n - bias * bias);
  std::printf("step 1 um, noise 0.05 um: bias %.2e um, sd %.2e um, mean u %.2e um, covered %d/%d\n", bias, sd, u_mean,
              covered, n);
  EXPECT_GE(covered, 90);
  EXPECT_NEAR(sd / u_mean, 1.0, 0.25);  // the uncertainty is the spread, not just an upper bound
}

TEST(StepHeightTest, BadRegionsAreRefused) {
  const cv::Size size(60, 40);
  const cv::Mat z = Step(size, 1.0, 30);
  const cv::Mat a = Rect(size, {0, 0, 35, 40}), b = Rect(size, {30, 0, 30, 40});
  auto overlap = MeasureStepHeight(z, a, b, kPx, StepHeightOptions{}, nullptr);
  EXPECT_EQ(overlap.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(overlap.status().message().find("overlap"), std::string::npos);
  cv::Mat holes = z.clone();
  holes(cv::Rect(40, 0, 20, 40)).setTo(NAN);
  auto empty = MeasureStepHeight(holes, Rect(size, {0, 0, 20, 40}), Rect(size, {40, 0, 20, 40}), kPx,
                                 StepHeightOptions{}, nullptr);
  EXPECT_EQ(empty.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(empty.status().message().find("measured region"), std::string::npos) << empty.status().message();
  EXPECT_EQ(*ParseStepHeightFit("separate_planes"), StepHeightFit::kSeparatePlanes);
  EXPECT_EQ(ParseStepHeightFit("iso").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
