// Depth interpolation (thesis 3.1.4) on synthetic focus curves with known peaks, uniform and
// non-uniform z, and the confidence on analytic curves.
#include "core/sff/depth_interpolation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace inspection {
namespace {

std::vector<double> Gaussian(const std::vector<double>& z, double mu, double sigma, double height, double floor = 0) {
  std::vector<double> f;
  for (double v : z) f.push_back(floor + height * std::exp(-0.5 * (v - mu) * (v - mu) / (sigma * sigma)));
  return f;
}

TEST(DepthInterpolationTest, GaussianRecoversGaussianPeaksUniformSteps) {
  const double dz = 2.5;
  std::vector<double> z;
  for (int k = 0; k < 15; ++k) z.push_back(10.0 + k * dz);
  double worst = 0;
  for (double frac = -0.5; frac <= 0.5; frac += 0.05) {
    const double mu = 10.0 + 7 * dz + frac * dz;
    for (double sigma : {0.8 * dz, 2.0 * dz, 5.0 * dz}) {
      const auto f = Gaussian(z, mu, sigma, 1000.0);
      const FocusPeak p = InterpolateFocusCurve(DepthInterpolation::kGaussian, z, f);
      EXPECT_TRUE(p.interpolated);
      const int m = int(std::max_element(f.begin(), f.end()) - f.begin());
      EXPECT_EQ(GaussianPeakZ(z[m - 1], z[m], z[m + 1], f[m - 1], f[m], f[m + 1]), p.z_um);
      worst = std::max(worst, std::abs(p.z_um - mu) / dz);
      EXPECT_NEAR(p.sigma_um, sigma, 1e-6 * sigma);
      EXPECT_NEAR(p.height, 1000.0, 1e-6);  // eq. 3.34
    }
  }
  std::printf("[figures] gaussian fit on gaussian curves, uniform z: worst error %.2e step\n", worst);
  EXPECT_LT(worst, 0.01);
}

TEST(DepthInterpolationTest, GaussianMatchesThesisEquation332ForUniformSteps) {
  // Eq. 3.32 literally, for d_m-1, d_m, d_m+1 = 4, 5, 6 (dz = 1) and arbitrary positive F.
  const double d1 = 4, d2 = 5, d3 = 6, f1 = 30, f2 = 50, f3 = 45;
  const double l1 = std::log(f1), l2 = std::log(f2), l3 = std::log(f3);
  const double thesis =
      ((l2 - l3) * (d2 * d2 - d1 * d1) - (l2 - l1) * (d2 * d2 - d3 * d3)) / (2 * 1.0 * ((l2 - l1) + (l2 - l3)));
  const FocusPeak p = GaussianPeak(d1, d2, d3, f1, f2, f3);
  EXPECT_NEAR(p.z_um, thesis, 1e-12);
  // Eq. 3.33 for uniform steps: sigma^2 = dz^2 / ((l2 - l1) + (l2 - l3)).
  EXPECT_NEAR(p.sigma_um * p.sigma_um, 1.0 / ((l2 - l1) + (l2 - l3)), 1e-12);
}

TEST(DepthInterpolationTest, GaussianRecoversPeaksWithNonUniformAndDescendingSteps) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> step(0.5, 1.5), frac(0.0, 1.0);
  double worst = 0;
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<double> z{0.0};
    for (int k = 1; k < 12; ++k) z.push_back(z.back() + step(rng));
    const double mu = z[5] + frac(rng) * (z[6] - z[5]);
    auto f = Gaussian(z, mu, 1.7, 200.0);
    FocusPeak p = InterpolateFocusCurve(DepthInterpolation::kGaussian, z, f);
    const double local_step = z[6] - z[5];
    worst = std::max(worst, std::abs(p.z_um - mu) / local_step);
    // Same curve acquired top-down.
    std::reverse(z.begin(), z.end());
    std::reverse(f.begin(), f.end());
    p = InterpolateFocusCurve(DepthInterpolation::kGaussian, z, f);
    worst = std::max(worst, std::abs(p.z_um - mu) / local_step);
  }
  std::printf("[figures] gaussian fit, non-uniform/descending z: worst error %.2e step\n", worst);
  EXPECT_LT(worst, 0.01);
}

