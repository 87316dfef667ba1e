// ISO 25178-600 characteristics on synthetic maps of known truth: each injected error (noise
// level, flatness, z amplification and linearity, lateral scale, resolution) is recovered within
// its own expanded uncertainty (k = 2), and the uncertainty is not wider than the evidence allows.
#include "core/metrology/verification.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

// White noise of sigma um, smoothed over a k x k box and rescaled back to sigma (correlated like
// SFF depth noise over its focus window).
cv::Mat Noise(cv::Size size, double sigma, int k, uint64_t seed) {
  cv::Mat n(size, CV_32FC1);
  cv::RNG rng(seed);
  rng.fill(n, cv::RNG::NORMAL, 0.0, 1.0);
  if (k > 1) cv::blur(n, n, cv::Size(k, k));
  cv::Scalar m, s;
  cv::meanStdDev(n, m, s);
  return (n - m[0]) * (sigma / s[0]);
}

TEST(VerificationTest, MeasurementNoiseRecoversTheInjectedLevel) {
  const cv::Size size(320, 240);
  const double sigma = 0.025;  // um per map
  cv::Mat flat(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) flat.at<float>(y, x) = float(200.0 + 0.001 * x + 0.05 * std::sin(x / 30.0));
  const cv::Mat a = flat + Noise(size, sigma, 5, 1);
  const cv::Mat b = flat + Noise(size, sigma, 5, 2) + 0.3f;  // re-placed 0.3 um higher
  auto n = MeasurementNoise(a, b, 5);
  ASSERT_TRUE(n.ok()) << n.status().ToString();
  std::printf("N_M %.5f um, u %.5f um (injected %.5f)\n", n->value, n->standard_uncertainty, sigma);
  EXPECT_NEAR(n->value, sigma, 2 * n->standard_uncertainty);
  EXPECT_LT(n->standard_uncertainty, 0.05 * sigma);
  cv::Mat holes = a.clone();
  holes.setTo(NAN);
  EXPECT_EQ(MeasurementNoise(holes, b, 5).status().code(), StatusCode::kInvalidArgument);
}

TEST(VerificationTest, FlatnessDeviationRecoversAnInjectedBow) {
  const cv::Size size(320, 240);
  const double bow = 0.2;  // um peak to valley: a paraboloid over the field
  cv::Mat flat(size, CV_32FC1);
  const double cx = 159.5, cy = 119.5, r2 = cx * cx + cy * cy;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      flat.at<float>(y, x) = float(200.0 + 0.002 * y + bow * ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / r2);
    }
  // Symmetric about the centre: its least-squares plane is level, so levelling keeps the bow.
  const cv::Mat a = flat + Noise(size, 0.02, 5, 3);
  const cv::Mat b = flat + Noise(size, 0.02, 5, 4);
  auto f = FlatnessDeviation(a, b, 5);
  ASSERT_TRUE(f.ok()) << f.status().ToString();
  // 20 x 20 px block means: the corner blocks' centres sit 9.5 px inside the field, so the truth
  // on the block grid (the block mean of the paraboloid) is below the bow.
  const double truth = bow * ((150.0 * 150.0 + 110.0 * 110.0 + 2 * (20.0 * 20.0 - 1) / 12.0) / r2);
  std::printf("z_FLT %.4f um, u %.4f um (injected bow %.4f, %.4f on the block grid)\n", f->value,
              f->standard_uncertainty, bow, truth);
  EXPECT_NEAR(f->value, truth, 2 * f->standard_uncertainty);
  EXPECT_LT(f->standard_uncertainty, 0.1 * bow);  // sharp enough to see the bow
}

TEST(VerificationTest, AmplificationAndLinearityFromStepHeights) {
  // An instrument reading 0.5 % long with a 30 nm bump at the 10 um step.
  std::vector<ResponsePoint> points;
  for (double h : {1.0, 5.0, 10.0, 25.0, 50.0}) {
    ResponsePoint p;
    p.certified_um = h;
    p.certified_u_um = 0.002 + 0.0005 * h;
    p.measured_um = 1.005 * h + (h == 10.0 ? 0.03 : 0.0);
    p.measured_u_um = 0.01;
    points.push_back(p);
  }
  auto r = AmplificationAndLinearity(points);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  std::printf("alpha_z %.5f u %.5f, offset %.4f u %.4f, l_z %.4f u %.4f\n", r->alpha_z.value,
              r->alpha_z.standard_uncertainty, r->offset_um.value, r->offset_um.standard_uncertainty, r->l_z_um.value,
              r->l_z_um.standard_uncertainty);
  EXPECT_NEAR(r->alpha_z.value, 1.005, 2 * r->alpha_z.standard_uncertainty + 1e-4);
  EXPECT_LT(r->alpha_z.standard_uncertainty, 0.001);  // sharp enough to see a 0.5 % error
  EXPECT_NEAR(r->l_z_um.value, 0.03, 2 * r->l_z_um.standard_uncertainty);
  points.resize(1);
  EXPECT_EQ(AmplificationAndLinearity(points).status().code(), StatusCode::kInvalidArgument);
}

