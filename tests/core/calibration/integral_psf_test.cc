// Integral PSF (thesis 5.4.1, eq. 5.22-5.23): a stack of a random texture blurred by growing
// Gaussians; the estimated kernel must restore the focused image from the integral image.
#include "core/calibration/integral_psf.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <random>

namespace inspection {
namespace {

struct Stack {
  cv::Mat focused;
  std::vector<cv::Mat> frames;
};

Stack MakeStack(uint64_t seed) {
  cv::RNG rng(seed);
  Stack s;
  cv::Mat noise(96, 112, CV_32FC1);
  rng.fill(noise, cv::RNG::UNIFORM, 0.0, 200.0);
  cv::GaussianBlur(noise, s.focused, {0, 0}, 0.8);
  for (double sigma : {0.0, 0.7, 1.4, 2.1, 2.8, 3.5, 4.2}) {
    cv::Mat f;
    if (sigma == 0)
      f = s.focused.clone();
    else
      cv::GaussianBlur(s.focused, f, {0, 0}, sigma, sigma, cv::BORDER_REFLECT);
    s.frames.push_back(f);
  }
  return s;
}

TEST(IntegralPsfTest, RestoresFocusedImageFromIntegralImage) {
  const Stack s = MakeStack(1);
  auto integral = IntegralImage(s.frames);
  ASSERT_TRUE(integral.ok());
  IntegralPsfOptions o;
  o.radius_px = 8;
  o.regularisation_weight = 1e-5;
  auto ipsf = EstimateIntegralPsf(*integral, s.focused, o);
  ASSERT_TRUE(ipsf.ok()) << ipsf.status().ToString();
  ASSERT_TRUE(ipsf->Validate().ok());
  // The blur leaves a large error; the IPSF removes most of it.
  EXPECT_GT(ipsf->integral_rms_error, 5.0);
  EXPECT_LT(ipsf->restored_rms_error, 0.25 * ipsf->integral_rms_error);
  // Applying the stored kernel reproduces the figure on the interior.
  const cv::Mat restored = ipsf->Apply(*integral);
  const cv::Rect inner(10, 10, 92, 76);
  const double rms = std::sqrt(cv::norm(restored(inner), s.focused(inner), cv::NORM_L2SQR) / inner.area());
  EXPECT_LT(rms, 0.3 * ipsf->integral_rms_error);
  // Symmetric blur -> symmetric kernel with unit DC gain (the mean grey is preserved).
  EXPECT_NEAR(cv::sum(ipsf->kernel)[0], 1.0, 0.05);
  EXPECT_NEAR(ipsf->kernel.at<float>(8, 5), ipsf->kernel.at<float>(8, 11), 0.02);
  EXPECT_NEAR(ipsf->kernel.at<float>(5, 8), ipsf->kernel.at<float>(11, 8), 0.02);
}

TEST(IntegralPsfTest, TotalVariationOptionAlsoRestores) {
  const Stack s = MakeStack(2);
  auto integral = IntegralImage(s.frames);
  ASSERT_TRUE(integral.ok());
  IntegralPsfOptions o;
  o.radius_px = 6;
  o.regularisation = IpsfRegularisation::kTotalVariation;
  o.regularisation_weight = 1e-4;
  o.tv_reweight_iterations = 3;
  auto ipsf = EstimateIntegralPsf(*integral, s.focused, o);
  ASSERT_TRUE(ipsf.ok()) << ipsf.status().ToString();
  EXPECT_LT(ipsf->restored_rms_error, 0.35 * ipsf->integral_rms_error);
  EXPECT_EQ(ipsf->regularisation, IpsfRegularisation::kTotalVariation);
}

// TV-L1 (thesis Fig. 5.21's best): a few badly matched pixels in the focused image (dust, glints:
// 1 % of the pixels off by 150 grey) bend the L2 estimates, not the L1 one: its restoration of the
// clean image is as good from the corrupted calibration image as from the clean one.
TEST(IntegralPsfTest, TvL1KernelResistsOutliersInTheFocusedImage) {
  const Stack s = MakeStack(3);
  auto integral = IntegralImage(s.frames);
  ASSERT_TRUE(integral.ok());
  cv::Mat corrupted = s.focused.clone();
  cv::RNG rng(9);
  for (int i = 0; i < int(corrupted.total()) / 100; ++i) {
    corrupted.at<float>(rng.uniform(0, corrupted.rows), rng.uniform(0, corrupted.cols)) += 150.0f;
  }
  const cv::Rect inner(10, 10, 92, 76);
  // RMS error of the restored clean image, kernel estimated from `focused`.
  auto restored_error = [&](IpsfRegularisation reg, const cv::Mat& focused) {
    IntegralPsfOptions o;
    o.radius_px = 6;
    o.regularisation = reg;
    o.regularisation_weight = 1e-4;
    o.max_cg_iterations = 200;
    o.tv_reweight_iterations = 4;
    auto k = EstimateIntegralPsf(*integral, focused, o);
    EXPECT_TRUE(k.ok()) << k.status().ToString();
    EXPECT_EQ(k->regularisation, reg);
    return std::sqrt(cv::norm(k->Apply(*integral)(inner), s.focused(inner), cv::NORM_L2SQR) / inner.area());
  };
  const double l2_clean = restored_error(IpsfRegularisation::kGradientL2, s.focused);
  const double l2_corrupt = restored_error(IpsfRegularisation::kGradientL2, corrupted);
  const double l1_clean = restored_error(IpsfRegularisation::kTotalVariationL1, s.focused);
  const double l1_corrupt = restored_error(IpsfRegularisation::kTotalVariationL1, corrupted);
  EXPECT_GT(l2_corrupt, 1.1 * l2_clean) << "the outliers must matter to L2 for this test to mean anything";
  EXPECT_LT(l1_corrupt, 1.03 * l1_clean) << "TV-L1 clean " << l1_clean << " corrupted " << l1_corrupt;
  EXPECT_LT(l1_clean, 0.6 * std::sqrt(cv::norm((*integral)(inner), s.focused(inner), cv::NORM_L2SQR) / inner.area()));
}

TEST(IntegralPsfTest, RegularisationNamesRoundTrip) {
  for (IpsfRegularisation r :
       {IpsfRegularisation::kGradientL2, IpsfRegularisation::kTotalVariation, IpsfRegularisation::kTotalVariationL1}) {
    auto p = ParseIpsfRegularisation(IpsfRegularisationName(r));
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(*p, r);
  }
  EXPECT_EQ(*ParseIpsfRegularisation("tv_l2"), IpsfRegularisation::kTotalVariation);
  const auto bad = ParseIpsfRegularisation("l0");
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("tv_l1"), std::string::npos);
}

TEST(IntegralPsfTest, RejectsMismatchedImages) {
  EXPECT_FALSE(EstimateIntegralPsf(cv::Mat(40, 40, CV_32FC1), cv::Mat(41, 40, CV_32FC1), {}).ok());
  EXPECT_FALSE(EstimateIntegralPsf(cv::Mat(10, 10, CV_32FC1), cv::Mat(10, 10, CV_32FC1), {}).ok());
}

}  // namespace
}  // namespace inspection
