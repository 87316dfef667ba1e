// Projector response (thesis eq. 5.1) and camera exposure/response/noise (eq. 5.3, 5.4) of the
// simulated rig, checked against their analytic definitions.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/core/utility.hpp>

#include "devices/sim/radiometry.h"

namespace inspection {
namespace {

TEST(ProjectorResponseTest, GammaCurveWithBlackFloor) {
  ProjectorResponse prf;
  prf.gamma = 2.0;
  prf.black_irradiance = 0.002;
  EXPECT_DOUBLE_EQ(prf.Irradiance(0), 0.002);
  EXPECT_DOUBLE_EQ(prf.Irradiance(255), 1.0);
  EXPECT_NEAR(prf.Irradiance(128), 0.002 + 0.998 * std::pow(128.0 / 255.0, 2.0), 1e-12);
  const auto table = prf.Table();
  for (int i = 1; i < 256; ++i) EXPECT_GT(table[i], table[i - 1]) << i;
  prf.gamma = 9.0;
  EXPECT_EQ(prf.Validate().code(), StatusCode::kInvalidArgument);
}

TEST(CameraResponseTest, ResponseAndInverseRoundTrip) {
  CameraResponse crf;
  EXPECT_DOUBLE_EQ(crf.GreyForRelativeExposure(0.0), 2.0);    // black level
  EXPECT_DOUBLE_EQ(crf.GreyForRelativeExposure(1.0), 255.0);  // full well
  EXPECT_DOUBLE_EQ(crf.GreyForRelativeExposure(3.0), 255.0);  // saturation
  EXPECT_NEAR(crf.GreyForRelativeExposure(0.25), 2.0 + 253.0 * std::pow(0.25, 0.8), 1e-9);
  for (double g : {10.0, 64.0, 128.0, 200.0, 250.0}) {
    EXPECT_NEAR(crf.GreyForRelativeExposure(crf.RelativeExposureForGrey(g)), g, 1e-9);
  }
  crf.bit_depth = 12;
  EXPECT_EQ(crf.max_dn(), 4095);
  EXPECT_DOUBLE_EQ(crf.GreyForRelativeExposure(0.0), 2.0 * 4095.0 / 255.0);
  crf.bit_depth = 10;
  EXPECT_EQ(crf.Validate().code(), StatusCode::kInvalidArgument);
}

CameraResponse NoiseFree(int bits) {
  CameraResponse crf;
  crf.bit_depth = bits;
  crf.shot_noise = false;
  crf.read_noise_dn8 = 0.0;
  return crf;
}

TEST(ExposeAndDigitiseTest, NoiseFreeExposureFollowsEq53And54) {
  const CameraResponse crf = NoiseFree(8);
  // E = 0.1, dt = 2000 us: 0.1 * 2000 * 10 e/us = 2000 e = 0.2 full well.
  cv::Mat e(8, 8, CV_32FC1, cv::Scalar(0.1));
  cv::Mat z = ExposeAndDigitise(e, 2000.0, 0.0, crf, 1);
  ASSERT_EQ(z.type(), CV_8UC1);
  const int expected = static_cast<int>(std::lround(crf.GreyForRelativeExposure(0.2)));
  EXPECT_EQ(cv::countNonZero(z != expected), 0) << "expected " << expected;
  // 6 dB gain doubles the exposure.
  z = ExposeAndDigitise(e, 2000.0, 20.0 * std::log10(2.0), crf, 1);
  EXPECT_EQ(z.at<uint8_t>(0, 0), std::lround(crf.GreyForRelativeExposure(0.4)));
  // Beyond the full well: saturated.
  z = ExposeAndDigitise(e, 20000.0, 0.0, crf, 1);
  EXPECT_EQ(cv::countNonZero(z != 255), 0);
}

TEST(ExposeAndDigitiseTest, TwelveBitOutputRange) {
  const CameraResponse crf = NoiseFree(12);
  cv::Mat e(4, 64, CV_32FC1);
  for (int c = 0; c < 64; ++c) e.col(c).setTo(c * 0.002);
  // Column c: c * 0.002 * 10000 us * 10 e/us = 200 c electrons.
  cv::Mat z = ExposeAndDigitise(e, 10000.0, 0.0, crf, 1);
  ASSERT_EQ(z.type(), CV_16UC1);
  double lo, hi;
  cv::minMaxLoc(z, &lo, &hi);
  EXPECT_EQ(lo, std::lround(2.0 * 4095.0 / 255.0));
  EXPECT_EQ(hi, 4095.0);  // column 63: 12600 e, beyond the 10000 e full well
  EXPECT_EQ(z.at<uint16_t>(0, 25), std::lround(crf.GreyForRelativeExposure(0.5)));  // 5000 e
}

TEST(ExposeAndDigitiseTest, ShotAndReadNoiseHaveTheModelledSpread) {
  CameraResponse crf;
  crf.response_exponent = 1.0;  // linear, so the grey spread is the electron spread scaled
  crf.bit_depth = 12;           // fine quantisation
  cv::Mat e(256, 256, CV_32FC1, cv::Scalar(0.25));
  const cv::Mat z = ExposeAndDigitise(e, 1000.0, 0.0, crf, 7);  // 2500 e
  cv::Mat zf;
  z.convertTo(zf, CV_64F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(zf, mean, stddev);
  const double black = 2.0 * 4095.0 / 255.0, dn_per_e = (4095.0 - black) / crf.full_well_e;
  const double read_e = crf.read_noise_dn8 / (255.0 - crf.black_level_dn8) * crf.full_well_e;
  const double expected_sd = std::sqrt(2500.0 + read_e * read_e) * dn_per_e;
  EXPECT_NEAR(mean[0], black + 2500.0 * dn_per_e, 0.5);
  EXPECT_NEAR(stddev[0], expected_sd, 0.03 * expected_sd);
}

TEST(ExposeAndDigitiseTest, SeededAndIndependentOfThreadCount) {
  const CameraResponse crf;
  cv::Mat e(100, 90, CV_32FC1, cv::Scalar(0.2));
  const cv::Mat a = ExposeAndDigitise(e, 1000.0, 0.0, crf, 42);
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  const cv::Mat b = ExposeAndDigitise(e, 1000.0, 0.0, crf, 42);
  cv::setNumThreads(threads);
  const cv::Mat c = ExposeAndDigitise(e, 1000.0, 0.0, crf, 43);
  EXPECT_EQ(cv::countNonZero(a != b), 0);
  EXPECT_GT(cv::countNonZero(a != c), 1000);
}

}  // namespace
}  // namespace inspection
