// Camera response (thesis eq. 4.4): recovered curves on a synthetic gamma camera, cross-checked
// against OpenCV's CalibrateDebevec on the very same samples.
#include "core/calibration/camera_response.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/photo.hpp>
#include <random>

namespace inspection {
namespace {

// Synthetic camera: Z = 255 (X / X_sat)^(1/2.2), X = E dt (dt in us), Gaussian read noise.
constexpr double kGamma = 2.2;
constexpr double kSaturationExposure = 4.0e4;

int GammaCamera(double x, double noise, std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, noise);
  const double z = 255.0 * std::pow(std::max(x, 0.0) / kSaturationExposure, 1.0 / kGamma) + n(rng);
  return static_cast<int>(std::clamp(std::lround(z), 0L, 255L));
}

// True crf in the gauge crf(128) = 0: ln X(z) - ln X(128) = gamma ln(z / 128).
double TrueCrf(int z) { return kGamma * std::log(z / 128.0); }

struct Series {
  std::vector<cv::Mat> images;  // 10x10 CV_8UC1, one per exposure
  std::vector<double> exposure_us;
  std::vector<std::vector<int>> z;  // [pixel][image]
};

Series MakeSeries(double noise, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> log_e(std::log(0.5), std::log(200.0));
  std::vector<double> irradiance(100);
  for (double& e : irradiance) e = std::exp(log_e(rng));
  Series s;
  for (int j = 0; j < 16; ++j) s.exposure_us.push_back(100.0 * std::pow(1000.0, j / 15.0));  // 100 us .. 100 ms
  s.z.assign(100, std::vector<int>(16));
  for (int j = 0; j < 16; ++j) {
    cv::Mat img(10, 10, CV_8UC1);
    for (int i = 0; i < 100; ++i) {
      const int z = GammaCamera(irradiance[i] * s.exposure_us[j], noise, rng);
      img.at<uint8_t>(i / 10, i % 10) = static_cast<uint8_t>(z);
      s.z[i][j] = z;
    }
    s.images.push_back(img);
  }
  return s;
}

TEST(CameraResponseTest, RecoversGammaCurveWithoutNoise) {
  const Series s = MakeSeries(0.0, 1);
  CameraResponseOptions o;
  o.smoothness_lambda = 1.0;
  auto r = SolveCameraResponse(s.z, s.exposure_us, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_TRUE(r->Validate().ok());
  EXPECT_DOUBLE_EQ(r->log_exposure[128], 0.0);
  // Quantisation alone: half a grey level at z = 32 is 2.2 * 0.5 / 32 = 0.034 ln units.
  double worst = 0;
  for (int z = 32; z <= 240; ++z) worst = std::max(worst, std::abs(r->log_exposure[z] - TrueCrf(z)));
  EXPECT_LT(worst, 0.04);
  EXPECT_EQ(r->image_count, 16);
}

TEST(CameraResponseTest, NoisySeriesStaysWithinTwoPercentInMidRange) {
  const Series s = MakeSeries(0.8, 2);
  CameraResponseOptions o;
  auto r = SolveCameraResponse(s.z, s.exposure_us, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  double worst = 0;
  for (int z = 48; z <= 230; ++z) worst = std::max(worst, std::abs(r->log_exposure[z] - TrueCrf(z)));
  // 0.02 ln units = 2 % in exposure.
  EXPECT_LT(worst, 0.02);
  EXPECT_GT(r->fit_rms_residual, 0.0);
}

// OpenCV's CalibrateDebevec solves the same system (gsolve) with weights w(z) + 1 instead of
// eq. 3.41's w(z), SVD instead of CHOLMOD, and the same gauge g(128) = 0. On identical samples
// the curves must agree to well below a grey level's worth of exposure: 0.01 ln units between
// z = 16 and 240, where the weight difference is below 1/16.
TEST(CameraResponseTest, AgreesWithOpenCvCalibrateDebevecOnSameSamples) {
  const Series s = MakeSeries(0.8, 3);
  std::vector<float> times_s;
  for (double t : s.exposure_us) times_s.push_back(static_cast<float>(t * 1e-6));
  cv::Ptr<cv::CalibrateDebevec> cal = cv::createCalibrateDebevec(100, 10.0f, false);
  cv::Mat ocv;
  cal->process(s.images, ocv, times_s);
  ASSERT_EQ(ocv.rows, 256);
  CameraResponseOptions o;
  o.smoothness_lambda = 10.0;
  auto r = SolveCameraResponse(s.z, s.exposure_us, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const double g128 = std::log(ocv.at<float>(128, 0));
  double worst = 0;
  for (int z = 16; z <= 240; ++z) {
    const double g = std::log(ocv.at<float>(z, 0)) - g128;
    worst = std::max(worst, std::abs(g - r->log_exposure[z]));
  }
  std::printf("crf vs OpenCV CalibrateDebevec: worst |difference| z 16..240 = %.5f ln\n", worst);
  EXPECT_LT(worst, 0.01);
  // And both are close to the truth in the well-exposed range.
  for (int z = 48; z <= 230; z += 10) EXPECT_NEAR(r->log_exposure[z], TrueCrf(z), 0.02) << "z=" << z;
}

TEST(CameraResponseTest, EstimateFromImagesPicksSpreadSamples) {
  // 64x48 image whose irradiance ramps across x; 12 exposures.
  std::mt19937 rng(4);
  std::vector<cv::Mat> images;
  std::vector<double> dt;
  for (int j = 0; j < 12; ++j) {
    dt.push_back(200.0 * std::pow(2.0, j * 0.8));
    cv::Mat img(48, 64, CV_8UC1);
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 64; ++x) img.at<uint8_t>(y, x) = GammaCamera((1.0 + x * 2.0 + y) * dt.back(), 0.5, rng);
    images.push_back(img);
  }
  CameraResponseOptions o;
  o.sample_pixel_count = 60;
  auto r = EstimateCameraResponse(images, dt, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_GE(r->sample_pixel_count, 50);
  for (int z = 48; z <= 230; z += 10) EXPECT_NEAR(r->log_exposure[z], TrueCrf(z), 0.03) << "z=" << z;

  // Radiance (eq. 4.5) and HDR merge (eq. 3.44) invert the synthetic camera.
  auto merged = MergeRadiance(images, dt, *r);
  ASSERT_TRUE(merged.ok());
  // Relative irradiance between two pixels is gauge-free: pixel (x=40,y=0) vs (x=10,y=0).
  const double ratio = merged->at<float>(0, 40) / merged->at<float>(0, 10);
  EXPECT_NEAR(ratio, 81.0 / 21.0, 0.05 * 81.0 / 21.0);
  // GreyForLogExposure inverts LogExposure.
  for (double z : {20.0, 100.5, 200.25}) EXPECT_NEAR(r->GreyForLogExposure(r->LogExposure(z)), z, 1e-6);
}

TEST(CameraResponseTest, RejectsBadInput) {
  CameraResponseOptions o;
  EXPECT_EQ(SolveCameraResponse({{1, 2}}, {1.0}, o).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(SolveCameraResponse({{1, 2}, {3, 300}}, {1.0, 2.0}, o).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(SolveCameraResponse({{1, 2}, {3, 4}}, {1.0, -2.0}, o).status().code(), StatusCode::kInvalidArgument);
  CameraResponseFunction bad;
  bad.log_exposure.assign(256, 0.0);
  bad.log_exposure[10] = -1;
  EXPECT_FALSE(bad.Validate().ok());
}

}  // namespace
}  // namespace inspection