TEST(DepthInterpolationTest, GaussianFallsBackToTheMaximum) {
  // Non-positive samples (log undefined): the sampled maximum.
  FocusPeak p = GaussianPeak(1, 2, 3, 0.0, 5.0, 3.0);
  EXPECT_FALSE(p.interpolated);
  EXPECT_EQ(p.z_um, 2.0);
  // Flat over all three samples: no curvature.
  p = GaussianPeak(1, 2, 3, 5.0, 5.0, 5.0);
  EXPECT_FALSE(p.interpolated);
  EXPECT_EQ(p.z_um, 2.0);
  // Maximum on the first frame: no left neighbour.
  const std::vector<double> z{0, 1, 2, 3}, f{9, 5, 2, 1};
  p = InterpolateFocusCurve(DepthInterpolation::kGaussian, z, f);
  EXPECT_FALSE(p.interpolated);
  EXPECT_EQ(p.z_um, 0.0);
  // A tie with the left neighbour puts the peak halfway between them.
  p = GaussianPeak(1, 2, 3, 5.0, 5.0, 2.0);
  EXPECT_NEAR(p.z_um, 1.5, 1e-12);
}

// The focus curve of a gradient measure on a flat-spectrum texture under a blur of second moment
// sigma_b^2 = s0^2 + k^2 (z - z_f)^2: F = c / sigma_b^4 (core/sff/depth_interpolation.h).
std::vector<double> DefocusCurve(const std::vector<double>& z, double z_f, double s0, double k, double c) {
  std::vector<double> f;
  for (double v : z) {
    const double sb2 = s0 * s0 + k * k * (v - z_f) * (v - z_f);
    f.push_back(c / (sb2 * sb2));
  }
  return f;
}

TEST(DepthInterpolationTest, DefocusParabolaIsExactOnDefocusCurvesWhereTheGaussianIsNot) {
  // Non-uniform and descending z, in-focus blur 0.4..1.5 px, 0.3..1.2 px of blur per step.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> step(0.6, 1.4), frac(0.0, 1.0), s0(0.4, 1.5), k(0.3, 1.2);
  double worst_parabola = 0, worst_gaussian = 0;
  for (int trial = 0; trial < 300; ++trial) {
    std::vector<double> z{0.0};
    for (int i = 1; i < 12; ++i) z.push_back(z.back() + step(rng));
    const double z_f = z[5] + frac(rng) * (z[6] - z[5]);
    const double local_step = z[6] - z[5];
    const double sigma0 = s0(rng), blur = k(rng);
    for (int direction = 0; direction < 2; ++direction) {
      const auto f = DefocusCurve(z, z_f, sigma0, blur, 5e4);
      const FocusPeak p = InterpolateFocusCurve(DepthInterpolation::kDefocusParabola, z, f);
      worst_parabola = std::max(worst_parabola, std::abs(p.z_um - z_f) / local_step);
      const FocusPeak g = InterpolateFocusCurve(DepthInterpolation::kGaussian, z, f);
      worst_gaussian = std::max(worst_gaussian, std::abs(g.z_um - z_f) / local_step);
      const int m = int(std::max_element(f.begin(), f.end()) - f.begin());
      EXPECT_EQ(DefocusParabolaPeakZ(z[m - 1], z[m], z[m + 1], f[m - 1], f[m], f[m + 1]), p.z_um);
      std::reverse(z.begin(), z.end());
    }
  }
  std::printf("[figures] defocus curves, non-uniform/descending z: worst error parabola %.2e, gaussian %.2e step\n",
              worst_parabola, worst_gaussian);
  EXPECT_LT(worst_parabola, 1e-9);
  EXPECT_GT(worst_gaussian, 0.03);  // the sub-step error the parabola removes
}

