// Defocus PSF of the simulated rig (thesis 4.3.3): width grows with |h - z|, Gaussian near
// focus, pillbox far from it; the fast spatially varying blur reproduces the model's width.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "devices/sim/defocus.h"

namespace inspection {
namespace {

// Second moment (per axis) of a non-negative image about its centroid.
double SecondMoment(const cv::Mat& img) {
  const cv::Moments m = cv::moments(img);
  return 0.5 * (m.mu20 + m.mu02) / m.m00;
}

TEST(DefocusModelTest, SigmaGrowsWithDefocusAsTheBlurCircle) {
  DefocusModel d;
  EXPECT_DOUBLE_EQ(d.SigmaPx(0.0), d.in_focus_sigma_px);
  EXPECT_DOUBLE_EQ(d.SigmaPx(-10.0), d.SigmaPx(10.0));
  // Far from focus sigma -> radius / 2 = 0.5 * k |dz|.
  EXPECT_NEAR(d.SigmaPx(100.0), 0.5 * d.blur_radius_px_per_um * 100.0, 0.02);
  for (double dz = 0.5; dz < 50; dz += 0.5) EXPECT_GT(d.SigmaPx(dz), d.SigmaPx(dz - 0.5));
  // Two 5 um steps from focus the texture is clearly blurred (sigma > 3.5x the in-focus one).
  EXPECT_GT(d.SigmaPx(10.0), 3.5 * d.in_focus_sigma_px);
}

TEST(DefocusModelTest, KernelIsGaussianNearFocusAndPillboxFarAway) {
  DefocusModel d;
  for (double s : {0.8, 1.5, 3.0, 6.0, 12.0}) {
    const cv::Mat k = d.Kernel(s);
    EXPECT_NEAR(cv::sum(k)[0], 1.0, 1e-5);
    EXPECT_NEAR(std::sqrt(SecondMoment(k)), s, 0.04 * s) << "sigma " << s;
  }
  // Near focus: Gaussian profile, centre / value at 1 sigma = exp(0.5).
  const cv::Mat g = d.Kernel(1.2);
  const int c = g.rows / 2;
  EXPECT_LT(d.PillboxWeight(1.2), 1e-9);
  EXPECT_NEAR(g.at<float>(c, c) / g.at<float>(c, c + 1) / std::exp(0.5 / (1.2 * 1.2)), 1.0, 1e-4);
  // Far: flat top (radius 2 sigma): the centre equals the value at half the radius.
  const cv::Mat p = d.Kernel(12.0);
  const int pc = p.rows / 2;
  EXPECT_DOUBLE_EQ(d.PillboxWeight(12.0), 1.0);
  EXPECT_FLOAT_EQ(p.at<float>(pc, pc), p.at<float>(pc, pc + 12));
  EXPECT_EQ(p.at<float>(pc, pc + 26), 0.0f);
}

// Impulse response of the fast blur at a constant sigma has that sigma.
TEST(SpatiallyVaryingBlurTest, ImpulseResponseWidthFollowsTheModel) {
  DefocusModel d;
  SpatiallyVaryingBlur blur(d);
  const cv::Size size(160, 160);
  for (double s : {0.55, 0.9, 1.3, 2.0, 2.5, 3.5, 5.0, 7.5, 11.0}) {
    cv::Mat src(size, CV_32FC1, cv::Scalar(0));
    src.at<float>(80, 80) = 1.0f;
    cv::Mat sigma(size, CV_32FC1, cv::Scalar(s)), dst;
    blur.Apply(src, sigma, &dst);
    EXPECT_NEAR(cv::sum(dst)[0], 1.0, 1e-3) << s;
    EXPECT_NEAR(std::sqrt(SecondMoment(dst)), s, 0.08 * s + 0.05) << "sigma " << s;
  }
}

TEST(SpatiallyVaryingBlurTest, EachPixelGetsItsOwnWidth) {
  DefocusModel d;
  SpatiallyVaryingBlur blur(d);
  const cv::Size size(192, 96);
  cv::Mat src(size, CV_32FC1, cv::Scalar(0));
  src.at<float>(48, 48) = 1.0f;
  src.at<float>(48, 144) = 1.0f;
  cv::Mat sigma(size, CV_32FC1, cv::Scalar(1.0));
  sigma.colRange(96, 192).setTo(4.0);
  cv::Mat dst;
  blur.Apply(src, sigma, &dst);
  EXPECT_NEAR(std::sqrt(SecondMoment(dst.colRange(0, 96))), 1.0, 0.08);
  EXPECT_NEAR(std::sqrt(SecondMoment(dst.colRange(96, 192))), 4.0, 0.3);
  // A constant image stays constant whatever the blur.
  cv::Mat flat(size, CV_32FC1, cv::Scalar(0.7));
  blur.Apply(flat, sigma, &dst);
  double lo, hi;
  cv::minMaxLoc(dst, &lo, &hi);
  EXPECT_NEAR(lo, 0.7, 1e-5);
  EXPECT_NEAR(hi, 0.7, 1e-5);
}

// Where sigma varies across the image the two passes differ. The gather (Apply: each output
// pixel takes its own sigma) moves a point's image towards the larger blur (by about
// d(sigma^2)/dx = 0.24 px here for a Gaussian); the scatter (ApplyScatter: each source point
// spreads by its own sigma) keeps it centred, with that point's width, and conserves the energy.
// The source is a pair of pixels either side of x = 80 (centroid 79.5), so that the reduced rungs'
// 2^k x 2^k blocks do not move it. A uniform sigma gives the same image both ways.
TEST(SpatiallyVaryingBlurTest, PointSpreadKeepsAPointCentredWhereTheBlurVaries) {
  DefocusModel d;
  SpatiallyVaryingBlur blur(d);
  const cv::Size size(160, 96);
  cv::Mat src(size, CV_32FC1, cv::Scalar(0));
  src.at<float>(47, 79) = src.at<float>(47, 80) = src.at<float>(48, 79) = src.at<float>(48, 80) = 0.25f;
  cv::Mat sigma(size, CV_32FC1);
  const double slope = 0.04;  // sigma 3 px at the point, growing 0.04 px per px to the right
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) sigma.at<float>(y, x) = float(3.0 + slope * (x - 79.5));
  const BlurPlan plan = blur.Plan(sigma);
  cv::Mat gather, scatter;
  blur.Apply(src, plan, &gather);
  blur.ApplyScatter(src, plan, &scatter);
  const cv::Moments g = cv::moments(gather), s = cv::moments(scatter);
  EXPECT_NEAR(s.m00, 1.0, 1e-3);
  EXPECT_NEAR(s.m10 / s.m00, 79.5, 0.05);
  EXPECT_NEAR(s.m01 / s.m00, 47.5, 0.05);
  EXPECT_NEAR(std::sqrt(0.5 * (s.mu20 + s.mu02) / s.m00), 3.0, 0.3);
  EXPECT_GT(g.m10 / g.m00 - 79.5, 0.15);
  cv::Mat uniform(size, CV_32FC1, cv::Scalar(2.5)), a, b;
  const BlurPlan flat = blur.Plan(uniform);
  cv::Mat texture(size, CV_32FC1);
  cv::randu(texture, 0.0, 1.0);
  blur.Apply(texture, flat, &a);
  blur.ApplyScatter(texture, flat, &b);
  EXPECT_LT(cv::norm(a, b, cv::NORM_INF), 1e-4);
}

}  // namespace
}  // namespace inspection
