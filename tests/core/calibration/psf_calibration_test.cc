// PSF calibration (thesis 4.3.3) and sigma_p (thesis 5.2.1): Gaussian dots of known width.
#include "core/calibration/psf_calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace inspection {
namespace {

PsfCapture GaussianDots(double sigma, double defocus_um, std::mt19937& rng) {
  PsfCapture c;
  c.defocus_um = defocus_um;
  c.signal = cv::Mat(120, 160, CV_32FC1, cv::Scalar(0));
  std::normal_distribution<float> noise(0.0f, 0.3f);
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) c.signal.at<float>(y, x) = noise(rng);
  for (double cy = 20.3; cy < 110; cy += 30)
    for (double cx = 20.6; cx < 150; cx += 30) {
      c.dot_centres.emplace_back(cx, cy);
      for (int y = 0; y < 120; ++y)
        for (int x = 0; x < 160; ++x)
          c.signal.at<float>(y, x) +=
              static_cast<float>(50.0 * std::exp(-((x - cx) * (x - cx) + (y - cy) * (y - cy)) / (2 * sigma * sigma)));
    }
  return c;
}

TEST(PsfCalibrationTest, RecoversSigmaPerDefocusAndInfluenceRadius) {
  std::mt19937 rng(3);
  std::vector<PsfCapture> caps;
  const std::vector<std::pair<double, double>> truth = {{-10, 2.5}, {0, 1.2}, {10, 2.4}, {20, 3.6}};
  for (auto [dz, s] : truth) caps.push_back(GaussianDots(s, dz, rng));
  PsfOptions o;
  o.patch_radius_px = 13;
  auto psf = EstimatePsf(caps, o);
  ASSERT_TRUE(psf.ok()) << psf.status().ToString();
  ASSERT_TRUE(psf->Validate().ok());
  ASSERT_EQ(psf->steps.size(), 4u);
  for (size_t k = 0; k < 4; ++k) {
    EXPECT_DOUBLE_EQ(psf->steps[k].defocus_um, truth[k].first);
    EXPECT_NEAR(psf->steps[k].sigma_px, truth[k].second, 0.05 * truth[k].second) << k;
    EXPECT_EQ(psf->steps[k].dot_count, 15);
    EXPECT_NEAR(cv::sum(psf->steps[k].psf)[0], 1.0, 1e-5);
  }
  // Gaussian: 5 % of the peak at r = sigma sqrt(2 ln 20) = 2.448 sigma.
  EXPECT_NEAR(psf->influence_radius_px, 2.448 * 1.2, 0.2);
  EXPECT_EQ(psf->Focused()->defocus_um, 0.0);
}

TEST(PsfCalibrationTest, RejectsDuplicateDefocusAndEmptyInput) {
  std::mt19937 rng(1);
  EXPECT_FALSE(EstimatePsf({}, {}).ok());
  auto dup = EstimatePsf({GaussianDots(1.0, 0, rng), GaussianDots(1.0, 0, rng)}, {});
  EXPECT_EQ(dup.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
