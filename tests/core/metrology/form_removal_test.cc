// Form removal against analytic surfaces: plane (tilt), polynomials, sphere and cylinder
// (lenses) recover their parameters; with correlated noise and NaN holes the errors stay within
// the propagated uncertainty; bad regions fail with FAILED_PRECONDITION.
#include "core/metrology/form_removal.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/metrology/measurement_uncertainty.h"
#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

using testing::kPi;
using testing::SampleSurface;

constexpr double kPx = 0.74;
// Depths are float32: ~200-700 um values carry a rounding of ~1e-5 um, which bounds how exactly
// a noise-free fit can reproduce them.
constexpr double kFloatUm = 1e-4;

cv::Mat All(cv::Size s) { return cv::Mat(s, CV_8UC1, cv::Scalar(255)); }

// Noise model with a known per-pixel sigma and window, no z-linearity and no stage term.
DepthNoiseModel KnownNoise(const cv::Mat& depth, double sigma_um, int window_px) {
  DepthNoiseModel m;
  m.sigma_um = cv::Mat(depth.size(), CV_32FC1, cv::Scalar(float(sigma_um)));
  m.sigma_um.setTo(NAN, depth != depth);
  m.global_sigma_um = sigma_um;
  m.correlation_px = window_px;
  m.grid = *ZGrid::Create({0.0, 10000.0});
  m.linearity.bias_of_step = {0.0, 0.0};
  return m;
}

TEST(FormRemovalTest, PlaneRecoversHeightAndSlopes) {
  const cv::Size size(120, 90);
  const cv::Mat z = SampleSurface(size, kPx, [](double x, double y) { return 200.0 + 0.05 * x - 0.02 * y; });
  auto fit = FitForm(z, All(size), kPx, FormOptions{});
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  EXPECT_NEAR(fit->parameters[1], 0.05, 1e-7);
  EXPECT_NEAR(fit->parameters[2], -0.02, 1e-7);
  EXPECT_NEAR(fit->Evaluate(10.0, 20.0), 200.0 + 0.5 - 0.4, kFloatUm);
  EXPECT_NEAR(fit->PlaneTiltDeg(), std::atan(std::hypot(0.05, 0.02)) * 180.0 / kPi, 1e-6);
  EXPECT_LT(fit->residual_rms_um, kFloatUm);
  EXPECT_EQ(fit->pixel_count, 120u * 90u);
  // The residual map is NaN outside the mask.
  cv::Mat mask = All(size);
  mask(cv::Rect(0, 0, 10, 90)).setTo(0);
  const cv::Mat r = FormResidual(z, mask, kPx, *fit);
  EXPECT_TRUE(std::isnan(r.at<float>(5, 5)));
  EXPECT_NEAR(r.at<float>(50, 50), 0.0, kFloatUm);
}

TEST(FormRemovalTest, PolynomialOfOrderTwoAndThreeAreExact) {
  const cv::Size size(100, 80);
  auto quad = [](double x, double y) { return 300.0 + 0.01 * x + 0.002 * x * x - 0.003 * x * y + 0.001 * y * y; };
  auto cubic = [&](double x, double y) { return quad(x, y) + 2e-5 * x * x * x - 1e-5 * x * y * y; };
  for (int order : {2, 3}) {
    const cv::Mat z = SampleSurface(size, kPx, order == 2 ? std::function<double(double, double)>(quad) : cubic);
    FormOptions o;
    o.model = FormModel::kPolynomial;
    o.polynomial_order = order;
    auto fit = FitForm(z, All(size), kPx, o);
    ASSERT_TRUE(fit.ok()) << fit.status().ToString();
    EXPECT_EQ(fit->parameters.size(), order == 2 ? 6 : 10);
    EXPECT_LT(fit->residual_rms_um, kFloatUm) << "order " << order;
    EXPECT_NEAR(fit->Evaluate(30.0, 40.0), order == 2 ? quad(30, 40) : cubic(30, 40), kFloatUm);
    // A lower order cannot: the quadratic leaves the cubic terms (~0.1 um here).
    o.polynomial_order = order - 1;
    auto low = FitForm(z, All(size), kPx, o);
    ASSERT_TRUE(low.ok());
    EXPECT_GT(low->residual_rms_um, 0.01);
  }
}

TEST(FormRemovalTest, SphereRecoversRadiusAndCentreConvexAndConcave) {
  const cv::Size size(200, 150);
  const double r = 500.0, cx = 80.0, cy = 50.0;
  for (int sign : {1, -1}) {
    const cv::Mat z = SampleSurface(size, kPx, [&](double x, double y) {
      return 400.0 + sign * std::sqrt(r * r - (x - cx) * (x - cx) - (y - cy) * (y - cy));
    });
    FormOptions o;
    o.model = FormModel::kSphere;
    auto fit = FitForm(z, All(size), kPx, o);
    ASSERT_TRUE(fit.ok()) << fit.status().ToString();
    EXPECT_EQ(fit->sign, sign);
    // Noise-free: the radius is determined to float rounding over a cap ~0.1 um... 25 um deep.
    EXPECT_NEAR(fit->parameters[fit->ParameterIndex("radius_um")], r, 1e-3);
    EXPECT_NEAR(fit->parameters[0], cx, 1e-4);
    EXPECT_NEAR(fit->parameters[1], cy, 1e-4);
    EXPECT_NEAR(fit->parameters[2], 400.0, 1e-3);
    EXPECT_LT(fit->residual_rms_um, kFloatUm);
  }
}

