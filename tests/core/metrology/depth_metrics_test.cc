#include "core/metrology/depth_metrics.h"

#include <gtest/gtest.h>

#include <cmath>

namespace inspection {
namespace {

TEST(DepthMetricsTest, AnalyticErrors) {
  cv::Mat ref(2, 2, CV_32F, cv::Scalar(10.f));
  cv::Mat d = (cv::Mat_<float>(2, 2) << 11.f, 9.f, 14.f, std::nanf(""));
  DepthErrorStats s = CompareDepth(d, ref, 2.0);
  EXPECT_EQ(s.compared_pixels, 3u);
  EXPECT_NEAR(s.valid_percent, 75.0, 1e-9);
  EXPECT_NEAR(s.mean_error_um, 4.0 / 3.0, 1e-9);        // (1 - 1 + 4) / 3
  EXPECT_NEAR(s.rmse_um, std::sqrt(18.0 / 3.0), 1e-9);  // (1 + 1 + 16) / 3
  EXPECT_NEAR(s.mean_abs_error_um, 2.0, 1e-9);
  EXPECT_NEAR(s.stddev_error_um, std::sqrt(6.0 - 16.0 / 9.0), 1e-9);
  EXPECT_NEAR(s.outlier_percent, 100.0 / 3.0, 1e-9);
}

TEST(DepthMetricsTest, BorderIsLeftOut) {
  cv::Mat ref(5, 5, CV_32F, cv::Scalar(0.f));
  cv::Mat d(5, 5, CV_32F, cv::Scalar(100.f));
  d(cv::Rect(1, 1, 3, 3)).setTo(1.f);
  DepthErrorStats s = CompareDepth(d, ref, 10.0, 1);
  EXPECT_EQ(s.compared_pixels, 9u);
  EXPECT_NEAR(s.rmse_um, 1.0, 1e-9);
}

TEST(DepthMetricsTest, MaskLimitsTheComparedPixels) {
  cv::Mat ref(1, 4, CV_32F, cv::Scalar(0.f));
  cv::Mat d = (cv::Mat_<float>(1, 4) << 1.f, 3.f, 100.f, std::nanf(""));
  cv::Mat mask = (cv::Mat_<uint8_t>(1, 4) << 1, 1, 0, 1);
  DepthErrorStats s = CompareDepth(d, ref, mask, 10.0);
  EXPECT_EQ(s.compared_pixels, 2u);                 // the 100 um pixel is outside the mask
  EXPECT_NEAR(s.valid_percent, 200.0 / 3.0, 1e-9);  // 2 of the 3 masked pixels have depth
  EXPECT_NEAR(s.mean_error_um, 2.0, 1e-9);
  EXPECT_NEAR(s.outlier_percent, 0.0, 1e-9);
  EXPECT_EQ(CompareDepth(d, ref, 10.0).compared_pixels, 3u);
}

TEST(DepthMetricsTest, LocalOutliersCountSpikesNotSteps) {
  // 10 x 10 plane at 0 with a 30 um step at x >= 5, one spike of +20 um at (2, 2) and a NaN.
  cv::Mat d(10, 10, CV_32F, cv::Scalar(0.f));
  d(cv::Rect(5, 0, 5, 10)).setTo(30.f);
  d.at<float>(2, 2) = 20.f;
  d.at<float>(7, 7) = std::nanf("");
  // 99 measured pixels: the spike is the only outlier, the 20 pixels along the step are not.
  EXPECT_NEAR(LocalOutlierPercent(d, 10.0), 100.0 / 99.0, 1e-9);
  EXPECT_NEAR(LocalOutlierPercent(d, 25.0), 0.0, 1e-9);  // the spike is within 25 um
  // A border of 3 leaves the spike out (4 x 4 inner pixels, all regular).
  EXPECT_NEAR(LocalOutlierPercent(d, 10.0, 3), 0.0, 1e-9);
  // A pixel with fewer than 3 measured neighbours is not judged.
  cv::Mat lone(3, 3, CV_32F, cv::Scalar(NAN));
  lone.at<float>(1, 1) = 5.f;
  lone.at<float>(0, 0) = 50.f;
  EXPECT_NEAR(LocalOutlierPercent(lone, 1.0), 0.0, 1e-9);
  EXPECT_EQ(LocalOutlierPercent(cv::Mat(2, 2, CV_32F, cv::Scalar(NAN)), 1.0), 0.0);
}

TEST(DepthMetricsTest, FiniteRange) {
  cv::Mat d = (cv::Mat_<float>(1, 4) << std::nanf(""), -2.f, 7.5f, 3.f);
  auto [lo, hi] = FiniteRange(d);
  EXPECT_DOUBLE_EQ(lo, -2.0);
  EXPECT_DOUBLE_EQ(hi, 7.5);
  EXPECT_TRUE(std::isnan(FiniteRange(cv::Mat(2, 2, CV_32F, cv::Scalar(NAN))).first));
}

}  // namespace
}  // namespace inspection
