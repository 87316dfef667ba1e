// The recipe-facing entry point: parameter names, spec validation naming the field, and a
// synthetic part (roughness region, step, flat land, with noise and holes) measured through
// MeasureAll: values near their analytic truths, within their uncertainties, with coverage, and
// verdicts from Judge.
#include "core/metrology/measurement.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/metrology/verdict.h"
#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

using testing::kPi;

constexpr double kPx = 0.74;

TEST(MeasurementTest, NamesRoundTripAndUnknownNamesAreListed) {
  for (MeasurementKind k : AllMeasurementKinds()) {
    auto p = ParseMeasurementKind(MeasurementKindName(k));
    ASSERT_TRUE(p.ok()) << MeasurementKindName(k);
    EXPECT_EQ(*p, k);
  }
  auto bad = ParseMeasurementKind("Sdr");
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("'Sdr'"), std::string::npos);
  EXPECT_NE(bad.status().message().find("step_height"), std::string::npos);
}

TEST(MeasurementTest, SpecValidationNamesTheField) {
  const cv::Size size(100, 80);
  MeasurementSpec step;
  step.kind = MeasurementKind::kStepHeight;
  step.roi = RegionOfInterest::Rectangle(0, 0, 40, 80);
  EXPECT_NE(step.Validate(size, kPx, "measurements[0]").message().find("measurements[0].reference_roi is required"),
            std::string::npos);
  MeasurementSpec tilt;
  tilt.kind = MeasurementKind::kTilt;
  tilt.reference_roi = RegionOfInterest::WholeField();
  EXPECT_NE(tilt.Validate(size, kPx, "m").message().find("m.reference_roi is not used by tilt"), std::string::npos);
  MeasurementSpec radius;
  radius.kind = MeasurementKind::kRadius;
  radius.form.model = FormModel::kPlane;
  EXPECT_NE(radius.Validate(size, kPx, "m").message().find("m.form.model"), std::string::npos);
  MeasurementSpec sa;
  sa.roi = RegionOfInterest::Rectangle(0, 0, 120, 10);
  EXPECT_NE(sa.Validate(size, kPx, "measurements[2]").message().find("measurements[2].roi"), std::string::npos);
  sa.roi = RegionOfInterest::WholeField();
  sa.areal.l_filter_cutoff_um = -3;
  EXPECT_NE(sa.Validate(size, kPx, "m").message().find("m.areal: l_filter_cutoff_um"), std::string::npos);
  EXPECT_EQ(sa.unit(), "um");
  MeasurementSpec v;
  v.kind = MeasurementKind::kVolumeBelow;
  v.volume_unit = VolumeUnit::kCubicMillimetre;
  EXPECT_EQ(v.unit(), "mm3");
}

class SyntheticPartTest : public ::testing::Test {
 protected:
  // 320 x 120 px: x < 140 px a 0.5 um cosine (lambda 30 px) on a tilted base; x >= 160 px a
  // flat at 200 um rising by 1.5 um at x >= 240 px. Noise 0.02 um (7 px correlated), holes.
  void SetUp() override {
    size_ = cv::Size(320, 120);
    depth_ = testing::SampleSurface(size_, kPx, [](double x, double y) {
      const double xp = x / kPx;
      if (xp < 150) return 205.0 + 0.01 * x + 0.005 * y + 0.5 * std::cos(2 * kPi * (x - 70 * kPx) / (30 * kPx));
      return 200.0 + (xp >= 240 ? 1.5 : 0.0);
    });
    depth_ += testing::CorrelatedNoise(size_, 0.02, 7, 31);
    testing::PunchHoles(depth_, 12, 3, 32);
    ctx_.depth_um = depth_;
    ctx_.pixel_size_um = kPx;
    ctx_.noise.window_px = 7;
    for (int k = 0; k < 30; ++k) ctx_.noise.z_positions_um.push_back(180.0 + 5.0 * k);
    ctx_.noise.linearity.bias_of_step = {0.0, 0.0};  // this synthetic instrument has none,
    ctx_.noise.linearity.characterised_step_um = 5.0;  // characterised at the scan's step
  }
  MeasurementSpec Spec(MeasurementKind kind, RegionOfInterest roi) {
    MeasurementSpec s;
    s.kind = kind;
    s.roi = roi;
    return s;
  }
  cv::Size size_;
  cv::Mat depth_;
  MeasurementContext ctx_;
};

