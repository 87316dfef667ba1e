// ISO 16610-61 Gaussian filter: the mean surface keeps 50 % of a sinusoid at the cut-off
// wavelength and follows exp(-pi (alpha lc / lambda)^2) elsewhere, also with missing pixels
// (normalised convolution); constants survive masks exactly.
#include "core/metrology/areal_filter.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

using testing::kPi;

constexpr double kPx = 0.74;

// Amplitude of the component cos(2 pi x / lambda) in `m` over the pixels of `mask` (projection).
double CosineAmplitude(const cv::Mat& m, const cv::Mat& mask, double lambda_um) {
  double num = 0.0, den = 0.0;
  for (int row = 0; row < m.rows; ++row) {
    for (int col = 0; col < m.cols; ++col) {
      if (!mask.at<uint8_t>(row, col) || !std::isfinite(m.at<float>(row, col))) continue;
      const double c = std::cos(2.0 * kPi * (col + 0.5) * kPx / lambda_um);
      num += m.at<float>(row, col) * c;
      den += c * c;
    }
  }
  return num / den;
}

// Transmission of the mean surface for one wavelength, measured away from the borders (more than
// one cut-off from them, where the normalised convolution's end correction plays no part).
double MeasuredTransmission(double cutoff_um, double lambda_um, bool holes) {
  const cv::Size size(900, 40);
  cv::Mat z = testing::SampleSurface(size, kPx, [&](double x, double) { return std::cos(2.0 * kPi * x / lambda_um); });
  if (holes) testing::PunchHoles(z, 60, 3, 7);
  const cv::Mat all(size, CV_8UC1, cv::Scalar(255));
  auto mean = GaussianMeanSurface(z, all, kPx, cutoff_um);
  EXPECT_TRUE(mean.ok()) << mean.status().ToString();
  cv::Mat interior(size, CV_8UC1, cv::Scalar(0));
  const int margin = int(std::ceil(cutoff_um / kPx)) + 1;
  interior(cv::Rect(margin, 0, size.width - 2 * margin, size.height)).setTo(255);
  return CosineAmplitude(*mean, interior, lambda_um);
}

TEST(ArealFilterTest, AlphaAndTransmissionFormula) {
  EXPECT_NEAR(GaussianFilterAlpha(), 0.4697, 1e-4);  // ISO 16610-61 value
  EXPECT_DOUBLE_EQ(GaussianMeanTransmission(80.0, 80.0), 0.5);
  EXPECT_NEAR(GaussianFilterSigmaUm(80.0), 0.1874 * 80.0, 0.01);
}

TEST(ArealFilterTest, SinusoidAtTheCutOffKeepsHalfItsAmplitude) {
  // lc = 60 um: the sampled kernel (sigma ~15 px, truncated at +-lc = 5.3 sigma) matches the
  // continuous weighting function to ~1e-4 in transmission; 0.002 allows for the projection's
  // sampling over ~7 periods.
  for (double lc : {25.0, 60.0}) {
    std::printf("lc %.0f um: transmission at lc %.5f, at 2 lc %.5f (%.5f), at lc/2 %.5f (%.5f)\n", lc,
                MeasuredTransmission(lc, lc, false), MeasuredTransmission(lc, 2 * lc, false),
                GaussianMeanTransmission(lc, 2 * lc), MeasuredTransmission(lc, 0.5 * lc, false),
                GaussianMeanTransmission(lc, 0.5 * lc));
    EXPECT_NEAR(MeasuredTransmission(lc, lc, false), 0.5, 0.002) << "lc " << lc;
    EXPECT_NEAR(MeasuredTransmission(lc, 2.0 * lc, false), GaussianMeanTransmission(lc, 2.0 * lc), 0.002);
    EXPECT_NEAR(MeasuredTransmission(lc, 0.5 * lc, false), GaussianMeanTransmission(lc, 0.5 * lc), 0.002);
  }
  // 60 holes of radius 3 px (~5 % of the pixels): the normalised convolution re-weights the
  // remaining pixels, which shifts the transmission by well under 1 %.
  const double holed = MeasuredTransmission(60.0, 60.0, true);
  std::printf("lc 60 um with NaN holes: transmission at lc %.5f\n", holed);
  EXPECT_NEAR(holed, 0.5, 0.005);
}

TEST(ArealFilterTest, ConstantSurvivesMasksAndRegionEdgesExactly) {
  const cv::Size size(120, 80);
  cv::Mat z(size, CV_32FC1, cv::Scalar(7.25f));
  testing::PunchHoles(z, 10, 4, 1);
  cv::Mat mask(size, CV_8UC1, cv::Scalar(0));
  cv::circle(mask, cv::Point(60, 40), 30, cv::Scalar(255), cv::FILLED);
  auto mean = GaussianMeanSurface(z, mask, kPx, 40.0);
  ASSERT_TRUE(mean.ok());
  double lo, hi;
  cv::minMaxLoc(*mean, &lo, &hi, nullptr, nullptr, mask & (z == z));
  EXPECT_NEAR(lo, 7.25, 1e-5);
  EXPECT_NEAR(hi, 7.25, 1e-5);
  EXPECT_TRUE(std::isnan(mean->at<float>(0, 0)));  // outside the mask
  EXPECT_EQ(GaussianMeanSurface(z, mask, kPx, 0.0).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
