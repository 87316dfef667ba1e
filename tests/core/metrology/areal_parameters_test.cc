// ISO 25178-2 height parameters against a sinusoid (Sa = 2A/pi, Sq = A/sqrt 2, Sp = Sv = A,
// Sz = 2A, Ssk = 0, Sku = 1.5) on a tilted base (form removal), with noise and holes, and the
// S-/L-filter pipeline separating roughness from waviness.
#include "core/metrology/areal_parameters.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/metrology/areal_filter.h"
#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

using testing::kPi;

constexpr double kPx = 0.74;
constexpr double kA = 1.5;  // um

// A cos(2 pi (x - xc) / lambda) on a tilted plane over 8 whole periods of 50 px, symmetric about
// the region's centre (so the least-squares plane takes exactly the tilt and nothing of the cosine).
cv::Mat TiltedCosine(cv::Size size) {
  const double lambda = 50 * kPx, xc = 0.5 * size.width * kPx;
  return testing::SampleSurface(size, kPx, [&](double x, double y) {
    return 250.0 + 0.03 * x - 0.01 * y + kA * std::cos(2.0 * kPi * (x - xc) / lambda);
  });
}

TEST(ArealParametersTest, SinusoidHasItsAnalyticParameters) {
  const cv::Size size(400, 60);
  const cv::Mat z = TiltedCosine(size);
  auto e = EvaluateArealSurface(z, cv::Mat(size, CV_8UC1, cv::Scalar(255)), kPx, ArealOptions{});
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  const ArealHeightParameters& p = e->parameters;
  std::printf("sinusoid A = %.2f um: Sa %.6f (%.6f) Sq %.6f (%.6f) Sp %.6f Sv %.6f Sz %.6f Ssk %.2e Sku %.6f\n", kA,
              p.Sa_um, 2 * kA / kPi, p.Sq_um, kA / std::sqrt(2.0), p.Sp_um, p.Sv_um, p.Sz_um, p.Ssk, p.Sku);
  // 50 samples per period: sums of cos^2, cos^3, cos^4 over whole periods are exact, so Sq, Ssk
  // and Sku are exact to float rounding of 250 um depths (~2e-5 um). Sa's |cos| sum differs from
  // 2/pi by (pi/50)^2/6 ~ 7e-4 relative; the samples sit half a pixel off the crests, so Sp, Sv
  // are A cos(pi/50) (0.2 % low).
  EXPECT_NEAR(p.Sq_um, kA / std::sqrt(2.0), 1e-4);
  EXPECT_NEAR(p.Ssk, 0.0, 1e-4);
  EXPECT_NEAR(p.Sku, 1.5, 1e-4);
  EXPECT_NEAR(p.Sa_um, 2.0 * kA / kPi, 1e-3 * kA);
  EXPECT_NEAR(p.Sp_um, kA, 3e-3 * kA);
  EXPECT_NEAR(p.Sv_um, kA, 3e-3 * kA);
  EXPECT_NEAR(p.Sz_um, 2.0 * kA, 6e-3 * kA);
  EXPECT_NEAR(e->form.parameters[1], 0.03, 1e-6);  // the tilt went to the form, not the roughness
}

TEST(ArealParametersTest, NoiseAndHolesMoveTheParametersByTheNoiseOnly) {
  const cv::Size size(400, 80);
  cv::Mat z = TiltedCosine(size);
  const double sigma = 0.02;
  z += testing::CorrelatedNoise(size, sigma, 7, 11);
  testing::PunchHoles(z, 30, 5, 12);
  auto e = EvaluateArealSurface(z, cv::Mat(size, CV_8UC1, cv::Scalar(255)), kPx, ArealOptions{});
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  const ArealHeightParameters& p = e->parameters;
  std::printf("noise 0.02 um + 30 holes: Sa %.5f Sq %.5f Sp %.5f Sv %.5f Ssk %.4f Sku %.4f\n", p.Sa_um, p.Sq_um,
              p.Sp_um, p.Sv_um, p.Ssk, p.Sku);
  // Independent noise adds in quadrature: Sq^2 = A^2 / 2 + sigma^2, a shift of 1.3e-4 um. The
  // holes (30 discs of ~80 px, 7 % of the pixels, at random phases of the 50 px period) sample
  // crests and troughs unequally: that moves mean z^k by ~sqrt(30) * 80 px * ~0.4 A^k / 32000 px,
  // i.e. Sa, Sq by ~3e-3 relative and Ssk, Sku by ~0.02 (one standard deviation); the bounds are
  // 2-3 of those.
  EXPECT_NEAR(p.Sq_um, std::sqrt(kA * kA / 2 + sigma * sigma), 8e-3 * kA);
  EXPECT_NEAR(p.Sa_um, 2.0 * kA / kPi, 8e-3 * kA);
  EXPECT_NEAR(p.Ssk, 0.0, 0.05);
  EXPECT_NEAR(p.Sku, 1.5, 0.05);
  // Sp, Sv: the largest noise value among the ~1000 correlation areas along the crests (troughs),
  // where the cosine is within a few sigma of its extreme: expected ~3-4 sigma; bound 6 sigma.
  EXPECT_NEAR(p.Sp_um, kA, 6 * sigma + 3e-3 * kA);
  EXPECT_NEAR(p.Sv_um, kA, 6 * sigma + 3e-3 * kA);
}