TEST(DepthInterpolationTest, DefocusParabolaMatchesTheUniformStepVertexAndFallsBack) {
  // Uniform steps: the textbook vertex dz (g1 - g3) / (2 (g1 - 2 g2 + g3)) of g = F^-1/2.
  const double f1 = 30, f2 = 50, f3 = 45;
  const double g1 = 1 / std::sqrt(f1), g2 = 1 / std::sqrt(f2), g3 = 1 / std::sqrt(f3);
  EXPECT_NEAR(DefocusParabolaPeakZ(4, 5, 6, f1, f2, f3), 5 + (g1 - g3) / (2 * (g1 - 2 * g2 + g3)), 1e-12);
  EXPECT_EQ(DefocusParabolaPeakZ(1, 2, 3, 0.0, 5.0, 3.0), 2.0);           // non-positive sample
  EXPECT_EQ(DefocusParabolaPeakZ(1, 2, 3, 5.0, 5.0, 5.0), 2.0);           // flat
  EXPECT_NEAR(DefocusParabolaPeakZ(1, 2, 3, 5.0, 5.0, 2.0), 1.5, 1e-12);  // tie: halfway
  const std::vector<double> z{0, 1, 2, 3}, f{9, 5, 2, 1};                 // maximum on the first frame
  const FocusPeak p = InterpolateFocusCurve(DepthInterpolation::kDefocusParabola, z, f);
  EXPECT_FALSE(p.interpolated);
  EXPECT_EQ(p.z_um, 0.0);
}

TEST(DepthInterpolationTest, MaximumReturnsTheSampledPeak) {
  const std::vector<double> z{0, 0.5, 1.7, 2.0, 3.1}, f{1, 4, 9, 8, 2};
  const FocusPeak p = InterpolateFocusCurve(DepthInterpolation::kMaximum, z, f);
  EXPECT_EQ(p.z_um, 1.7);
  EXPECT_EQ(p.height, 9.0);
}

std::vector<double> Triangle(const std::vector<double>& z, double mu, double slope, double height) {
  std::vector<double> f;
  for (double v : z) f.push_back(height - slope * std::abs(v - mu));
  return f;
}

TEST(DepthInterpolationTest, LineFitByHand) {
  // Samples at z = 0..6, triangle peak at 3 (on a sample): both lines are exact and intersect
  // at 3; d_i = d_max, so eq. 3.29 gives d_max exactly.
  std::vector<double> z{0, 1, 2, 3, 4, 5, 6};
  FocusPeak p = InterpolateFocusCurve(DepthInterpolation::kLineFit, z, Triangle(z, 3.0, 10, 100), 2);
  EXPECT_NEAR(p.z_um, 3.0, 1e-12);
  // Worked example, j = 1: F = 2, 6, 5 at z = 1, 2, 3 (max at 2). DS1 line through (1,2),(2,6):
  // F = 4z - 2; DS2 through (2,6),(3,5): F = -z + 8. d_i = 2. d_c = closest other sample = 1 or
  // 3 (both 1 away; the first, 1). d1 = 1, d2 = 0 -> w1 = 0, w2 = 1: 2.
  z = {1, 2, 3};
  p = InterpolateFocusCurve(DepthInterpolation::kLineFit, z, {2, 6, 5}, 1);
  EXPECT_NEAR(p.z_um, 2.0, 1e-12);
  // F = 2, 6, 8, 3 at z = 1..4 (max at 3), j = 1: DS1 (2,6),(3,8): F = 2z + 2; DS2 (3,8),(4,3):
  // F = -5z + 23. d_i = 21/7 = 3. Result 3.
  z = {1, 2, 3, 4};
  p = InterpolateFocusCurve(DepthInterpolation::kLineFit, z, {2, 6, 8, 3}, 1);
  EXPECT_NEAR(p.z_um, 3.0, 1e-12);
  // F = 1, 4, 7, 6, 1 at z = 0..4, j = 2: DS1 (0,1),(1,4),(2,7): F = 3z + 1; DS2 (2,7),(3,6),(4,1):
  // slope -3, intercept 7 + 3*2... least squares: mean z 3, mean F 14/3; slope = sum((z-3)(F-14/3))
  // / 2 = ((-1)(7/3) + (1)(-11/3)) / 2 = -3; intercept = 14/3 + 9 = 41/3. d_i: 3z + 1 = -3z + 41/3
  // -> z = (38/3)/6 = 19/9 = 2.111. d_c = 2? No: d_max = 2 is excluded, closest other is 3 (0.889
  // away) vs 1 (1.111): d_c = 3. d1 = 0.889, d2 = 0.111: z = (0.111*3 + 0.889*2) / 1 = 2.111.
  z = {0, 1, 2, 3, 4};
  p = InterpolateFocusCurve(DepthInterpolation::kLineFit, z, {1, 4, 7, 6, 1}, 2);
  EXPECT_NEAR(p.z_um, 19.0 / 9.0, 1e-12);
  EXPECT_TRUE(p.interpolated);
}

