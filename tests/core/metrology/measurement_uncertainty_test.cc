// The depth error model and its propagation, checked against simulation: the noise estimate
// recovers a known sigma (also with a lay and per region), the analytic covariance of a fit
// matches the spread over many noise realisations, the z-linearity and stage terms match their
// closed forms, and the Monte Carlo noise-bias estimate covers the bias of Sq on pure noise.
#include "core/metrology/measurement_uncertainty.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/metrology/areal_parameters.h"
#include "core/metrology/measurement.h"
#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

using testing::kPi;

constexpr double kPx = 0.74;

DepthNoiseOptions Options(int window = 7) {
  DepthNoiseOptions o;
  o.window_px = window;
  for (int k = 0; k < 40; ++k) o.z_positions_um.push_back(150.0 + 5.0 * k);
  o.linearity.bias_of_step = {0.0, 0.0};  // no z-linearity unless a test sets one
  o.linearity.characterised_step_um = 5.0;  // (characterised as none: not the uncharacterised prior)
  return o;
}

cv::Mat All(cv::Size s) { return cv::Mat(s, CV_8UC1, cv::Scalar(255)); }

TEST(MeasurementUncertaintyTest, NoiseEstimateRecoversSigmaOnPlaneAndOnALaidSurface) {
  const cv::Size size(300, 200);
  const double sigma = 0.05;
  // Tilted plane: second differences cancel it. ~60000 samples / 49 px per correlation area:
  // the estimate is good to ~5 %.
  cv::Mat plane = testing::SampleSurface(size, kPx, [](double x, double y) { return 200.0 + 0.1 * x + 0.05 * y; });
  const cv::Mat noise = testing::CorrelatedNoise(size, sigma, 7, 21);
  plane += noise;
  auto m = EstimateDepthNoise(plane, cv::Mat(), Options());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_NEAR(m->global_sigma_um, sigma, 0.1 * sigma);
  EXPECT_NEAR(m->sigma_um.at<float>(100, 150), sigma, 0.25 * sigma);  // local: ~64 areas, ~13 %
  // The extreme bound holds the realisation's largest error (~1.2x it for Gaussian noise).
  double lo, hi;
  cv::minMaxLoc(noise, &lo, &hi);
  EXPECT_GE(m->extreme_error_um, std::max(hi, -lo));
  EXPECT_LE(m->extreme_error_um, 2.0 * std::max(hi, -lo));
  // A 2 um cosine lay along x would swamp x's second differences; y's still see the noise only.
  cv::Mat laid =
      testing::SampleSurface(size, kPx, [](double x, double) { return 200.0 + 2.0 * std::cos(2 * kPi * x / 30.0); });
  laid += noise;
  auto ml = EstimateDepthNoise(laid, cv::Mat(), Options());
  ASSERT_TRUE(ml.ok());
  EXPECT_NEAR(ml->global_sigma_um, sigma, 0.15 * sigma);
}

