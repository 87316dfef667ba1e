// The height-dependent systematic term of Ssk and Sku (core/metrology/measurement_uncertainty.h): the
// window flattening against its closed form on a cosine, the sensitivity signs against finite
// differences, the bound's parts, and the term covering an error of that size whose shape the
// Monte Carlo does not know (valleys raised, peaks left: the SFF's pattern on a curved surface).
#include <gtest/gtest.h>

#include <cmath>
#include <map>

#include "core/metrology/areal_parameters.h"
#include "core/metrology/measurement.h"
#include "core/metrology/measurement_uncertainty.h"
#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

using testing::kPi;

constexpr double kPx = 0.74;

DepthNoiseOptions Options(int window = 7) {
  DepthNoiseOptions o;
  o.window_px = window;
  for (int k = 0; k < 40; ++k) o.z_positions_um.push_back(150.0 + 5.0 * k);
  o.linearity.bias_of_step = {0.0, 0.0};
  o.linearity.characterised_step_um = 5.0;
  return o;
}

TEST(ShapeParameterUncertaintyTest, WindowFlatteningMatchesTheSecondOrderMeanOfTheWindow) {
  // z = A cos(2 pi x / L) along x (in pixels). The 4-neighbour Laplacian of the Gaussian-smoothed
  // cosine is -A k^2 (1 - k^2 / 12) exp(-k^2 sigma^2 / 2) cos, k = 2 pi / L, to O(k^6); e is
  // (s2 / 2) times that, s2 = (w^2 - 1) / 12 + 1/2.
  const double amplitude = 2.0, period_px = 64.0;
  const int window = 7;
  const cv::Mat z = testing::SampleSurface(cv::Size(256, 64), 1.0, [&](double x, double) {
    return 210.0 + amplitude * std::cos(2 * kPi * (x - 0.5) / period_px);
  });
  const cv::Mat e = WindowAveragingError(z, window);
  const double k = 2 * kPi / period_px, sigma = 0.5 * window;
  const double s2 = (window * window - 1.0) / 12.0 + 0.5;
  const double gain = -0.5 * s2 * k * k * (1.0 - k * k / 12.0) * std::exp(-0.5 * k * k * sigma * sigma);
  for (int col : {64, 80, 96, 112, 128, 150}) {
    const double expected = gain * amplitude * std::cos(k * col);
    EXPECT_NEAR(e.at<float>(32, col), expected, 5e-3 * amplitude * std::abs(gain)) << "column " << col;
  }
  // A peak is flattened by ~0.04 um at this period and window: the size seen on the simulated rig.
  EXPECT_NEAR(e.at<float>(32, 128), -0.040, 0.004);
  // A plane has none (away from the image edge, which the smoothing reflects).
  const cv::Mat plane =
      testing::SampleSurface(cv::Size(64, 64), kPx, [](double x, double y) { return 5 + 0.1 * x - 0.2 * y; });
  double lo, hi;
  cv::minMaxLoc(WindowAveragingError(plane, window)(cv::Rect(16, 16, 32, 32)), &lo, &hi);
  EXPECT_LT(std::max(hi, -lo), 1e-4);
  // A hole gets no estimate, and the normalised smoothing keeps its neighbours' small.
  cv::Mat holed = plane.clone();
  holed.at<float>(30, 30) = std::nanf("");
  const cv::Mat eh = WindowAveragingError(holed, window);
  EXPECT_EQ(eh.at<float>(30, 30), 0.0f);
  cv::minMaxLoc(eh(cv::Rect(12, 12, 40, 40)), &lo, &hi);
  EXPECT_LT(std::max(hi, -lo), 0.01);
}

