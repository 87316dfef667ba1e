// Local depth consistency (core/sff/depth_consistency.h): the residual about a local plane ignores
// slopes, flags windows across depth steps and over noise, and NaN.
#include "core/sff/depth_consistency.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

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

TEST(DepthConsistencyTest, FocusEnergyCentroidIsWhereTheWindowsGradientIs) {
  // One bright pixel at (20, 20): its Sobel energy is symmetric about it, so every window that
  // holds all of it has its centroid exactly there.
  cv::Mat aif(41, 41, CV_8UC1, cv::Scalar(0));
  aif.at<uchar>(20, 20) = 200;
  auto c = FocusEnergyCentroidOffset(aif, 9);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_NEAR(c->at<cv::Vec2f>(20, 17)[0], 3.0f, 1e-4);  // (x 17, y 20): the energy 3 px to the right
  EXPECT_NEAR(c->at<cv::Vec2f>(20, 17)[1], 0.0f, 1e-4);
  EXPECT_NEAR(c->at<cv::Vec2f>(17, 20)[1], 3.0f, 1e-4);
  EXPECT_NEAR(c->at<cv::Vec2f>(23, 22)[0], -2.0f, 1e-4);
  EXPECT_NEAR(c->at<cv::Vec2f>(23, 22)[1], -3.0f, 1e-4);
  EXPECT_EQ(c->at<cv::Vec2f>(5, 5), cv::Vec2f(0.f, 0.f));  // no gradient in the window
  EXPECT_EQ(FocusEnergyCentroidOffset(aif, 8).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(FocusEnergyCentroidOffset(cv::Mat(), 9).status().code(), StatusCode::kInvalidArgument);
}

// The centroid offset as whole-image filters give it (the definition; the implementation filters
// bands of rows in parallel): Sobel energy, three box sums, their ratios, 0 without energy.
cv::Mat WholeImageCentroidOffset(const cv::Mat& all_in_focus, int window_px) {
  constexpr int kBorder = cv::BORDER_REFLECT_101;
  cv::Mat grey, gx, gy;
  if (all_in_focus.channels() == 3) {
    cv::cvtColor(all_in_focus, grey, cv::COLOR_BGR2GRAY);
    grey.convertTo(grey, CV_32F);
  } else {
    all_in_focus.convertTo(grey, CV_32F);
  }
  cv::Sobel(grey, gx, CV_32F, 1, 0, 3, 1.0, 0.0, kBorder);
  cv::Sobel(grey, gy, CV_32F, 0, 1, 3, 1.0, 0.0, kBorder);
  const cv::Mat energy = gx.mul(gx) + gy.mul(gy);
  const int r = window_px / 2;
  cv::Mat ones(1, 2 * r + 1, CV_32F, cv::Scalar(1.f)), ramp(1, 2 * r + 1, CV_32F);
  for (int k = -r; k <= r; ++k) ramp.at<float>(0, k + r) = float(k);
  cv::Mat sum, mx, my;
  cv::sepFilter2D(energy, sum, CV_32F, ones, ones, cv::Point(-1, -1), 0.0, kBorder);
  cv::sepFilter2D(energy, mx, CV_32F, ramp, ones, cv::Point(-1, -1), 0.0, kBorder);
  cv::sepFilter2D(energy, my, CV_32F, ones, ramp, cv::Point(-1, -1), 0.0, kBorder);
  std::vector<cv::Mat> channels(2);
  cv::divide(mx, sum, channels[0]);
  cv::divide(my, sum, channels[1]);
  channels[0].setTo(0.f, sum <= 0.f);
  channels[1].setTo(0.f, sum <= 0.f);
  cv::Mat out;
  cv::merge(channels, out);
  return out;
}

TEST(DepthConsistencyTest, FocusEnergyCentroidInBandsEqualsTheWholeImageFilters) {
  // Sizes that do not divide into the 32-row bands, a band of fewer rows than the window, flat
  // patches (no energy) beside texture; grey 8/16 bit, float and colour.
  cv::RNG rng(7);
  for (const cv::Size size : {cv::Size(97, 70), cv::Size(41, 33), cv::Size(64, 129)}) {
    for (const int type : {CV_8UC1, CV_16UC1, CV_32FC1, CV_8UC3}) {
      cv::Mat image(size, type);
      rng.fill(image, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(type == CV_16UC1 ? 65535 : 255));
      image(cv::Rect(0, 0, size.width / 3, size.height / 2)).setTo(cv::Scalar::all(17));
      for (const int window : {3, 9}) {
        auto c = FocusEnergyCentroidOffset(image, window);
        ASSERT_TRUE(c.ok()) << c.status().ToString();
        const cv::Mat want = WholeImageCentroidOffset(image, window);
        ASSERT_EQ(c->type(), CV_32FC2);
        ASSERT_EQ(c->size(), size);
        // Same filters on the same pixels: equal to the last bit.
        EXPECT_EQ(cv::norm(*c, want, cv::NORM_INF), 0.0)
            << size << " type " << type << " window " << window;
        EXPECT_EQ(c->at<cv::Vec2f>(2, 2), cv::Vec2f(0.f, 0.f));  // inside the flat patch
      }
    }
  }
}

TEST(DepthConsistencyTest, WindowsWhoseFocusEnergyIsFarFromTheirPixelOnASlopeAreRejected) {
  // A plane rising 0.5 um per pixel in x (residual 0: the plane check keeps it all) whose only
  // texture is one bright pixel: a pixel 3 px from it got the depth of the texture, 1.5 um (1.5
  // z steps) away from its own. The mixing estimate |slope . offset| rejects offsets > 1 px at
  // max_window_mixing_z_steps 0.5; on a flat surface the same offsets cost nothing.
  cv::Mat depth(41, 41, CV_32F);
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) depth.at<float>(y, x) = 100.f + 0.5f * x;
  cv::Mat aif(41, 41, CV_8UC1, cv::Scalar(0));
  aif.at<uchar>(20, 20) = 200;
  const DepthConsistencyOptions o;  // max_window_mixing_z_steps 0.5
  auto kept = RejectInconsistentDepth(depth, depth, 1.0, 9, o, aif);
  ASSERT_TRUE(kept.ok()) << kept.status().ToString();
  EXPECT_TRUE(std::isnan(kept->at<float>(20, 17)));   // offset 3 px in x: 1.5 um
  EXPECT_TRUE(std::isnan(kept->at<float>(20, 22)));   // offset -2 px: 1.0 um
  EXPECT_FALSE(std::isnan(kept->at<float>(20, 19)));  // offset 1 px: 0.5 um, at the limit
  EXPECT_FALSE(std::isnan(kept->at<float>(20, 20)));
  EXPECT_FALSE(std::isnan(kept->at<float>(17, 20)));  // offset along y, where the plane is level
  EXPECT_FALSE(std::isnan(kept->at<float>(5, 5)));    // no texture in the window: left to the confidence
  // Only windows that reach the texture's energy (within 4 + 1 px of it) can be rejected.
  // (cv::compare's CMP_NE is false for NaN: NaN is "not equal to itself" as ~EQ.)
  auto nan_count = [](const cv::Mat& m) { return cv::countNonZero(~(m == m)); };
  cv::Mat rejected = ~(*kept == *kept);
  EXPECT_GE(cv::countNonZero(rejected), 2 * 3 * 7);  // at least |dx| 2..4 on rows 17..23
  rejected(cv::Rect(15, 15, 11, 11)).setTo(0);
  EXPECT_EQ(cv::countNonZero(rejected), 0);
  // Without the image, or with the check off, nothing is rejected.
  EXPECT_EQ(nan_count(*RejectInconsistentDepth(depth, depth, 1.0, 9, o)), 0);
  DepthConsistencyOptions off;
  off.max_window_mixing_z_steps = 0;
  EXPECT_EQ(nan_count(*RejectInconsistentDepth(depth, depth, 1.0, 9, off, aif)), 0);
  // Flat: the same texture, no slope, nothing rejected.
  const cv::Mat flat(41, 41, CV_32F, cv::Scalar(100.f));
  EXPECT_EQ(nan_count(*RejectInconsistentDepth(flat, flat, 1.0, 9, o, aif)), 0);
  DepthConsistencyOptions bad;
  bad.max_window_mixing_z_steps = -1;
  EXPECT_NE(RejectInconsistentDepth(depth, depth, 1.0, 9, bad, aif).status().message().find("max_window_mixing"),
            std::string::npos);
  EXPECT_EQ(RejectInconsistentDepth(depth, depth, 1.0, 9, o, cv::Mat(4, 4, CV_8UC1)).status().code(),
            StatusCode::kInvalidArgument);
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
