// Line profiles: exact heights along a tilted plane (bilinear sampling is exact on planes),
// band averaging across a step, missing depth, the band's noise reduction under the box
// correlation model, and validation naming the field.
#include "core/metrology/line_profile.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

constexpr double kPx = 0.74;

TEST(LineProfileTest, PlaneProfileIsExactWithPositionsInMicrometres) {
  const cv::Size size(120, 80);
  const cv::Mat z = testing::SampleSurface(size, kPx, [](double x, double y) { return 200.0 + 0.1 * x - 0.05 * y; });
  LineProfileOptions o;
  o.start = {10.0, 20.0};
  o.end = {100.0, 60.0};  // diagonal, px
  auto p = ExtractLineProfile(z, kPx, o, nullptr);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  const double length_px = std::hypot(90.0, 40.0);
  EXPECT_NEAR(p->length_um, length_px * kPx, 1e-9);
  ASSERT_EQ(p->height_um.size(), size_t(std::floor(length_px)) + 1);
  for (size_t i = 0; i < p->height_um.size(); i += 7) {
    const double x = p->x_um[i], y = p->y_um[i];
    EXPECT_NEAR(p->position_um[i], double(i) * kPx, 1e-9);
    EXPECT_NEAR(p->height_um[i], 200.0 + 0.1 * x - 0.05 * y, 1e-4) << i;  // float depths
  }
  EXPECT_DOUBLE_EQ(p->coverage_percent(), 100.0);
  // The same line in um.
  LineProfileOptions um = o;
  um.unit = RoiUnit::kMicrometre;
  um.start = {10.0 * kPx, 20.0 * kPx};
  um.end = {100.0 * kPx, 60.0 * kPx};
  auto q = ExtractLineProfile(z, kPx, um, nullptr);
  ASSERT_TRUE(q.ok());
  EXPECT_NEAR(q->height_um.back(), p->height_um.back(), 1e-6);
}

TEST(LineProfileTest, BandAveragesAcrossAndGapsStayEmpty) {
  // A 2 um step at x = 60 px; profile along x at y = 40, band 9 px wide.
  const cv::Size size(120, 80);
  cv::Mat z = testing::SampleSurface(size, kPx, [](double x, double) { return x >= 60 * kPx ? 202.0 : 200.0; });
  z(cv::Rect(20, 30, 10, 20)).setTo(NAN);  // a hole across the whole band at x 20..29
  z(cv::Rect(90, 36, 10, 2)).setTo(NAN);   // a hole across two of the band's 9 cross samples
  LineProfileOptions o;
  o.start = {5.5, 40.0};
  o.end = {115.5, 40.0};
  o.width_px = 9;
  auto p = ExtractLineProfile(z, kPx, o, nullptr);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_NEAR(p->height_um[10], 200.0, 1e-5);  // x = 15.5: flat
  EXPECT_TRUE(std::isnan(p->height_um[20]));   // x = 25.5: no depth anywhere across
  EXPECT_EQ(p->cross_samples[20], 0);
  EXPECT_NEAR(p->height_um[100], 202.0, 1e-5);  // x = 105.5
  // x = 95.5: cross samples at y = 36, 37, 38 interpolate from rows 35..38, which touch the hole.
  EXPECT_EQ(p->cross_samples[90], 9 - 3);
  EXPECT_NEAR(p->height_um[90], 202.0, 1e-5);
  EXPECT_LT(p->coverage_percent(), 100.0);
}

TEST(LineProfileTest, BandReducesNoiseAsTheBoxModelPredicts) {
  // sigma 0.05 um, 7 px correlated; a band of 21 px across a horizontal line averages samples
  // whose correlation falls as 1 - k/7: variance factor (1/21^2) sum_ij max(0, 1 - |i-j|/7).
  const cv::Size size(400, 60);
  const cv::Mat z = 200.0f + testing::CorrelatedNoise(size, 0.05, 7, 8);
  DepthNoiseModel m;
  m.sigma_um = cv::Mat(size, CV_32FC1, cv::Scalar(0.05f));
  m.global_sigma_um = 0.05;
  m.correlation_px = 7;
  m.grid = *ZGrid::Create({0.0, 1000.0});
  m.linearity.bias_of_step = {0.0, 0.0};
  double factor = 0.0;
  for (int i = 0; i < 21; ++i)
    for (int j = 0; j < 21; ++j) factor += std::max(0.0, 1.0 - std::abs(i - j) / 7.0);
  factor /= 21.0 * 21.0;
  LineProfileOptions o;
  o.start = {10.5, 30.0};
  o.end = {389.5, 30.0};
  o.width_px = 21;
  o.spacing_px = 1.0;
  auto p = ExtractLineProfile(z, kPx, o, &m);
  ASSERT_TRUE(p.ok());
  EXPECT_NEAR(p->uncertainty_um[50], 0.05 * std::sqrt(factor), 1e-6);
  // The heights' actual scatter along the line (~54 independent stretches of 7 px): within 25 %.
  double s = 0, s2 = 0;
  for (double h : p->height_um) {
    s += h - 200.0;
    s2 += (h - 200.0) * (h - 200.0);
  }
  const double n = double(p->height_um.size()), sd = std::sqrt(s2 / n - (s / n) * (s / n));
  std::printf("band 21 px: predicted u %.4f um, scatter %.4f um\n", p->uncertainty_um[50], sd);
  EXPECT_NEAR(sd / p->uncertainty_um[50], 1.0, 0.25);
}

TEST(LineProfileTest, ValidationNamesTheField) {
  const cv::Mat z(50, 40, CV_32FC1, cv::Scalar(1.f));
  LineProfileOptions o;
  o.start = {1, 1};
  o.end = {45, 1};
  auto out = ExtractLineProfile(z, kPx, o, nullptr, "profiles[2]");
  EXPECT_EQ(out.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(out.status().message().find("profiles[2].end"), std::string::npos) << out.status().message();
  o.end = {1.5, 1};
  EXPECT_NE(ExtractLineProfile(z, kPx, o, nullptr, "p").status().message().find("shorter than one sample"),
            std::string::npos);
  o.end = {30, 30};
  o.width_px = 0.5;
  EXPECT_NE(ExtractLineProfile(z, kPx, o, nullptr, "p").status().message().find("p.width_px"), std::string::npos);
}

}  // namespace
}  // namespace inspection