TEST(MeasurementUncertaintyTest, ExtremeBoundLeavesOutTheFormAndErrorsThatCannotReachTheExtreme) {
  // A 3 um sine along x and y (43 px periods: second differences of 3.7 um at lag 8 from the form
  // alone) with one +0.5 um spike on a flank, mid-height, and light noise.
  const cv::Size size(240, 200);
  const double lambda_um = 43.0 * kPx;
  cv::Mat z = testing::SampleSurface(size, kPx, [&](double x, double y) {
    return 200.0 + 1.5 * std::sin(2 * kPi * x / lambda_um) + 1.5 * std::sin(2 * kPi * y / lambda_um);
  });
  z += testing::CorrelatedNoise(size, 0.02, 7, 23);
  const int fx = 86, fy = 86;  // sin(2 pi 86 / 43) = 0 in both: the flank's middle height
  z.at<float>(fy, fx) += 0.5f;
  auto m = EstimateDepthNoise(z, cv::Mat(), Options());
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  ASSERT_FALSE(m->extreme_error_map_um.empty());
  // The region-wide bound is the form's curvature; the local one at the spike is the spike.
  EXPECT_GT(m->extreme_error_um, 1.0);
  EXPECT_NEAR(m->extreme_error_map_um.at<float>(fy, fx), 0.5, 0.15);
  // The spike lies ~3 um below the peak and above the valley: it cannot move either, so the
  // extremes' bounds are the form's residual and the noise at the peak and the valley, well
  // below the spike and the region-wide bound.
  const double peak = ExtremeErrorUm(z, *m, true), valley = ExtremeErrorUm(z, *m, false);
  EXPECT_LT(peak, 0.45);
  EXPECT_LT(valley, 0.45);
  EXPECT_GT(peak, 0.0);
  // The same spike on the peak itself moves Sp by 0.5 um: the bound holds it.
  cv::Mat on_peak = z.clone();
  on_peak.at<float>(fy, fx) -= 0.5f;
  const int px = 86 + 11, py = 86 + 11;  // sin = 1 in both: the top
  on_peak.at<float>(py, px) += 0.5f;
  auto mp = EstimateDepthNoise(on_peak, cv::Mat(), Options());
  ASSERT_TRUE(mp.ok());
  EXPECT_GE(ExtremeErrorUm(on_peak, *mp, true), 0.45);
  // The budget: U = E + R, u = U / 2.
  const UncertaintyBudget b = ExtremeValueBudgetUm(0.4, 0.1);
  EXPECT_DOUBLE_EQ(b.standard_uncertainty, 0.25);
  EXPECT_EQ(b.method, "bound");
}

TEST(MeasurementUncertaintyTest, NoiseEstimateFollowsRegionsAndFallsBackForTinyOnes) {
  const cv::Size size(300, 120);
  // Left half noise 0.02 um, right half 0.1 um.
  cv::Mat z = 200.0f + testing::CorrelatedNoise(size, 0.02, 7, 1);
  const cv::Mat rz = 200.0f + testing::CorrelatedNoise(size, 0.1, 7, 2);
  rz(cv::Rect(150, 0, 150, 120)).copyTo(z(cv::Rect(150, 0, 150, 120)));
  cv::Mat lmask(size, CV_8UC1, cv::Scalar(0)), rmask = lmask.clone();
  lmask(cv::Rect(0, 0, 150, 120)).setTo(255);
  rmask(cv::Rect(150, 0, 150, 120)).setTo(255);
  auto ml = EstimateDepthNoise(z, lmask, Options()), mr = EstimateDepthNoise(z, rmask, Options());
  ASSERT_TRUE(ml.ok() && mr.ok());
  EXPECT_NEAR(ml->global_sigma_um, 0.02, 0.003);
  EXPECT_NEAR(mr->global_sigma_um, 0.1, 0.015);
  EXPECT_TRUE(std::isnan(ml->sigma_um.at<float>(60, 200)));  // outside its region
  // A 10 x 10 region has no second difference at lag 8 of its own: the map's level stands in.
  cv::Mat tiny(size, CV_8UC1, cv::Scalar(0));
  tiny(cv::Rect(20, 20, 10, 10)).setTo(255);
  auto mt = EstimateDepthNoise(z, tiny, Options());
  ASSERT_TRUE(mt.ok()) << mt.status().ToString();
  EXPECT_GT(mt->global_sigma_um, 0.02);
  EXPECT_TRUE(std::isfinite(mt->sigma_um.at<float>(25, 25)));
}

// Model with exactly the generator's sigma and window.
DepthNoiseModel Known(const cv::Mat& depth, double sigma, int window, const DepthNoiseOptions& o) {
  DepthNoiseModel m;
  m.sigma_um = cv::Mat(depth.size(), CV_32FC1, cv::Scalar(float(sigma)));
  m.global_sigma_um = sigma;
  m.correlation_px = window;
  m.grid = *ZGrid::Create(o.z_positions_um);
  m.linearity = o.linearity;
  m.stage_u_um = o.stage_repeatability_um / std::sqrt(3.0);
  m.three_point_peak = o.three_point_peak;
  return m;
}