TEST_F(SyntheticPartTest, MeasuresTheKnownValuesWithinTheirUncertainty) {
  // The roughness region holds 4 whole periods (x 10..130 px) symmetric about x = 70 px.
  const RegionOfInterest rough = RegionOfInterest::Rectangle(10, 0, 120, 120);
  const RegionOfInterest land = RegionOfInterest::Rectangle(165, 0, 60, 120);
  const RegionOfInterest top = RegionOfInterest::Rectangle(255, 0, 60, 120);
  std::vector<MeasurementSpec> specs = {Spec(MeasurementKind::kSa, rough),  Spec(MeasurementKind::kSq, rough),
                                        Spec(MeasurementKind::kSku, rough), Spec(MeasurementKind::kStepHeight, top),
                                        Spec(MeasurementKind::kTilt, land), Spec(MeasurementKind::kFlatness, land),
                                        Spec(MeasurementKind::kSz, rough)};
  specs[3].reference_roi = land;
  const std::vector<double> truth = {2 * 0.5 / kPi, 0.5 / std::sqrt(2.0), 1.5, 1.5, 0.0, 0.0, 1.0};
  // Sa's sampled |cos| (30 px per period) is 2/pi (1 + 1.8e-3); Sz of the sampled cosine = 2A.
  auto out = MeasureAll(specs, ctx_);
  ASSERT_EQ(out.size(), specs.size());
  for (size_t i = 0; i < specs.size(); ++i) {
    ASSERT_TRUE(out[i].ok()) << i << ": " << out[i].status().ToString();
    const MeasuredValue& v = *out[i];
    const double u = v.uncertainty.standard_uncertainty;
    std::printf("%-11s %9.5f %-3s truth %8.5f  u %.5f (%s)  coverage %.1f %%\n", MeasurementKindName(v.kind), v.value,
                v.unit.c_str(), truth[i], u, v.uncertainty.method.c_str(), v.coverage_percent);
    EXPECT_GT(u, 0.0) << MeasurementKindName(v.kind);
    // One realisation: within U = 2u (plus Sa's 0.2 % sampling offset). Flatness and tilt of a
    // noisy flat measure the noise itself (truth 0), which their uncertainty must hold.
    EXPECT_LE(std::abs(v.value - truth[i]), 2.0 * u + 2e-3 * truth[i]) << MeasurementKindName(v.kind);
    EXPECT_GT(v.coverage_percent, 90.0);
  }
  EXPECT_EQ(out[0]->unit, "um");
  EXPECT_EQ(out[2]->unit, "");
  EXPECT_EQ(out[4]->unit, "deg");
  EXPECT_EQ(out[0]->uncertainty.method, "monte-carlo");
  EXPECT_EQ(out[3]->uncertainty.method, "analytic");
  EXPECT_EQ(out[6]->uncertainty.method, "bound");
  // Grouped (one Monte Carlo for Sa, Sq, Sku on the same region) = measured alone.
  auto alone = Measure(specs[1], ctx_);
  ASSERT_TRUE(alone.ok());
  EXPECT_EQ(alone->value, out[1]->value);
  EXPECT_EQ(alone->uncertainty.standard_uncertainty, out[1]->uncertainty.standard_uncertainty);
  // Verdicts: the step is 1.5 +- 0.1 um (OK); Sa <= 0.2 um is violated (0.318).
  Tolerance step_tol;
  step_tol.nominal = 1.5;
  step_tol.lower = -0.1;
  step_tol.upper = 0.1;
  step_tol.min_coverage_percent = 90;
  EXPECT_EQ(Judge(out[3]->value, out[3]->uncertainty.standard_uncertainty, out[3]->coverage_percent, step_tol).verdict,
            Verdict::kOk);
  Tolerance sa_tol;
  sa_tol.upper = 0.2;
  EXPECT_EQ(Judge(out[0]->value, out[0]->uncertainty.standard_uncertainty, out[0]->coverage_percent, sa_tol).verdict,
            Verdict::kNotOk);
}

TEST_F(SyntheticPartTest, EmptyRegionsFailAndValuesCanSkipTheUncertainty) {
  cv::Mat holed = depth_.clone();
  holed(cv::Rect(0, 0, 50, 50)).setTo(NAN);
  ctx_.depth_um = holed;
  auto none = Measure(Spec(MeasurementKind::kSa, RegionOfInterest::Rectangle(0, 0, 50, 50)), ctx_, "measurements[5]");
  EXPECT_EQ(none.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(none.status().message().find("measurements[5].roi"), std::string::npos);
  // Half of the region without depth: coverage 50 %.
  auto half = Measure(Spec(MeasurementKind::kSq, RegionOfInterest::Rectangle(0, 0, 100, 50)), ctx_);
  ASSERT_TRUE(half.ok()) << half.status().ToString();
  EXPECT_NEAR(half->coverage_percent, 50.0, 1.0);
  ctx_.with_uncertainty = false;
  auto plain = Measure(Spec(MeasurementKind::kTilt, RegionOfInterest::Rectangle(165, 0, 60, 120)), ctx_);
  ASSERT_TRUE(plain.ok());
  EXPECT_TRUE(std::isnan(plain->uncertainty.standard_uncertainty));
  // A radius needs a curved region: a flat one fails as not measurable, not as a bad request.
  MeasurementSpec r = Spec(MeasurementKind::kRadius, RegionOfInterest::Rectangle(165, 0, 60, 120));
  EXPECT_EQ(Measure(r, ctx_).status().code(), StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace inspection