TEST(FormRemovalTest, SphereWithNoiseAndHolesStaysWithinItsUncertainty) {
  const cv::Size size(200, 150);
  const double r = 500.0;
  cv::Mat z = SampleSurface(size, kPx, [&](double x, double y) {
    return 400.0 + std::sqrt(r * r - (x - 70) * (x - 70) - (y - 60) * (y - 60));
  });
  z += testing::CorrelatedNoise(size, 0.05, 7, 3);
  testing::PunchHoles(z, 20, 6, 4);
  FormOptions o;
  o.model = FormModel::kSphere;
  auto fit = FitForm(z, All(size), kPx, o);
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  const int k = fit->ParameterIndex("radius_um");
  auto cov = FormFitCovariance(*fit, z, All(size), kPx, KnownNoise(z, 0.05, 7));
  ASSERT_TRUE(cov.ok()) << cov.status().ToString();
  const double u = std::sqrt(cov->Total()(k, k));
  std::printf("sphere R 500 um, noise 0.05 um (7 px correlated), holes: R = %.3f um, u = %.3f um\n", fit->parameters[k],
              u);
  // One realisation: within 3 u (a 99.7 % interval when the uncertainty is right), and u must be
  // meaningful (not tiny, not huge) for a 110 x 150 um cap.
  EXPECT_NEAR(fit->parameters[k], r, 3.0 * u);
  EXPECT_GT(u, 0.05);
  EXPECT_LT(u, 10.0);
  // The textbook covariance from the residuals ignores the 7 x 7 correlation: it is ~7x too small.
  EXPECT_LT(std::sqrt(fit->covariance_from_residuals(k, k)), 0.4 * u);
}

TEST(FormRemovalTest, CylinderRecoversRadiusAxisAndSlope) {
  const cv::Size size(200, 150);
  const double r = 800.0, phi = 30.0 * kPi / 180.0, slope = 0.01;
  // Axis through (70, 60) um in direction phi, rising along it.
  const cv::Mat z = SampleSurface(size, kPx, [&](double x, double y) {
    const double t = (x - 70) * std::cos(phi) + (y - 60) * std::sin(phi);
    const double d = -(x - 70) * std::sin(phi) + (y - 60) * std::cos(phi);
    return 250.0 + slope * t + std::sqrt(r * r - d * d);
  });
  FormOptions o;
  o.model = FormModel::kCylinder;
  auto fit = FitForm(z, All(size), kPx, o);
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  EXPECT_EQ(fit->sign, 1);
  EXPECT_NEAR(fit->parameters[fit->ParameterIndex("radius_um")], r, 1e-2);
  EXPECT_NEAR(fit->parameters[fit->ParameterIndex("axis_angle_rad")], phi, 1e-6);
  EXPECT_NEAR(fit->parameters[fit->ParameterIndex("axis_slope")], slope, 1e-7);
  EXPECT_LT(fit->residual_rms_um, kFloatUm);
  // The same surface as a sphere does not fit (a cylinder has no curvature along its axis).
  o.model = FormModel::kSphere;
  auto sphere = FitForm(z, All(size), kPx, o);
  if (sphere.ok()) {
    EXPECT_GT(sphere->residual_rms_um, 0.1);
  }
}

TEST(FormRemovalTest, RegionsThatCannotDetermineTheFormFail) {
  const cv::Size size(50, 40);
  const cv::Mat z = SampleSurface(size, kPx, [](double x, double) { return 200.0 + 0.1 * x; });
  cv::Mat line(size, CV_8UC1, cv::Scalar(0));
  line.row(20).setTo(255);  // one row: the y slope is undetermined
  EXPECT_EQ(FitForm(z, line, kPx, FormOptions{}).status().code(), StatusCode::kFailedPrecondition);
  cv::Mat three(size, CV_8UC1, cv::Scalar(0));
  three(cv::Rect(0, 0, 3, 1)).setTo(255);
  auto few = FitForm(z, three, kPx, FormOptions{});
  EXPECT_EQ(few.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(few.status().message().find("at least 4"), std::string::npos) << few.status().message();
  FormOptions bad;
  bad.model = FormModel::kPolynomial;
  bad.polynomial_order = 4;
  EXPECT_EQ(FitForm(z, All(size), kPx, bad).status().code(), StatusCode::kInvalidArgument);
  // A plane has no sphere radius.
  FormOptions sphere;
  sphere.model = FormModel::kSphere;
  EXPECT_EQ(FitForm(z, All(size), kPx, sphere).status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(*ParseFormModel("cylinder"), FormModel::kCylinder);
  EXPECT_EQ(ParseFormModel("cone").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