TEST(MeasurementUncertaintyTest, FitCovarianceMatchesTheSpreadOverRealisations) {
  // 400 noise realisations (sigma 0.05 um, 7 x 7 correlated) on a 90 x 60 px plane: the sample
  // variance of each parameter is known to sqrt(2 / 400) = 7 %; the bound is 3 of those (21 %).
  const cv::Size size(90, 60);
  const cv::Mat base =
      testing::SampleSurface(size, kPx, [](double x, double y) { return 210.0 + 0.02 * x - 0.01 * y; });
  auto fit0 = FitForm(base, All(size), kPx, FormOptions{});
  ASSERT_TRUE(fit0.ok());
  auto cov = FormFitCovariance(*fit0, base, All(size), kPx, Known(base, 0.05, 7, Options()));
  ASSERT_TRUE(cov.ok()) << cov.status().ToString();
  const int n = 400;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum2 = Eigen::Vector3d::Zero();
  for (int k = 0; k < n; ++k) {
    const cv::Mat z = base + testing::CorrelatedNoise(size, 0.05, 7, 1000 + k);
    auto f = FitForm(z, All(size), kPx, FormOptions{});
    ASSERT_TRUE(f.ok());
    const Eigen::Vector3d d = f->parameters - fit0->parameters;
    sum += d;
    sum2 += d.cwiseProduct(d);
  }
  for (int j = 0; j < 3; ++j) {
    const double var = sum2[j] / n - (sum[j] / n) * (sum[j] / n);
    std::printf("%s: empirical sd %.3e, predicted %.3e (independent-noise formula %.3e)\n",
                fit0->parameter_names[j].c_str(), std::sqrt(var), std::sqrt(cov->random(j, j)),
                0.05 * std::sqrt(fit0->normal_inverse(j, j)));
    EXPECT_NEAR(var / cov->random(j, j), 1.0, 0.21) << fit0->parameter_names[j];
  }
  EXPECT_DOUBLE_EQ(cov->linearity.norm(), 0.0);
  EXPECT_DOUBLE_EQ(cov->stage.norm(), 0.0);
}

TEST(MeasurementUncertaintyTest, LinearityAndStageTermsMatchTheirClosedForms) {
  // Two flat regions 1 um apart with a first-harmonic linearity a sin(2 pi f) (a = 0.04 of a
  // 5 um step). Over its unknown phase the step functional's variance is
  // (a step)^2 (1 - cos(2 pi df)) with df = 1 um / 5 um.
  const cv::Size size(100, 40);
  cv::Mat z(size, CV_32FC1, cv::Scalar(200.0f));
  z(cv::Rect(50, 0, 50, 40)).setTo(201.0f);
  DepthNoiseOptions o = Options();
  o.linearity.bias_of_step.clear();
  for (int i = 0; i < 100; ++i) o.linearity.bias_of_step.push_back(0.04 * std::sin(2 * kPi * i / 100.0));
  o.stage_repeatability_um = 0.1;
  const DepthNoiseModel m = Known(z, 0.0, 7, o);
  cv::Mat w = cv::Mat::zeros(size, CV_64F);
  w(cv::Rect(50, 0, 50, 40)).setTo(1.0 / 2000);
  w(cv::Rect(0, 0, 50, 40)).setTo(-1.0 / 2000);
  auto cov = LinearFunctionalCovariance({w}, z, m);
  ASSERT_TRUE(cov.ok()) << cov.status().ToString();
  const double expected = std::pow(0.04 * 5.0, 2) * (1.0 - std::cos(2 * kPi * 0.2));
  EXPECT_NEAR(cov->linearity(0, 0), expected, 0.01 * expected);  // piecewise-linear table, 64 phases
  // Stage, through the three-point peak's sensitivities (core/metrology/depth_noise_model.h):
  // a depth at the frame at 200 um takes -(d195 + d205) / 2; one at 201 um (x = 0.2)
  // -0.36 d195 - 0.08 d200 - 0.56 d205. The step's coefficients 0.14, -0.08, -0.06 give
  // var = 0.0296 (0.1 / sqrt 3)^2.
  EXPECT_NEAR(cov->stage(0, 0), 0.0296 * 0.01 / 3.0, 1e-12);
  EXPECT_NEAR(cov->random(0, 0), 0.0, 1e-15);
  // Heights 5 um apart, both at a frame: -(d195 + d205) / 2 against -(d200 + d210) / 2, four
  // frames at +-1/2: var = (0.1 / sqrt 3)^2; the linearity is common.
  z(cv::Rect(50, 0, 50, 40)).setTo(205.0f);
  auto cov2 = LinearFunctionalCovariance({w}, z, m);
  ASSERT_TRUE(cov2.ok());
  EXPECT_NEAR(cov2->stage(0, 0), 0.01 / 3.0, 1e-12);
  // With a maximum or line-fit interpolation each depth takes its nearest frame's error in full.
  o.three_point_peak = false;
  const DepthNoiseModel nearest = Known(z, 0.0, 7, o);
  auto cov3 = LinearFunctionalCovariance({w}, z, nearest);
  ASSERT_TRUE(cov3.ok());
  EXPECT_NEAR(cov3->stage(0, 0), 2.0 * 0.01 / 3.0, 1e-12);
  EXPECT_NEAR(cov2->linearity(0, 0), 0.0, 1e-12);
}