TEST(ShapeParameterUncertaintyTest, SensitivitySignsAgreeWithFiniteDifferences) {
  cv::Mat surface = testing::SampleSurface(cv::Size(40, 30), 1.0, [](double x, double y) {
    return 0.8 * std::cos(x / 5.0) + 0.3 * std::sin(y / 3.0) + 0.2 * std::cos(x * y / 40.0);
  });
  surface.at<float>(3, 4) = std::nanf("");
  for (const HeightParameter p : {HeightParameter::kSsk, HeightParameter::kSku}) {
    auto sign = ShapeParameterSensitivitySign(surface, p);
    ASSERT_TRUE(sign.ok());
    EXPECT_EQ(sign->at<float>(3, 4), 0.0f);
    // The moments of the levelled surface the sign is taken on (no further levelling here).
    const auto value = [&](const cv::Mat& s) {
      double n = 0, m1 = 0, m2 = 0, m3 = 0, m4 = 0;
      for (float v : cv::Mat_<float>(s)) {
        if (std::isfinite(v)) n += 1, m1 += v;
      }
      m1 /= n;
      for (float v : cv::Mat_<float>(s)) {
        if (!std::isfinite(v)) continue;
        const double d = v - m1;
        m2 += d * d / n, m3 += d * d * d / n, m4 += d * d * d * d / n;
      }
      return p == HeightParameter::kSsk ? m3 / std::pow(m2, 1.5) : m4 / (m2 * m2);
    };
    const double base = value(surface);
    int checked = 0, agree = 0;
    for (int r = 0; r < surface.rows; r += 3) {
      for (int c = 0; c < surface.cols; c += 3) {
        if (!std::isfinite(surface.at<float>(r, c))) continue;
        cv::Mat bumped = surface.clone();
        bumped.at<float>(r, c) += 1e-3f;
        const double d = value(bumped) - base;
        if (std::abs(d) < 1e-7) continue;  // at a sign change of the derivative
        ++checked;
        agree += (d > 0) == (sign->at<float>(r, c) > 0);
      }
    }
    EXPECT_GT(checked, 100);
    EXPECT_EQ(agree, checked) << HeightParameterName(p);
  }
  EXPECT_FALSE(ShapeParameterSensitivitySign(surface, HeightParameter::kSa).ok());
}

TEST(ShapeParameterUncertaintyTest, AnErrorPeriodicInTheGridMovesSskFarLessThanAnUnconstrainedOne) {
  // A 6 um cosine on a 2 um z grid spans six steps: an error that is a function of the
  // fractional grid position (peak locking) takes the same sign a step apart in height, so it
  // cannot follow sign(d Ssk / d z) over the whole surface.
  const cv::Size size(256, 32);
  const cv::Mat depth = testing::SampleSurface(
      size, 1.0, [](double x, double) { return 200.0 + 6.0 * std::cos(2 * kPi * (x - 0.5) / 128.0); });
  const cv::Mat surface = depth - 200.0;
  DepthNoiseOptions o = Options();
  o.z_positions_um.clear();
  for (int k = 0; k < 40; ++k) o.z_positions_um.push_back(170.0 + 2.0 * k);
  auto model = EstimateDepthNoise(depth + testing::CorrelatedNoise(size, 0.01, 7, 9), cv::Mat(), o);
  ASSERT_TRUE(model.ok()) << model.status().ToString();
  auto periodic = PeriodicWorstCaseSign(depth, surface, HeightParameter::kSsk, *model, 20);
  auto free = ShapeParameterSensitivitySign(surface, HeightParameter::kSsk);
  ASSERT_TRUE(periodic.ok() && free.ok());
  // One sign per bin of the fractional position.
  std::map<int, float> sign_of_bin;
  int mismatched = 0;
  for (int col = 0; col < size.width; ++col) {
    const int bin = std::min(19, int(model->grid.Locate(depth.at<float>(0, col)).fraction * 20));
    const float s = periodic->at<float>(0, col);
    auto [it, inserted] = sign_of_bin.emplace(bin, s);
    mismatched += !inserted && it->second != s;
  }
  EXPECT_EQ(mismatched, 0);
  const cv::Mat mask(size, CV_8UC1, cv::Scalar(255));
  auto ssk = [&](const cv::Mat& z) { return ComputeHeightParameters(z, mask)->Ssk; };
  const double delta = 0.05, base = ssk(surface);
  const double moved_periodic = std::abs(ssk(surface + *periodic * delta) - base);
  const double moved_free = std::abs(ssk(surface + *free * delta) - base);
  std::printf("Ssk moved by %.5f (periodic worst case) against %.5f (unconstrained)\n", moved_periodic, moved_free);
  EXPECT_GT(moved_free, 0.0);
  EXPECT_LT(moved_periodic, 0.5 * moved_free);
  EXPECT_FALSE(PeriodicWorstCaseSign(depth, surface, HeightParameter::kSq, *model, 20).ok());
}