TEST(ArealParametersTest, LFilterRemovesWavinessAndKeepsRoughness) {
  // Roughness 0.5 um at 10 um wavelength on waviness 3 um at 200 um; lc = 40 um passes 0.973 of
  // the waviness into the mean surface (2.7 % leaks into the roughness) and keeps 1 - 1.5e-5 of
  // the roughness. Parameters over the region more than lc from its border.
  const cv::Size size(700, 60);
  const cv::Mat z = testing::SampleSurface(size, kPx, [](double x, double) {
    return 220.0 + 3.0 * std::cos(2 * kPi * x / 200.0) + 0.5 * std::cos(2 * kPi * x / 10.0);
  });
  ArealOptions o;
  o.l_filter_cutoff_um = 40.0;
  const cv::Mat all(size, CV_8UC1, cv::Scalar(255));
  auto e = EvaluateArealSurface(z, all, kPx, o);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  cv::Mat interior(size, CV_8UC1, cv::Scalar(0));
  const int margin = int(40.0 / kPx) + 1;
  interior(cv::Rect(margin, 0, size.width - 2 * margin, size.height)).setTo(255);
  auto p = ComputeHeightParameters(e->surface_um, interior);
  ASSERT_TRUE(p.ok());
  const double leak = 3.0 * (1.0 - GaussianMeanTransmission(40.0, 200.0));
  std::printf("L-filter 40 um: Sq %.4f um (roughness alone %.4f, with waviness leak %.4f)\n", p->Sq_um,
              0.5 / std::sqrt(2.0), std::sqrt(0.125 + leak * leak / 2));
  EXPECT_NEAR(p->Sq_um, std::sqrt(0.125 + leak * leak / 2), 0.005);
  // Without the L-filter the waviness dominates.
  auto raw = EvaluateArealSurface(z, all, kPx, ArealOptions{});
  ASSERT_TRUE(raw.ok());
  EXPECT_GT(raw->parameters.Sq_um, 1.5);
  // An S-filter at 30 um removes the 10 um roughness instead (it keeps exp(-9 ln 2) = 0.2 % of it).
  ArealOptions s;
  s.s_filter_cutoff_um = 30.0;
  auto sf = EvaluateArealSurface(z, all, kPx, s);
  ASSERT_TRUE(sf.ok());
  auto ps = ComputeHeightParameters(sf->surface_um, interior);
  ASSERT_TRUE(ps.ok());
  EXPECT_LT(std::abs(ps->Sq_um - raw->parameters.Sq_um), 0.15);  // the waviness remains
  EXPECT_LT(ps->Sku, 1.6);                                       // a pure cosine (Sku 1.5), the fine roughness gone
}

TEST(ArealParametersTest, OptionsAndNamesAreValidated) {
  ArealOptions o;
  o.s_filter_cutoff_um = 8.0;
  o.l_filter_cutoff_um = 2.5;
  const Status s = o.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("l_filter_cutoff_um"), std::string::npos);
  o.l_filter_cutoff_um = -1;
  EXPECT_EQ(o.Validate().code(), StatusCode::kInvalidArgument);
  for (const char* name : {"Sa", "Sq", "Sp", "Sv", "Sz", "Ssk", "Sku"}) {
    auto p = ParseHeightParameter(name);
    ASSERT_TRUE(p.ok());
    EXPECT_STREQ(HeightParameterName(*p), name);
  }
  EXPECT_EQ(ParseHeightParameter("Sdq").status().code(), StatusCode::kInvalidArgument);
  const cv::Mat empty_mask(10, 10, CV_8UC1, cv::Scalar(0));
  EXPECT_EQ(ComputeHeightParameters(cv::Mat(10, 10, CV_32FC1, cv::Scalar(1.f)), empty_mask).status().code(),
            StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace inspection