TEST(MeasurementUncertaintyTest, MonteCarloIsRepeatableAndItsBiasCoversNoiseOnlySq) {
  // A flat of pure noise: Sq measures the noise (truth 0). The doubling estimate of the noise
  // bias is exact in this worst case up to Monte Carlo scatter (64 samples: ~5 %).
  const cv::Size size(160, 120);
  const cv::Mat z = 200.0f + testing::CorrelatedNoise(size, 0.05, 7, 77);
  const DepthNoiseModel m = Known(z, 0.05, 7, Options());
  auto measure = [&](const cv::Mat& d) -> StatusOr<std::vector<double>> {
    INSPECT_ASSIGN_OR_RETURN(ArealEvaluation e, EvaluateArealSurface(d, All(size), kPx, ArealOptions{}));
    return std::vector<double>{e.parameters.Sq_um, e.parameters.Sa_um};
  };
  auto v = measure(z);
  ASSERT_TRUE(v.ok());
  MonteCarloOptions mc;
  mc.samples = 64;
  auto a = MonteCarloUncertainty(z, *v, measure, m, mc);
  auto b = MonteCarloUncertainty(z, *v, measure, m, mc);
  ASSERT_TRUE(a.ok() && b.ok()) << a.status().ToString();
  EXPECT_EQ((*a)[0].standard_uncertainty, (*b)[0].standard_uncertainty);  // same seed, same answer
  for (int i = 0; i < 2; ++i) {
    std::printf("%s of noise: %.4f um, MC bias %.4f spread %.4f\n", i ? "Sa" : "Sq", (*v)[i], (*a)[i].bias,
                (*a)[i].spread);
    EXPECT_NEAR((*a)[i].bias, (*v)[i], 0.15 * (*v)[i]);
    EXPECT_GE(2.0 * (*a)[i].standard_uncertainty, (*v)[i]);  // U covers the deviation from 0
  }
  EXPECT_EQ(MonteCarloUncertainty(z, *v, measure, m, MonteCarloOptions{4}).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection

namespace inspection {
namespace {

TEST(MeasurementUncertaintyTest, LinearityCharacterisedAtACoarserStepIsKeptInMicrometresAtAFinerOne) {
  const cv::Size size(120, 80);
  const cv::Mat plane = testing::SampleSurface(size, kPx, [](double x, double) { return 200.0 + 0.01 * x; }) +
                        testing::CorrelatedNoise(size, 0.05, 7, 5);
  DepthNoiseOptions o = Options();
  o.linearity.bias_of_step = {0.01, -0.02, 0.004, 0.006};
  o.linearity.characterised_step_um = 5.0;
  o.linearity.source = "tilted flat";
  // Scan at 2 um steps: the table becomes 2.5x its fraction of the step, the same in um.
  o.z_positions_um.clear();
  for (int k = 0; k < 60; ++k) o.z_positions_um.push_back(150.0 + 2.0 * k);
  auto fine = EstimateDepthNoise(plane, cv::Mat(), o);
  ASSERT_TRUE(fine.ok()) << fine.status().ToString();
  ASSERT_EQ(fine->linearity.bias_of_step.size(), 4u);
  EXPECT_NEAR(fine->linearity.bias_of_step[1], -0.05, 1e-12);
  EXPECT_NEAR(fine->linearity.bias_of_step[1] * 2.0, -0.02 * 5.0, 1e-12);
  EXPECT_NEAR(fine->linearity.characterised_step_um, 2.0, 1e-12);
  EXPECT_NE(fine->linearity.source.find("transferred from"), std::string::npos) << fine->linearity.source;
  // Scan at 10 um steps: the error grows with the step by an unknown amount; the uncharacterised
  // prior (a three-point peak: its interpolation's analytic error bound).
  o.z_positions_um.clear();
  for (int k = 0; k < 20; ++k) o.z_positions_um.push_back(150.0 + 10.0 * k);
  auto coarse = EstimateDepthNoise(plane, cv::Mat(), o);
  ASSERT_TRUE(coarse.ok()) << coarse.status().ToString();
  EXPECT_NEAR(coarse->linearity.MaxAbs(), ZLinearity::UncharacterisedThreePointPeak().MaxAbs(), 1e-12);
  EXPECT_NE(coarse->linearity.source.find("does not apply"), std::string::npos) << coarse->linearity.source;
  // A transfer that would need more than half a step of bias falls back as well (0.3 at 5 um
  // is 0.75 of a 2 um step).
  o.linearity.bias_of_step = {0.3, -0.3};
  o.z_positions_um.clear();
  for (int k = 0; k < 60; ++k) o.z_positions_um.push_back(150.0 + 2.0 * k);
  auto far = EstimateDepthNoise(plane, cv::Mat(), o);
  ASSERT_TRUE(far.ok()) << far.status().ToString();
  EXPECT_NEAR(far->linearity.MaxAbs(), ZLinearity::UncharacterisedThreePointPeak().MaxAbs(), 1e-12);
}

TEST(MeasurementUncertaintyTest, UncharacterisedThreePointPeakTakesItsInterpolationErrorNotTheSawtooth) {
  // The prior: the Gaussian three-point vertex on the defocus curve (1 + (u / w)^2)^-2 at
  // w = step / 2. Zero on a frame and half-way between (by symmetry), antisymmetric about
  // half a step, largest 0.109 of the step near f = 0.30 (the closed form evaluated by hand:
  // at x = 0.3, ln F at u = -1.3, -0.3, 0.7 gives mu = 0.1913, so the error is -0.1087).
  const ZLinearity prior = ZLinearity::UncharacterisedThreePointPeak();
  ASSERT_EQ(prior.bias_of_step.size(), 64u);
  EXPECT_NEAR(prior.At(0.0), 0.0, 1e-12);
  EXPECT_NEAR(prior.At(0.5), 0.0, 1e-12);
  EXPECT_NEAR(prior.At(0.3), -0.1087, 0.002);
  for (int i = 1; i < 32; ++i) EXPECT_NEAR(prior.bias_of_step[i], -prior.bias_of_step[64 - i], 1e-12) << i;
  EXPECT_NEAR(prior.MaxAbs(), 0.109, 0.002);
  EXPECT_NE(prior.source.find("three-point"), std::string::npos);
  // EstimateDepthNoise takes it for an uncharacterised linearity when the depth is a three-point
  // vertex, and keeps the discrete maximum's sawtooth for the maximum / line fit.
  const cv::Size size(120, 80);
  const cv::Mat plane = testing::SampleSurface(size, kPx, [](double x, double) { return 200.0 + 0.01 * x; }) +
                        testing::CorrelatedNoise(size, 0.05, 7, 5);
  DepthNoiseOptions o = Options();
  o.linearity = ZLinearity::Uncharacterised();
  auto three = EstimateDepthNoise(plane, cv::Mat(), o);
  ASSERT_TRUE(three.ok()) << three.status().ToString();
  EXPECT_NEAR(three->linearity.MaxAbs(), prior.MaxAbs(), 1e-12);
  EXPECT_FALSE(three->linearity_shape_known);
  o.three_point_peak = false;
  auto maximum = EstimateDepthNoise(plane, cv::Mat(), o);
  ASSERT_TRUE(maximum.ok());
  EXPECT_NEAR(maximum->linearity.MaxAbs(), ZLinearity::Uncharacterised().MaxAbs(), 1e-12);
  // A table characterised at the scan's step is known in shape; one transferred from a coarser
  // step is not.
  o.three_point_peak = true;
  o.linearity.bias_of_step = {0.0, 0.01, 0.0, -0.01};
  o.linearity.characterised_step_um = o.z_positions_um[1] - o.z_positions_um[0];
  auto own = EstimateDepthNoise(plane, cv::Mat(), o);
  ASSERT_TRUE(own.ok());
  EXPECT_TRUE(own->linearity_shape_known);
  o.linearity.characterised_step_um *= 2.0;
  auto transferred = EstimateDepthNoise(plane, cv::Mat(), o);
  ASSERT_TRUE(transferred.ok());
  EXPECT_FALSE(transferred->linearity_shape_known);
  EXPECT_GT(transferred->linearity.characterised_step_um, 0.0);
}

// A step between two flats, 120 x 80 px at 1 um/px, white noise of 0.02 um, each flat offset by
// `offset_um` (left +, right -) like a z-linearity error; the step read `gain` times too long.
StatusOr<MeasuredValue> MeasureNoisyStep(double step_um, double offset_um, double gain,
                                         const VerifiedCharacteristics& verified) {
  const cv::Size size(120, 80);
  cv::Mat z(size, CV_32FC1);
  cv::RNG rng(25178);
  rng.fill(z, cv::RNG::NORMAL, 0.0, 0.02);
  z(cv::Rect(0, 0, 60, 80)) += 200.0 + offset_um;
  z(cv::Rect(60, 0, 60, 80)) += 200.0 + gain * step_um - offset_um;
  MeasurementSpec spec;
  spec.kind = MeasurementKind::kStepHeight;
  spec.roi = RegionOfInterest::Rectangle(70, 5, 45, 70);
  spec.reference_roi = RegionOfInterest::Rectangle(5, 5, 45, 70);
  MeasurementContext ctx;
  ctx.depth_um = z;
  ctx.pixel_size_um = 1.0;
  ctx.noise.window_px = 7;
  for (int k = 0; k < 40; ++k) ctx.noise.z_positions_um.push_back(150.0 + 5.0 * k);
  ctx.noise.linearity = ZLinearity::Uncharacterised();
  ctx.noise.verified = verified;
  return Measure(spec, ctx);
}

TEST(VerifiedCharacteristicsTest, VerifiedLinearityDeviationReplacesTheSawtoothBoundAndStillCovers) {
  // Uncharacterised at 5 um steps, a 1.3 um step carries the three-point peak's prior of
  // +-0.55 um (0.109 step): U ~ 1.1 um. A verified l_z = 0.05 um scales the same shape to
  // +-0.05 um; the flats' +-0.03 um offsets (a 0.06 um short step, within 2 l_z) stay covered.
  auto bare = MeasureNoisyStep(1.3, 0.03, 1.0, {});
  VerifiedCharacteristics v;
  v.linearity_deviation_um = 0.05;
  auto verified = MeasureNoisyStep(1.3, 0.03, 1.0, v);
  ASSERT_TRUE(bare.ok() && verified.ok()) << bare.status().ToString() << verified.status().ToString();
  const double u_bare = 2.0 * bare->uncertainty.standard_uncertainty;
  const double u_ver = 2.0 * verified->uncertainty.standard_uncertainty;
  const double dev = verified->value - 1.3;
  std::printf("step 1.3 um: dev %+.4f, U %.4f uncharacterised, %.4f with l_z 0.05 um\n", dev, u_bare, u_ver);
  EXPECT_NEAR(dev, -0.06, 0.01);
  EXPECT_GT(u_bare, 0.8);
  EXPECT_LT(u_ver, 0.15);      // 0.05 / 0.55 of the prior's part, plus the noise
  EXPECT_LE(std::abs(dev), u_ver);
  // Never widened: an l_z above the prior's size leaves it.
  v.linearity_deviation_um = 10.0;
  auto wide = MeasureNoisyStep(1.3, 0.03, 1.0, v);
  ASSERT_TRUE(wide.ok());
  EXPECT_NEAR(wide->uncertainty.standard_uncertainty, bare->uncertainty.standard_uncertainty, 1e-12);
}

TEST(VerifiedCharacteristicsTest, VerifiedLinearityAppliesAtItsOwnStepAndFinerOnesOnly) {
  // The scans here step 5 um. An l_z verified at 5 um or at 10 um (coarser: its size in um
  // bounds a finer sampling too) replaces the sawtooth; one verified at 2 um does not bound the
  // interpolation error of 5 um steps, so U stays the uncharacterised one.
  auto bare = MeasureNoisyStep(1.3, 0.03, 1.0, {});
  ASSERT_TRUE(bare.ok()) << bare.status().ToString();
  VerifiedCharacteristics v;
  v.linearity_deviation_um = 0.05;
  for (double at : {5.0, 5.2, 10.0}) {
    v.linearity_step_um = at;
    auto r = MeasureNoisyStep(1.3, 0.03, 1.0, v);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_LT(2.0 * r->uncertainty.standard_uncertainty, 0.15) << "verified at " << at << " um";
  }
  for (double at : {2.0, 4.0}) {
    v.linearity_step_um = at;
    auto r = MeasureNoisyStep(1.3, 0.03, 1.0, v);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_NEAR(r->uncertainty.standard_uncertainty, bare->uncertainty.standard_uncertainty, 1e-12)
        << "verified at " << at << " um";
  }
  v.linearity_step_um = 0.0;
  auto bad = MeasureNoisyStep(1.3, 0.03, 1.0, v);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("verified.linearity_step_um"), std::string::npos) << bad.status().ToString();
}

TEST(VerifiedCharacteristicsTest, VerifiedAmplificationCoversAHeightScaleError) {
  // A 20 um step (a whole number of 4 steps: the linearity cancels) read 2 % long: 0.4 um, far
  // outside the random-only U. With alpha_z = 1.02 +- 0.005 verified, u_alpha = 0.0206 x 20.4 um.
  VerifiedCharacteristics lz;
  lz.linearity_deviation_um = 0.02;
  auto without = MeasureNoisyStep(20.0, 0.0, 1.02, lz);
  VerifiedCharacteristics v = lz;
  v.amplification = 1.02;
  v.amplification_u = 0.005;
  auto with = MeasureNoisyStep(20.0, 0.0, 1.02, v);
  ASSERT_TRUE(without.ok() && with.ok());
  const double dev = with->value - 20.0;
  std::printf("step 20 um x 1.02: dev %+.4f, U %.4f without, %.4f with alpha_z (component %.4f)\n", dev,
              2.0 * without->uncertainty.standard_uncertainty, 2.0 * with->uncertainty.standard_uncertainty,
              with->uncertainty.amplification);
  EXPECT_NEAR(dev, 0.4, 0.01);
  EXPECT_GT(std::abs(dev), 2.0 * without->uncertainty.standard_uncertainty);
  EXPECT_NEAR(with->uncertainty.amplification, std::hypot(0.005, 0.02) * with->value, 1e-9);
  EXPECT_LE(std::abs(dev), 2.0 * with->uncertainty.standard_uncertainty);
  EXPECT_LT(2.0 * with->uncertainty.standard_uncertainty, 1.0);
  // Invalid input names the field.
  VerifiedCharacteristics bad;
  bad.amplification_u = 0.01;
  auto b = MeasureNoisyStep(20.0, 0.0, 1.0, bad);
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.status().message().find("verified.amplification_u"), std::string::npos) << b.status().ToString();
}

}  // namespace
}  // namespace inspection