TEST(ShapeParameterUncertaintyTest, BoundIsTheLinearityHalfRangePlusTheFlattening) {
  DepthNoiseOptions o = Options();
  o.linearity.bias_of_step = {0.0, 0.02, 0.0, -0.02};  // +-0.1 um at 5 um steps
  const cv::Size size(256, 64);
  const cv::Mat mask(size, CV_8UC1, cv::Scalar(255));
  // A flat region at one height: the table is a common offset there, and nothing is curved.
  cv::Mat flat(size, CV_32F, cv::Scalar(201.0));
  flat += testing::CorrelatedNoise(size, 0.002, 7, 3);
  auto mf = EstimateDepthNoise(flat, mask, o);
  ASSERT_TRUE(mf.ok());
  EXPECT_LT(HeightDependentErrorBoundUm(flat, mask, *mf, LinearityRangeUm(flat, mask, *mf)), 0.005);
  // A 2 um cosine spans most of a step: half the table's range (0.1 um) plus ~0.04 um flattening.
  const cv::Mat cosine = testing::SampleSurface(
      size, 1.0, [](double x, double) { return 210.0 + 2.0 * std::cos(2 * kPi * (x - 0.5) / 64.0); });
  auto mc = EstimateDepthNoise(cosine, mask, o);
  ASSERT_TRUE(mc.ok());
  const double delta = HeightDependentErrorBoundUm(cosine, mask, *mc, LinearityRangeUm(cosine, mask, *mc));
  EXPECT_NEAR(delta, 0.1 + 0.040, 0.01);
}

TEST(ShapeParameterUncertaintyTest, SsksUncertaintyCoversAHeightDependentErrorItsMonteCarloDoesNotKnow) {
  // Truth: a cosine (Ssk 0, Sku 1.5). "Measured": the same with its valleys' bottom band raised
  // by 0.04 um and the rest left, plus noise. The cosine (208..212 um) spans less than one 5 um
  // step, so that error is a function of the fractional grid position too (periodic in the
  // grid, PeriodicWorstCaseSign). The model's z-linearity table, transferred from a 10 um
  // characterisation (its shape at 5 um steps unknown: the whole half-range is a worst case), is
  // of another shape, so the Monte Carlo cannot know the error; its size is within the bound
  // (half the table's range, 0.01 um, plus the flattening's estimated systematic).
  const cv::Size size(256, 96);
  const auto truth = [](double x, double) { return 210.0 + 2.0 * std::cos(2 * kPi * x / (64 * kPx)); };
  cv::Mat measured = testing::SampleSurface(size, kPx, [&](double x, double y) {
    const double t = truth(x, y) - 210.0;
    return 210.0 + t + (t < -1.5 ? 0.04 : 0.0);
  });
  measured += testing::CorrelatedNoise(size, 0.01, 7, 5);
  MeasurementContext ctx;
  ctx.depth_um = measured;
  ctx.pixel_size_um = kPx;
  ctx.noise = Options();
  ctx.noise.linearity.bias_of_step = {0.0, 0.001, 0.0, -0.001};  // +-0.01 um at 10 um
  ctx.noise.linearity.characterised_step_um = 10.0;
  MeasurementSpec spec;
  spec.roi = RegionOfInterest::Rectangle(32, 8, 192, 80);  // three whole periods
  MeasurementContext truth_ctx = ctx;
  truth_ctx.depth_um = testing::SampleSurface(size, kPx, truth);
  truth_ctx.with_uncertainty = false;
  for (const MeasurementKind kind : {MeasurementKind::kSsk, MeasurementKind::kSku}) {
    spec.kind = kind;
    auto m = Measure(spec, ctx);
    auto t = Measure(spec, truth_ctx);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    ASSERT_TRUE(t.ok());
    const UncertaintyBudget& b = m->uncertainty;
    const double dev = m->value - t->value;
    const double without = std::sqrt(std::max(0.0, std::pow(b.standard_uncertainty, 2) - std::pow(b.height_dependent, 2)));
    std::printf("%s: value %.4f truth %.4f dev %+.4f; u %.4f (Monte Carlo %.4f, height-dependent %.4f)\n",
                MeasurementKindName(kind), m->value, t->value, dev, b.standard_uncertainty, without, b.height_dependent);
    ASSERT_TRUE(std::isfinite(b.height_dependent));
    EXPECT_LE(std::abs(dev), 2.0 * b.standard_uncertainty) << MeasurementKindName(kind);
    if (kind == MeasurementKind::kSsk) {
      // The Monte Carlo alone (the table's shape, random phase, noise) does not cover it.
      EXPECT_GT(std::abs(dev), 2.0 * without);
      // A worst case, but still informative against Ssk tolerances of a few tenths.
      EXPECT_LT(2.0 * b.standard_uncertainty, 0.1);
    }
  }
}

}  // namespace
}  // namespace inspection