TEST(DepthInterpolationTest, LineFitOnTriangularPeaks) {
  std::vector<double> z;
  for (int k = 0; k < 11; ++k) z.push_back(k * 1.0);
  double worst_j1 = 0, worst_j2 = 0, rms_j2 = 0, rms_max = 0;
  int n = 0;
  for (double frac = -0.45; frac <= 0.451; frac += 0.05) {
    const double mu = 5.0 + frac;
    const auto f = Triangle(z, mu, 12, 100);
    const double zmax = InterpolateFocusCurve(DepthInterpolation::kMaximum, z, f).z_um;
    // j = 1: both lines pass through F_max itself, so they meet at d_max: the maximum method.
    worst_j1 = std::max(worst_j1, std::abs(InterpolateFocusCurve(DepthInterpolation::kLineFit, z, f, 1).z_um - zmax));
    const double e2 = InterpolateFocusCurve(DepthInterpolation::kLineFit, z, f, 2).z_um - mu;
    worst_j2 = std::max(worst_j2, std::abs(e2));
    rms_j2 += e2 * e2;
    rms_max += (zmax - mu) * (zmax - mu);
    ++n;
  }
  rms_j2 = std::sqrt(rms_j2 / n);
  rms_max = std::sqrt(rms_max / n);
  std::printf("[figures] triangle peaks: line fit j=2 RMS %.3f (worst %.3f) step, maximum RMS %.3f step\n", rms_j2,
              worst_j2, rms_max);
  EXPECT_EQ(worst_j1, 0.0);
  EXPECT_LT(rms_j2, rms_max);
}

