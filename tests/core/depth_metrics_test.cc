#include "core/depth_metrics.h"

#include <cmath>

#include <gtest/gtest.h>

namespace inspection {
namespace {

TEST(DepthMetricsTest, AnalyticErrors) {
  cv::Mat ref(2, 2, CV_32F, cv::Scalar(10.f));
  cv::Mat d = (cv::Mat_<float>(2, 2) << 11.f, 9.f, 14.f, std::nanf(""));
  DepthErrorStats s = CompareDepth(d, ref, 2.0);
  EXPECT_EQ(s.compared_pixels, 3u);
  EXPECT_NEAR(s.valid_percent, 75.0, 1e-9);
  EXPECT_NEAR(s.mean_error_um, 4.0 / 3.0, 1e-9);           // (1 - 1 + 4) / 3
  EXPECT_NEAR(s.rmse_um, std::sqrt(18.0 / 3.0), 1e-9);     // (1 + 1 + 16) / 3
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

TEST(DepthMetricsTest, FiniteRange) {
  cv::Mat d = (cv::Mat_<float>(1, 4) << std::nanf(""), -2.f, 7.5f, 3.f);
  auto [lo, hi] = FiniteRange(d);
  EXPECT_DOUBLE_EQ(lo, -2.0);
  EXPECT_DOUBLE_EQ(hi, 7.5);
  EXPECT_TRUE(std::isnan(FiniteRange(cv::Mat(2, 2, CV_32F, cv::Scalar(NAN))).first));
}

}  // namespace
}  // namespace inspection
