// The renderer's chain (thesis 5.1.1, eq. 5.1-5.4) on analytic scenes: each stage in order,
// light only where the projector reaches, defocus applied on the way in and on the way out.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "devices/sim/image_formation.h"

namespace inspection {
namespace {

// A flat specimen at height 100 um with uniform reflectance and no texture.
Specimen Flat(cv::Size size, float reflectance) {
  Specimen s;
  s.name = "flat";
  s.height_um = cv::Mat(size, CV_32FC1, cv::Scalar(100.0));
  s.reflectance = cv::Mat(size, CV_32FC1, cv::Scalar(reflectance));
  s.texture = cv::Mat(size, CV_32FC1, cv::Scalar(1.0));
  return s;
}

ImageFormationOptions SmallOptions(cv::Size camera, cv::Size projector) {
  ImageFormationOptions o;
  o.camera_size = camera;
  o.projector_size = projector;
  o.camera.shot_noise = false;
  o.camera.read_noise_dn8 = 0.0;
  return o;
}

TEST(ImageFormationTest, UniformLightOnUniformSurfaceFollowsEq51To54) {
  const ImageFormationOptions o = SmallOptions({128, 96}, {1280, 720});
  auto f = ImageFormation::Create(o, Flat(o.camera_size, 0.4f));
  ASSERT_TRUE(f.ok());
  const cv::Mat pattern(o.projector_size, CV_8UC1, cv::Scalar(200));
  // E_c = R * prf(200), whatever the defocus.
  for (double z : {100.0, 130.0}) {
    auto ec_or = (*f)->CameraIrradiance(pattern, z);
    ASSERT_TRUE(ec_or.ok());
    const cv::Mat& ec = *ec_or;
    double lo, hi;
    cv::minMaxLoc(ec, &lo, &hi);
    EXPECT_NEAR(lo, 0.4 * o.projector.Irradiance(200), 1e-6);
    EXPECT_NEAR(hi, 0.4 * o.projector.Irradiance(200), 1e-6);
  }
  // Z_c = crf(E_c * dt): 0.4 * prf(200) * 1500 us * 10 e/us / 10000 e.
  auto frame = (*f)->Render(pattern, 100.0, 1500.0, 0.0, 1);
  ASSERT_TRUE(frame.ok());
  const double x = 0.4 * o.projector.Irradiance(200) * 1500.0 * 10.0 / 10000.0;
  EXPECT_EQ(frame->at<uint8_t>(40, 60), std::lround(o.camera.GreyForRelativeExposure(x)));
  EXPECT_EQ(cv::countNonZero(*frame != frame->at<uint8_t>(40, 60)), 0);
  // The exposure solved for mean grey 128 gives it.
  const double dt = (*f)->ExposureForMeanGrey(128, 128.0);
  EXPECT_NEAR(o.camera.GreyForRelativeExposure(0.4 * o.projector.Irradiance(128) * dt * 10.0 / 10000.0), 128.0, 1e-3);
}

TEST(ImageFormationTest, NoLightOutsideTheProjectorImage) {
  // A small projector covers only the middle of the camera: 40 px * 3.4 = 136 camera px.
  const ImageFormationOptions o = SmallOptions({256, 256}, {40, 40});
  auto f = ImageFormation::Create(o, Flat(o.camera_size, 0.5f));
  ASSERT_TRUE(f.ok());
  auto ep_or = (*f)->ProjectorIrradianceOnCamera(cv::Mat(o.projector_size, CV_8UC1, cv::Scalar(255)));
  ASSERT_TRUE(ep_or.ok());
  const cv::Mat& ep = *ep_or;
  EXPECT_FLOAT_EQ(ep.at<float>(128, 128), 1.0f);
  EXPECT_FLOAT_EQ(ep.at<float>(5, 5), 0.0f);
  EXPECT_FLOAT_EQ(ep.at<float>(128, 250), 0.0f);
  EXPECT_NEAR(cv::sum(ep)[0], 40.0 * 40.0 * 3.4 * 3.4, 0.02 * 40 * 40 * 3.4 * 3.4);
}

// Second moment of a lit projector pixel's image about its centroid.
double SpotVariance(const cv::Mat& e) {
  const cv::Moments m = cv::moments(e);
  return 0.5 * (m.mu20 + m.mu02) / m.m00;
}

TEST(ImageFormationTest, ProjectedSpotIsDefocusedTwice) {
  const ImageFormationOptions o = SmallOptions({128, 128}, {64, 64});
  auto f = ImageFormation::Create(o, Flat(o.camera_size, 1.0f));
  ASSERT_TRUE(f.ok());
  cv::Mat pattern(o.projector_size, CV_8UC1, cv::Scalar(0));
  pattern.at<uint8_t>(32, 32) = 255;
  const double black = o.projector.Irradiance(0);
  auto spot = [&](double z) {
    auto ec = (*f)->CameraIrradiance(pattern, z);
    EXPECT_TRUE(ec.ok());
    cv::Mat e = *ec - black;
    return e(cv::Rect(24, 24, 80, 80)).clone();
  };
  const double box_variance = 3.4 * 3.4 / 12.0;  // one square projector pixel
  for (double dz : {0.0, 6.0, 12.0}) {
    const double sigma = o.defocus.SigmaPx(dz);
    // In: box * PSF; out: * PSF again -> variances add.
    const double expected = box_variance + 2.0 * sigma * sigma;
    EXPECT_NEAR(SpotVariance(spot(100.0 + dz)), expected, 0.12 * expected) << "dz " << dz;
  }
}

TEST(ImageFormationTest, RejectsBadInput) {
  const ImageFormationOptions o = SmallOptions({64, 48}, {128, 96});
  auto f = ImageFormation::Create(o, Flat(o.camera_size, 0.5f));
  ASSERT_TRUE(f.ok());
  const cv::Mat ok_pattern(o.projector_size, CV_8UC1, cv::Scalar(128));
  EXPECT_EQ((*f)->Render(cv::Mat(10, 10, CV_8UC1), 100, 1000, 0, 1).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*f)->Render(ok_pattern, NAN, 1000, 0, 1).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*f)->Render(ok_pattern, 100, -1, 0, 1).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*f)->SetSpecimen(Flat({10, 10}, 0.5f)).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*f)->CameraIrradiance(cv::Mat(10, 10, CV_8UC1), 100).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*f)->ProjectorIrradianceOnCamera(cv::Mat(o.projector_size, CV_16UC1)).status().code(),
            StatusCode::kInvalidArgument);
  ImageFormationOptions bad = o;
  bad.defocus.in_focus_sigma_px = 0.0;
  EXPECT_EQ(ImageFormation::Create(bad, Flat(o.camera_size, 0.5f)).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