TEST(VerificationTest, LateralAmplificationRecoversAScaleError) {
  // A cross grating of 20 um pitch seen by an instrument whose lateral scale is 1 % long: the
  // pitch spans 1.01 x 20 um of its assumed pixel size.
  const double pixel = 0.74, pitch = 20.0, scale = 1.01;
  const cv::Size size(320, 240);
  cv::Mat g(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double xu = (x + 0.5) * pixel / scale, yu = (y + 0.5) * pixel / scale;
      g.at<float>(y, x) = float(200.0 + 0.1 * std::sin(2 * M_PI * xu / pitch) * std::sin(2 * M_PI * yu / pitch + 0.3) +
                                0.1 * std::sin(2 * M_PI * xu / pitch));
    }
  g += Noise(size, 0.01, 5, 5);
  auto ax = LateralAmplification(g, pixel, pitch, 0);
  ASSERT_TRUE(ax.ok()) << ax.status().ToString();
  std::printf("alpha_x %.5f u %.5f (injected %.5f)\n", ax->value, ax->standard_uncertainty, scale);
  // One map pixel covers pixel / scale um of the grating but is reported as pixel um: the pitch
  // reads pitch * scale, alpha_x = scale.
  EXPECT_NEAR(ax->value, scale, 2 * ax->standard_uncertainty);
  EXPECT_LT(ax->standard_uncertainty, 0.003);
  // A grating of 400 um pitch shows less than a period in the 237 um field.
  cv::Mat coarse(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) coarse.at<float>(y, x) = float(0.1 * std::sin(2 * M_PI * (x + 0.5) * pixel / 400.0));
  coarse += Noise(size, 0.01, 5, 7);
  EXPECT_EQ(LateralAmplification(coarse, pixel, 400.0, 0).status().code(), StatusCode::kInvalidArgument);
}

TEST(VerificationTest, TopographicSpatialResolutionAtHalfAmplitude) {
  // An instrument whose amplitude transfer is a Gaussian filter with a 50 % period of 8 um.
  const double wr = 8.0;
  std::vector<TransferPoint> points;
  for (double p : {4.0, 6.0, 10.0, 20.0}) {
    TransferPoint t;
    t.period_um = p;
    t.certified_amplitude_um = 0.5;
    const double transfer = std::exp(std::log(0.5) * (wr / p) * (wr / p));
    t.measured_amplitude_um = 0.5 * transfer;
    t.measured_amplitude_u_um = 0.005;
    points.push_back(t);
  }
  auto w = TopographicSpatialResolution(points);
  ASSERT_TRUE(w.ok()) << w.status().ToString();
  std::printf("W_R %.3f um u %.3f um (true %.1f; linear interpolation between 6 and 10 um)\n", w->value,
              w->standard_uncertainty, wr);
  EXPECT_NEAR(w->value, wr, 2 * w->standard_uncertainty + 0.3);  // + the interpolation's own error
  EXPECT_EQ(TopographicSpatialResolution({points[3]}).status().code(), StatusCode::kFailedPrecondition);

  // The amplitude of a measured sinusoid from a map.
  const cv::Size size(320, 240);
  cv::Mat s(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) s.at<float>(y, x) = float(200.0 + 0.002 * x + 0.3 * std::sin(2 * M_PI * x / 40.0));
  s += Noise(size, 0.02, 5, 6);
  auto a = SinusoidAmplitudeAlongX(s, 5);
  ASSERT_TRUE(a.ok());
  std::printf("amplitude %.4f u %.4f (0.3)\n", a->value, a->standard_uncertainty);
  EXPECT_NEAR(a->value, 0.3, 2 * a->standard_uncertainty + 0.002);
}

}  // namespace
}  // namespace inspection
