// Tilt, flatness and volume on analytic surfaces: tilted planes (angle and azimuth), a cosine
// on a tilted plane (peak-to-valley), a flat with a raised disc and a pit (volumes), with holes;
// the tilt uncertainty near zero tilt covers the Rayleigh-distributed |slope|.
#include "core/metrology/plane_measures.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/core/metrology_surfaces.h"

namespace inspection {
namespace {

using testing::kPi;

constexpr double kPx = 0.74;

cv::Mat All(cv::Size s) { return cv::Mat(s, CV_8UC1, cv::Scalar(255)); }

DepthNoiseModel Known(const cv::Mat& depth, double sigma, int window) {
  DepthNoiseModel m;
  m.sigma_um = cv::Mat(depth.size(), CV_32FC1, cv::Scalar(float(sigma)));
  m.sigma_um.setTo(NAN, depth != depth);
  m.global_sigma_um = sigma;
  m.extreme_error_um = 0.0;
  m.correlation_px = window;
  m.grid = *ZGrid::Create({0.0, 10000.0});
  m.linearity.bias_of_step = {0.0, 0.0};
  return m;
}

TEST(PlaneMeasuresTest, TiltAngleAndAzimuthOfTiltedPlanes) {
  const cv::Size size(100, 80);
  struct Case {
    double sx, sy;
  };
  for (const Case c : {Case{std::tan(5.0 * kPi / 180.0), 0.0}, Case{0.03, 0.04}, Case{-0.1, 0.02}}) {
    const cv::Mat z =
        testing::SampleSurface(size, kPx, [&](double x, double y) { return 200.0 + c.sx * x + c.sy * y; });
    auto t = MeasureTilt(z, All(size), kPx, nullptr);
    ASSERT_TRUE(t.ok()) << t.status().ToString();
    EXPECT_NEAR(t->tilt_deg, std::atan(std::hypot(c.sx, c.sy)) * 180.0 / kPi, 1e-5);
    EXPECT_NEAR(t->tilt_x_deg, std::atan(c.sx) * 180.0 / kPi, 1e-5);
    EXPECT_NEAR(t->azimuth_deg, std::atan2(c.sy, c.sx) * 180.0 / kPi, 1e-4);
  }
}

TEST(PlaneMeasuresTest, TiltUncertaintyCoversNearZeroTilt) {
  // A level flat with 0.05 um correlated noise: the measured tilt is |slope| of noise (Rayleigh,
  // never below 0). U = 2 sqrt(trace) must hold >= 93 % of 200 realisations (98 % expected for a
  // Rayleigh variable; 93 % leaves the binomial scatter room).
  const cv::Size size(80, 60);
  int covered = 0;
  for (int k = 0; k < 200; ++k) {
    const cv::Mat z = 200.0f + testing::CorrelatedNoise(size, 0.05, 7, 40 + k);
    const DepthNoiseModel m = Known(z, 0.05, 7);
    auto t = MeasureTilt(z, All(size), kPx, &m);
    ASSERT_TRUE(t.ok());
    covered += t->tilt_deg <= 2.0 * t->uncertainty.standard_uncertainty;
  }
  std::printf("zero tilt: covered %d / 200\n", covered);
  EXPECT_GE(covered, 186);
}

TEST(PlaneMeasuresTest, FlatnessIsThePeakToValleyAboutTheLeastSquaresPlane) {
  // 0.8 um cosine over 8 whole periods, symmetric about the centre, on a 3 degree tilt: the
  // plane takes the tilt only, the deviations are the cosine: flatness = 2 * 0.8 cos(pi / 50)
  // (samples half a pixel off the crests) times cos(tilt) (perpendicular to the plane).
  const cv::Size size(400, 40);
  const double slope = std::tan(3.0 * kPi / 180.0), xc = 200 * kPx;
  const cv::Mat z = testing::SampleSurface(
      size, kPx, [&](double x, double) { return 250.0 + slope * x + 0.8 * std::cos(2 * kPi * (x - xc) / (50 * kPx)); });
  auto f = MeasureFlatness(z, All(size), kPx, nullptr);
  ASSERT_TRUE(f.ok()) << f.status().ToString();
  const double expected = 1.6 * std::cos(kPi / 50) * std::cos(3.0 * kPi / 180.0);
  EXPECT_NEAR(f->flatness_um, expected, 1e-4);
  EXPECT_NEAR(f->peak_um, f->valley_um, 1e-4);
}

TEST(PlaneMeasuresTest, VolumeAboveAndBelowAReference) {
  const cv::Size size(120, 100);
  // Flat at 200 um with a raised disc (+3 um, radius 15 px) and a square pit (-2 um, 10 x 10 px).
  cv::Mat z(size, CV_32FC1, cv::Scalar(200.0f));
  cv::Mat disc(size, CV_8UC1, cv::Scalar(0));
  cv::circle(disc, cv::Point(40, 50), 15, cv::Scalar(255), cv::FILLED);
  z.setTo(203.0f, disc);
  z(cv::Rect(80, 45, 10, 10)).setTo(198.0f);
  const double a = kPx * kPx;
  const double above = 3.0 * cv::countNonZero(disc) * a, below = 2.0 * 100 * a;
  VolumeOptions height;
  height.reference = VolumeReference::kHeight;
  height.reference_height_um = 200.0;
  auto v = MeasureVolume(z, All(size), cv::Mat(), kPx, height, nullptr);
  ASSERT_TRUE(v.ok()) << v.status().ToString();
  EXPECT_NEAR(v->above_um3, above, 1e-3 * above);  // float depths: 203 - 200 rounds at 1e-5
  EXPECT_NEAR(v->below_um3, below, 1e-3 * below);
  EXPECT_NEAR(v->above_mm3(), above * 1e-9, 1e-12);
  // Reference = the plane of a ring of flat land around the disc: the same above-volume.
  cv::Mat ring(size, CV_8UC1, cv::Scalar(0));
  cv::circle(ring, cv::Point(40, 50), 30, cv::Scalar(255), cv::FILLED);
  cv::circle(ring, cv::Point(40, 50), 20, cv::Scalar(0), cv::FILLED);
  cv::Mat disc_region(size, CV_8UC1, cv::Scalar(0));
  cv::circle(disc_region, cv::Point(40, 50), 20, cv::Scalar(255), cv::FILLED);
  auto vr = MeasureVolume(z, disc_region, ring, kPx, VolumeOptions{}, nullptr);
  ASSERT_TRUE(vr.ok()) << vr.status().ToString();
  EXPECT_NEAR(vr->above_um3, above, 1e-3 * above);
  EXPECT_NEAR(vr->below_um3, 0.0, 1e-3 * above);
  // A hole in the disc's flat top is filled from its neighbours (all 3 um up): the same volume.
  cv::Mat region(size, CV_8UC1, cv::Scalar(0));
  region(cv::Rect(20, 30, 40, 40)).setTo(255);  // holds the whole disc
  auto full = MeasureVolume(z, region, cv::Mat(), kPx, height, nullptr);
  cv::Mat holed = z.clone();
  holed(cv::Rect(38, 48, 3, 3)).setTo(NAN);
  auto part = MeasureVolume(holed, region, cv::Mat(), kPx, height, nullptr);
  ASSERT_TRUE(full.ok() && part.ok());
  EXPECT_EQ(part->measured_pixels, 1600u - 9u);
  EXPECT_NEAR(part->above_um3, full->above_um3, 1e-3 * above);
  // Pixels beyond the fill's reach (> ~12 px from any depth) count as the region's mean: a
  // region that is half disc-free flat, half missing, is scaled by 2.
  cv::Mat half(size, CV_32FC1, cv::Scalar(NAN));
  z(cv::Rect(20, 30, 40, 40)).copyTo(half(cv::Rect(20, 30, 40, 40)));
  cv::Mat far(size, CV_8UC1, cv::Scalar(0));
  far(cv::Rect(20, 30, 40, 70)).setTo(255);  // rows 30..99: rows 70..99 have no depth
  auto scaled = MeasureVolume(half, far, cv::Mat(), kPx, height, nullptr);
  ASSERT_TRUE(scaled.ok()) << scaled.status().ToString();
  // 1600 measured pixels, the missing rows within the fill's reach (weight > 0.05: ~1.6 sigma =
  // 7 rows, filled from the flat land: 0 um) and the rest scaled: full * 2800 / (1600 + filled).
  EXPECT_GT(scaled->above_um3, full->above_um3 * 2800.0 / 2200.0);
  EXPECT_LT(scaled->above_um3, full->above_um3 * 2800.0 / 1600.0);
}

TEST(PlaneMeasuresTest, VolumeUncertaintyCoversNoise) {
  const cv::Size size(100, 80);
  cv::Mat base(size, CV_32FC1, cv::Scalar(200.0f));
  cv::circle(base, cv::Point(50, 40), 15, cv::Scalar(202.0), cv::FILLED);
  VolumeOptions height;
  height.reference = VolumeReference::kHeight;
  height.reference_height_um = 200.0;
  auto truth = MeasureVolume(base, All(size), cv::Mat(), kPx, height, nullptr);
  ASSERT_TRUE(truth.ok());
  int covered = 0;
  for (int k = 0; k < 20; ++k) {
    const cv::Mat z = base + testing::CorrelatedNoise(size, 0.05, 7, 300 + k);
    const DepthNoiseModel m = Known(z, 0.05, 7);
    auto v = MeasureVolume(z, All(size), cv::Mat(), kPx, height, &m);
    ASSERT_TRUE(v.ok()) << v.status().ToString();
    // Above the 200 um reference the flat's noise adds ~0.02 um x area (a bias the Monte Carlo's
    // doubling estimate must hold).
    covered += std::abs(v->above_um3 - truth->above_um3) <= 2.0 * v->above_uncertainty.standard_uncertainty;
  }
  std::printf("volume above a noisy flat: covered %d / 20\n", covered);
  EXPECT_GE(covered, 18);
}

}  // namespace
}  // namespace inspection
