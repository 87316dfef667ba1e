// Local depth consistency (core/depth_consistency.h): the residual about a local plane ignores
// slopes, flags windows across depth steps and over noise, and NaN.
#include "core/depth_consistency.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace inspection {
namespace {

TEST(DepthConsistencyTest, SteepPlanePlusNoiseHasTheNoiseAsResidualEvenAtTheBorder) {
  const cv::Size size(60, 40);
  std::mt19937 rng(2);
  std::normal_distribution<float> noise(0.f, 0.1f);
  cv::Mat d(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) d.at<float>(y, x) = 200.f + 3.f * x - 2.f * y + noise(rng);
  auto r = LocalDepthResidual(d, 4);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  // A plane fit with 3 parameters to 81 samples leaves sigma * sqrt(78 / 81) ~ 0.098.
  const double interior = cv::mean((*r)(cv::Rect(4, 4, size.width - 8, size.height - 8)))[0];
  EXPECT_NEAR(interior, 0.098, 0.01);
  double lo, hi;
  cv::minMaxLoc(*r, &lo, &hi);
  EXPECT_LT(hi, 0.2);  // the slope (3 per pixel, 12 over the window's half-width) is absorbed
  // The raw standard deviation would be ~3.16 * 3.6 = 11: a raw-spread test rejects flanks.
}

TEST(DepthConsistencyTest, WindowsAcrossAStepAndOverNoiseAreRejected) {
  const cv::Size size(40, 30);
  cv::Mat d(size, CV_32F, cv::Scalar(100.f));
  d.colRange(20, 40).setTo(112.f);  // a 12 um step between columns 19 and 20
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> u(100.f, 120.f);
  for (int y = 24; y < 30; ++y)
    for (int x = 0; x < 12; ++x) d.at<float>(y, x) = u(rng);  // textureless: noise peaks
  d.at<float>(2, 3) = std::nanf("");
  DepthConsistencyOptions o;
  o.radius_px = 3;
  o.max_residual_z_steps = 1.0;
  auto out = RejectInconsistentDepth(d, d, 2.5, 7, o);
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  for (int x = 0; x < size.width; ++x) {
    // Row 12: far from the noise and the NaN. A window across a step of h leaves 0.247 h (step in
    // the middle) to 0.277 h (one column of seven across) about the best plane: >= 2.96 um here,
    // so windows covering both sides (columns 17..22) are rejected at 1 z step of 2.5 um.
    const bool across = x >= 17 && x <= 22;
    EXPECT_EQ(std::isnan(out->at<float>(12, x)), across) << x;
  }
  for (int x = 0; x < 9; ++x) EXPECT_TRUE(std::isnan(out->at<float>(27, x))) << x;  // noise
  EXPECT_TRUE(std::isnan(out->at<float>(4, 5)));                                    // NaN within 3 px
  EXPECT_FALSE(std::isnan(out->at<float>(8, 8)));                                   // NaN farther away
  // radius 0 = focus window / 2 + 1: 7 -> 4, so the band widens by one on each side.
  o.radius_px = 0;
  auto wide = RejectInconsistentDepth(d, d, 2.5, 7, o);
  ASSERT_TRUE(wide.ok());
  EXPECT_TRUE(std::isnan(wide->at<float>(12, 16)));
  EXPECT_TRUE(std::isnan(wide->at<float>(12, 23)));
  EXPECT_FALSE(std::isnan(wide->at<float>(12, 15)));
}

TEST(DepthConsistencyTest, MedianZStepAndBadInput) {
  EXPECT_DOUBLE_EQ(MedianZStep({0, 5, 10, 12, 17}), 5.0);
  EXPECT_DOUBLE_EQ(MedianZStep({30, 27.5, 25, 22.5}), 2.5);
  EXPECT_DOUBLE_EQ(MedianZStep({1}), 0.0);
  const cv::Mat d(8, 8, CV_32F, cv::Scalar(1.f));
  DepthConsistencyOptions o;
  o.max_residual_z_steps = 0;
  EXPECT_NE(RejectInconsistentDepth(d, d, 1.0, 7, o).status().message().find("max_residual_z_steps"),
            std::string::npos);
  o = DepthConsistencyOptions{};
  EXPECT_NE(RejectInconsistentDepth(d, d, 0.0, 7, o).status().message().find("z_step_um"), std::string::npos);
  EXPECT_EQ(RejectInconsistentDepth(d, cv::Mat(4, 4, CV_32F), 1.0, 7, o).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(LocalDepthResidual(cv::Mat(8, 8, CV_64F), 3).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
