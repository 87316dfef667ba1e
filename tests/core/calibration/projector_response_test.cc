// Projector response (thesis eq. 4.8-4.9) through a known gamma camera and a known projector.
#include "core/calibration/projector_response.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace inspection {
namespace {

// Camera: Z = 255 (X / 2e4)^(1/2.2); crf in the gauge of CameraResponseFunction (exact, no fit).
CameraResponseFunction GammaCrf() {
  CameraResponseFunction c;
  for (int z = 0; z < 256; ++z) c.log_exposure.push_back(std::log(2e4) + 2.2 * std::log(std::max(z, 1) / 255.0));
  return c;
}

// Projector: black level 0.004, gamma 2.0.
double TruePrf(int i) { return 0.004 + 0.996 * std::pow(i / 255.0, 2.0); }

TEST(ProjectorResponseTest, ExposuresFollowEq48) {
  EXPECT_NEAR(ProjectorCalibrationExposureUs(0, 100, 10000), 10000, 1e-6);
  EXPECT_NEAR(ProjectorCalibrationExposureUs(255, 100, 10000), 100, 1e-6);
  EXPECT_NEAR(ProjectorCalibrationExposureUs(128, 100, 10000), std::exp(std::log(10000) - std::log(100) * 128 / 255),
              1e-6);
}

TEST(ProjectorResponseTest, RecoversGammaProjectorWithinOnePercentOfFullScale) {
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 0.7);
  // A plane of mildly varying reflectance (the ratio of eq. 4.9 removes it).
  cv::Mat reflectance(30, 40, CV_64FC1);
  cv::randu(reflectance, 0.7, 1.0);
  std::vector<ProjectorResponseCapture> caps;
  for (int i = 0; i <= 255; i += 15) {
    const int grey = i;
    // Projector irradiance 1 at grey 255 gives E = 200 per unit reflectance.
    const double dt = ProjectorCalibrationExposureUs(grey, 60, 600);
    cv::Mat img(30, 40, CV_8UC1);
    for (int y = 0; y < 30; ++y)
      for (int x = 0; x < 40; ++x) {
        const double xexp = 200.0 * reflectance.at<double>(y, x) * TruePrf(grey) * dt;
        img.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(255.0 * std::pow(xexp / 2e4, 1 / 2.2) + noise(rng));
      }
    caps.push_back({grey, dt, img});
  }
  auto p = EstimateProjectorResponse(caps, GammaCrf(), {});
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  ASSERT_TRUE(p->Validate().ok()) << p->Validate().ToString();
  double worst = 0;
  for (int i = 0; i < 256; ++i) worst = std::max(worst, std::abs(p->relative_irradiance[i] - TruePrf(i)));
  EXPECT_LT(worst, 0.01);
  EXPECT_DOUBLE_EQ(p->relative_irradiance[255], 1.0);
  EXPECT_NEAR(p->GreyForIrradiance(p->Irradiance(100.0)), 100.0, 1e-6);
  EXPECT_LT(p->pixel_ratio_cv, 0.05);
}

TEST(ProjectorResponseTest, RequiresFullWhiteLevel) {
  std::vector<ProjectorResponseCapture> caps{{0, 100, cv::Mat(4, 4, CV_8UC1, cv::Scalar(100))},
                                             {128, 100, cv::Mat(4, 4, CV_8UC1, cv::Scalar(100))}};
  EXPECT_EQ(EstimateProjectorResponse(caps, GammaCrf(), {}).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
