// Per-frame statistics of the progress events (core/io/frame_statistics.h): exact figures against
// sums written out here, at 8 and 16 bits, on rows longer than one 32-bit summation run.
#include "core/io/frame_statistics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>

namespace inspection {
namespace {

struct Expected {
  double mean = 0, stddev = 0, saturated = 0, under = 0;
};

template <typename T>
Expected Reference(const cv::Mat& frame, int bit_depth) {
  const double full = double((1u << bit_depth) - 1u);
  long double sum = 0, sum2 = 0;
  double sat = 0, under = 0;
  for (int y = 0; y < frame.rows; ++y) {
    for (int x = 0; x < frame.cols; ++x) {
      const double v = frame.at<T>(y, x);
      sum += v;
      sum2 += v * v;
      sat += v >= full;
      under += v < std::floor(0.02 * full);
    }
  }
  const double n = double(frame.total()), mean = double(sum / n);
  return {mean * 255.0 / full, std::sqrt(double(sum2 / n) - mean * mean) * 255.0 / full, 100.0 * sat / n,
          100.0 * under / n};
}

void ExpectMatches(const FrameStatistics& s, const Expected& e) {
  EXPECT_NEAR(s.mean_grey, e.mean, 1e-9);
  EXPECT_NEAR(s.stddev_grey, e.stddev, 1e-6);
  EXPECT_DOUBLE_EQ(s.saturated_percent, e.saturated);
  EXPECT_DOUBLE_EQ(s.underexposed_percent, e.under);
}

TEST(FrameStatisticsTest, EightBitFigures) {
  // A constant frame: mean exact, no spread; all saturated; all under-exposed.
  FrameStatistics s = ComputeFrameStatistics(cv::Mat(30, 40, CV_8UC1, cv::Scalar(100)), 8);
  EXPECT_DOUBLE_EQ(s.mean_grey, 100.0);
  EXPECT_NEAR(s.stddev_grey, 0.0, 1e-9);
  EXPECT_EQ(s.saturated_percent, 0.0);
  EXPECT_DOUBLE_EQ(ComputeFrameStatistics(cv::Mat(3, 4, CV_8UC1, cv::Scalar(255)), 8).saturated_percent, 100.0);
  EXPECT_DOUBLE_EQ(ComputeFrameStatistics(cv::Mat(3, 4, CV_8UC1, cv::Scalar(4)), 8).underexposed_percent, 100.0);
  EXPECT_DOUBLE_EQ(ComputeFrameStatistics(cv::Mat(3, 4, CV_8UC1, cv::Scalar(5)), 8).underexposed_percent, 0.0);
  // Half 0, half 255: mean 127.5, sd 127.5.
  cv::Mat halves(10, 10, CV_8UC1, cv::Scalar(0));
  halves(cv::Rect(0, 0, 5, 10)).setTo(255);
  s = ComputeFrameStatistics(halves, 8);
  EXPECT_DOUBLE_EQ(s.mean_grey, 127.5);
  EXPECT_NEAR(s.stddev_grey, 127.5, 1e-9);
  EXPECT_DOUBLE_EQ(s.saturated_percent, 50.0);
  EXPECT_DOUBLE_EQ(s.underexposed_percent, 50.0);
  // Noise on rows longer than a 32-bit run (65536 px) and on a sub-matrix (rows not contiguous),
  // where all-255 rows would overflow 32-bit square sums if a run were longer.
  for (const cv::Size size : {cv::Size(70001, 3), cv::Size(1600, 1200)}) {
    cv::Mat noise(size, CV_8UC1);
    cv::RNG(7).fill(noise, cv::RNG::UNIFORM, 0, 256);
    noise.row(0).setTo(255);
    ExpectMatches(ComputeFrameStatistics(noise, 8), Reference<uint8_t>(noise, 8));
    const cv::Mat roi = noise(cv::Rect(3, 1, size.width - 5, 2));
    ExpectMatches(ComputeFrameStatistics(roi, 8), Reference<uint8_t>(roi, 8));
  }
}

TEST(FrameStatisticsTest, SixteenBitFiguresAtTheirSignificantBits) {
  cv::Mat noise(4, 70001, CV_16UC1);
  cv::RNG(11).fill(noise, cv::RNG::UNIFORM, 0, 4096);
  noise.row(1).setTo(4095);
  ExpectMatches(ComputeFrameStatistics(noise, 12), Reference<uint16_t>(noise, 12));
  // Full-scale 16-bit values: the squares exceed 32 bits.
  cv::Mat full(3, 70001, CV_16UC1);
  cv::RNG(12).fill(full, cv::RNG::UNIFORM, 0, 65536);
  full.row(2).setTo(65535);
  const FrameStatistics s = ComputeFrameStatistics(full, 16);
  ExpectMatches(s, Reference<uint16_t>(full, 16));
  EXPECT_GT(s.saturated_percent, 33.3);
}

}  // namespace
}  // namespace inspection