TEST(DepthInterpolationTest, ConfidenceOnAnalyticCurves) {
  // A smooth peak: steps away from the peak are tiny compared with its prominence.
  std::vector<double> z;
  for (int k = 0; k < 30; ++k) z.push_back(k);
  auto summarise = [&](const std::vector<double>& f) {
    const int m = int(std::max_element(f.begin(), f.end()) - f.begin());
    FocusCurveSummary s;
    s.peak = f[size_t(m)];
    double sum = 0, sq = 0;
    int terms = 0;
    for (size_t k = 0; k < f.size(); ++k) {
      sum += f[k];
      const int kk = int(k);
      if (kk >= 2 && m != kk && m != kk - 1 && m != kk - 2) {
        const double t = f[k] - 2 * f[k - 1] + f[k - 2];
        sq += t * t;
        ++terms;
      }
    }
    s.mean = sum / f.size();
    s.curvature_sq_sum = sq;
    s.curvature_count = terms;
    s.peak_at_end = m == 0 || m == int(f.size()) - 1;
    s.flank_terms = FlankTermCount(m, int(f.size()));
    return s;
  };
  const float c_peak = FocusConfidence(summarise(Gaussian(z, 14.3, 2.0, 100.0, 5.0)));
  EXPECT_GT(c_peak, 0.7);
  // Noise only: the maximum of 30 samples is ~2 sigma above the mean -> rejected.
  std::mt19937 rng(2);
  std::normal_distribution<double> n(50.0, 3.0);
  int accepted = 0;
  for (int t = 0; t < 200; ++t) {
    std::vector<double> f;
    for (int k = 0; k < 30; ++k) f.push_back(n(rng));
    accepted += FocusConfidence(summarise(f)) >= 0.2f;
  }
  EXPECT_LE(accepted, 2);
  // Hand value: peak 10, mean 4, second differences 2 and -1 -> sigma = sqrt(5 / (6 * 2)) =
  // 0.6455, s = 6 / 0.6455 = 9.295, c = 1 - 4 / 9.295 = 0.5697.
  FocusCurveSummary s;
  s.peak = 10;
  s.mean = 4;
  s.curvature_sq_sum = 5;
  s.curvature_count = 2;
  EXPECT_NEAR(FocusConfidence(s), 1.0 - 4.0 / (6.0 / std::sqrt(5.0 / 12.0)), 1e-6);
  s.peak_at_end = true;
  EXPECT_NEAR(FocusConfidence(s), 0.5 * (1.0 - 4.0 / (6.0 / std::sqrt(5.0 / 12.0))), 1e-6);
  // Constant curve: no prominence, confidence 0.
  EXPECT_EQ(FocusConfidence(summarise(std::vector<double>(10, 7.0))), 0.f);
}

// A 7-frame stack centred on its peak leaves only the two second differences that hold the
// peak's flanks (t_2 and t_6). By hand for the noiseless curve 0.05, 0.12, 0.45, 1, 0.45, 0.12,
// 0.05: t_2 = t_6 = 0.26, mean 0.3200. Counted plainly: sigma = sqrt(2 * 0.26^2 / (6 * 2)) =
// 0.1061, s = 0.68 / 0.1061 = 6.41 and c = 0.376 < 0.4: rejected although perfect. Each flank
// term counted as 3: sigma = sqrt(0.1352 / (6 * 6)) = 0.0613, s = 11.1, c = 0.640.
TEST(DepthInterpolationTest, ShortStackCentredOnItsPeakKeepsItsConfidence) {
  EXPECT_EQ(FlankTermCount(3, 7), 2);
  EXPECT_EQ(FlankTermCount(3, 8), 2);  // t_7 (frames 5..7) is counted there too, not a flank term
  EXPECT_EQ(FlankTermCount(2, 6), 1);
  EXPECT_EQ(FlankTermCount(0, 9), 1);
  EXPECT_EQ(FlankTermCount(1, 4), 0);
  FocusCurveSummary s;
  s.peak = 1.0;
  s.mean = (0.05 + 0.12 + 0.45 + 1.0 + 0.45 + 0.12 + 0.05) / 7.0;
  s.curvature_sq_sum = 2 * 0.26 * 0.26;
  s.curvature_count = 2;
  EXPECT_NEAR(FocusConfidence(s), 1.0 - 4.0 * std::sqrt(s.curvature_sq_sum / 12.0) / (1.0 - s.mean), 1e-6);
  EXPECT_NEAR(FocusConfidence(s), 0.376, 0.001);
  s.flank_terms = 2;
  EXPECT_NEAR(FocusConfidence(s), 1.0 - 4.0 * std::sqrt(s.curvature_sq_sum / 36.0) / (1.0 - s.mean), 1e-6);
  EXPECT_NEAR(FocusConfidence(s), 0.640, 0.001);
  // A 9-frame curve with the peak in the middle: two flank terms and two far ones (weight 8).
  s.curvature_sq_sum = 2 * 0.26 * 0.26 + 2 * 0.01 * 0.01;
  s.curvature_count = 4;
  EXPECT_NEAR(FocusConfidence(s), 1.0 - 4.0 * std::sqrt(s.curvature_sq_sum / 48.0) / (1.0 - s.mean), 1e-6);
}

}  // namespace
}  // namespace inspection
