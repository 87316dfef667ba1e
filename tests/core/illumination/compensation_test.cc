// Radiometric compensation on a synthetic projector-camera pair with an exact scatter matrix
// (each projector pixel lights a 3x3 camera block): eq. 5.11 recovers a known pattern, the
// iteration of eq. 5.5-5.6 brings a two-reflectance scene (one half saturating) to the target
// grey, the reflectance estimate over its window does not depend on how sharp the pattern is,
// and the prediction of eq. 5.12 extrapolates linearly.
#include "core/illumination/compensation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <utility>

namespace inspection {
namespace {

constexpr int kRatio = 3;
const cv::Size kProj{24, 16};
const cv::Size kCam{kProj.width * kRatio, kProj.height* kRatio};

// crf: Z = 128 * E * dt (linear camera), ln(E dt) = ln(Z / 128); Z = 0 clamped to ln(0.25/128).
CameraResponseFunction LinearCrf() {
  CameraResponseFunction c;
  c.levels = 256;
  for (int z = 0; z < 256; ++z) c.log_exposure.push_back(std::log(std::max(z, 1) / 128.0) - (z == 0 ? 1.0 : 0.0));
  return c;
}

// prf(i) = black + (1 - black) (i / 255)^2.
ProjectorResponseFunction SquarePrf() {
  ProjectorResponseFunction p;
  for (int i = 0; i < 256; ++i) p.relative_irradiance.push_back(0.002 + 0.998 * (i / 255.0) * (i / 255.0));
  return p;
}

ScatterMatrix BlockScatter() {
  ScatterMatrix s;
  s.camera_size = kCam;
  s.projector_size = kProj;
  s.projector_black_irradiance = 0.002;
  s.black_radiance = cv::Mat(kCam, CV_32FC1, cv::Scalar(0.002f));
  std::vector<Eigen::Triplet<float, int>> t;
  for (int y = 0; y < kCam.height; ++y) {
    for (int x = 0; x < kCam.width; ++x)
      t.emplace_back(y * kCam.width + x, (y / kRatio) * kProj.width + x / kRatio, 1.0f);
  }
  s.a.resize(kCam.area(), kProj.area());
  s.a.setFromTriplets(t.begin(), t.end());
  return s;
}

// Synthetic frame: Z = 128 * R * (A e_p + e) * dt, saturating at 255.
cv::Mat Render(const ScatterMatrix& s, const cv::Mat& irradiance, const cv::Mat& reflectance, double dt) {
  cv::Mat e = s.PredictRadiance(irradiance).value();
  cv::Mat z = e.mul(reflectance) * (128.0 * dt);
  cv::Mat out;
  z.convertTo(out, CV_8UC1);  // rounds and saturates
  return out;
}

TEST(CompensationTest, PseudoInverseRecoversSmoothPattern) {
  const auto crf = LinearCrf();
  const auto prf = SquarePrf();
  const auto s = BlockScatter();
  CompensationOptions o;
  o.pattern_cell_px = 1;
  o.camera_bin_px = 1;  // one unknown per projector pixel needs every camera row
  o.solver_iterations = 50;
  o.solver_tolerance = 1e-6;
  auto comp = Compensator::Create(crf, prf, s, o);
  ASSERT_TRUE(comp.ok()) << comp.status().ToString();
  cv::Mat truth(kProj, CV_32FC1);
  for (int v = 0; v < kProj.height; ++v) {
    for (int u = 0; u < kProj.width; ++u) truth.at<float>(v, u) = 0.2f + 0.6f * float(u) / kProj.width + 0.01f * v;
  }
  const cv::Mat scene = s.PredictRadiance(truth).value();
  const cv::Mat start(kProj, CV_32FC1, cv::Scalar(0.5f));
  int it = -1;
  double residual = 1;
  auto got = (*comp)->SolveIrradiance(scene, start, &it, &residual);
  ASSERT_TRUE(got.ok()) << got.status().ToString();
  double max_err = 0;
  cv::minMaxLoc(cv::abs(*got - truth), nullptr, &max_err);
  EXPECT_LT(max_err, 1e-4);
  EXPECT_GE(it, 0);
  EXPECT_LT(residual, 1e-5);
  // With the low-pass grid (cell 4) and 4x4 camera bins a linear pattern is still represented
  // exactly.
  o.pattern_cell_px = 4;
  o.camera_bin_px = 4;
  auto coarse = Compensator::Create(crf, prf, s, o);
  ASSERT_TRUE(coarse.ok());
  EXPECT_EQ((*coarse)->coarse_size(), cv::Size(7, 5));
  auto got4 = (*coarse)->SolveIrradiance(scene, start);
  ASSERT_TRUE(got4.ok());
  cv::minMaxLoc(cv::abs(*got4 - truth), nullptr, &max_err);
  EXPECT_LT(max_err, 2e-3);
}

TEST(CompensationTest, IterationReachesTargetOnHighDynamicRangeScene) {
  const auto crf = LinearCrf();
  const auto prf = SquarePrf();
  const auto s = BlockScatter();
  CompensationOptions o;
  o.pattern_cell_px = 2;
  o.solver_iterations = 30;
  auto comp = Compensator::Create(crf, prf, s, o);
  ASSERT_TRUE(comp.ok());
  // Left half dim (R = 1.2: grey 39 at pattern 128, irradiance ~0.25), right half bright
  // (R = 8: 128 * 8 * 0.25 = 258 saturates). Target 128 needs irradiance 0.83 and 0.125.
  cv::Mat refl(kCam, CV_32FC1, cv::Scalar(1.2f));
  refl(cv::Rect(kCam.width / 2, 0, kCam.width / 2, kCam.height)).setTo(8.0f);
  const double dt = 1.0;
  const cv::Mat desired(kCam, CV_32FC1, cv::Scalar(128.0f));
  cv::Mat irr = prf.IrradianceImage(cv::Mat(kProj, CV_8UC1, cv::Scalar(128)));
  cv::Mat frame = Render(s, irr, refl, dt);
  const double sat0 = double(cv::countNonZero(frame == 255)) / frame.total();
  EXPECT_GT(sat0, 0.45);
  for (int i = 0; i < 3; ++i) {
    auto st = (*comp)->Step(irr, frame, dt, desired);
    ASSERT_TRUE(st.ok()) << st.status().ToString();
    if (i == 0) {
      EXPECT_GT(st->mean_abs_error_grey, 40.0);
    }
    irr = prf.IrradianceImage(st->pattern);  // what the projector can show
    frame = Render(s, irr, refl, dt);
  }
  // After 3 corrections: no saturation, every pixel within 4 grey levels of 128 away from the
  // reflectance edge (the low-pass cannot follow the step exactly).
  EXPECT_EQ(cv::countNonZero(frame == 255), 0);
  cv::Mat dev;
  cv::absdiff(frame, cv::Scalar(128), dev);
  const int edge = kCam.width / 2;
  for (int y = 0; y < kCam.height; ++y) {
    for (int x = 0; x < kCam.width; ++x) {
      // Within three coarse cells of the step the smooth low-pass basis cannot follow it.
      if (std::abs(x - edge) < 3 * o.pattern_cell_px * kRatio) continue;
      ASSERT_LE(dev.at<uint8_t>(y, x), 4) << "at " << x << "," << y;
    }
  }
}

// The root of the ADAPT family's depth bias (docs/illumination.md): A is the in-focus
// transport, but a defocused frame shows the pattern blurred. Per pixel, the reflectance of a
// uniform surface under a checkerboard then comes out with the checkerboard inverted (blur(P) / P);
// over the reflectance window (one pattern period) it is the same sharp or blurred.
TEST(CompensationTest, ReflectanceEstimateIsTheSameForASharpAndABlurredPattern) {
  const auto crf = LinearCrf();
  const auto prf = SquarePrf();
  const auto s = BlockScatter();
  EXPECT_NEAR(CameraPxPerProjectorPx(s), double(kRatio), 1e-12);
  // Checkerboard of 2-projector-pixel cells (period 12 camera px) at irradiance 0.15 / 0.45.
  cv::Mat irr(kProj, CV_32FC1);
  for (int v = 0; v < kProj.height; ++v) {
    for (int u = 0; u < kProj.width; ++u) irr.at<float>(v, u) = ((u / 2 + v / 2) % 2 == 0) ? 0.45f : 0.15f;
  }
  const double dt = 1.0, reflectance = 2.0;
  const cv::Mat scene = s.PredictRadiance(irr).value();
  auto expose = [&](const cv::Mat& radiance) {
    cv::Mat out;
    cv::Mat(radiance * (128.0 * reflectance * dt)).convertTo(out, CV_8UC1);
    return out;
  };
  cv::Mat defocused;
  cv::GaussianBlur(scene, defocused, cv::Size(0, 0), 3.0, 3.0, cv::BORDER_REFLECT);
  const cv::Mat sharp_frame = expose(scene), blurred_frame = expose(defocused);
  const cv::Mat desired(kCam, CV_32FC1, cv::Scalar(128.0f));
  const cv::Rect inner(12, 12, kCam.width - 24, kCam.height - 24);
  auto estimate_range = [&](const Compensator& c, const cv::Mat& frame, ShownAt shown_at) {
    auto st = c.Step(irr, frame, dt, desired, cv::Mat(), shown_at);
    EXPECT_TRUE(st.ok()) << st.status().ToString();
    double lo = 0, hi = 0;
    cv::minMaxLoc(st->reflectance(inner), &lo, &hi);
    return std::pair{lo, hi};
  };
  CompensationOptions o;  // automatic window: two 2-px cells at 3 camera px per projector px
  auto comp = Compensator::Create(crf, prf, s, o);
  ASSERT_TRUE(comp.ok());
  EXPECT_EQ((*comp)->reflectance_window_px(), 11);  // nearest odd to 12
  for (const cv::Mat* frame : {&sharp_frame, &blurred_frame}) {
    const auto [lo, hi] = estimate_range(**comp, *frame, ShownAt::kNextZ);
    EXPECT_NEAR(lo, reflectance, 0.04 * reflectance);
    EXPECT_NEAR(hi, reflectance, 0.04 * reflectance);
  }
  // The thesis's per-pixel eq. 5.5 (a correction shown at the same z): right for the frame whose
  // focus state the pattern will light again, the pattern inverted for a blurred one.
  const auto [sharp_lo, sharp_hi] = estimate_range(**comp, sharp_frame, ShownAt::kSameZ);
  EXPECT_NEAR(sharp_lo, reflectance, 0.04 * reflectance);
  EXPECT_NEAR(sharp_hi, reflectance, 0.04 * reflectance);
  const auto [blur_lo, blur_hi] = estimate_range(**comp, blurred_frame, ShownAt::kSameZ);
  EXPECT_LT(blur_lo, 0.8 * reflectance);  // bright cells: blur(P) / P < 1
  EXPECT_GT(blur_hi, 1.4 * reflectance);  // dark cells
  // An explicit window; an even one is refused.
  o.reflectance_window_px = 1;
  auto per_pixel = Compensator::Create(crf, prf, s, o);
  ASSERT_TRUE(per_pixel.ok());
  EXPECT_EQ((*per_pixel)->reflectance_window_px(), 1);
  EXPECT_LT(estimate_range(**per_pixel, blurred_frame, ShownAt::kNextZ).first, 0.8 * reflectance);
  o.reflectance_window_px = 8;
  EXPECT_EQ(Compensator::Create(crf, prf, s, o).status().code(), StatusCode::kInvalidArgument);
}

TEST(CompensationTest, PredictionIsLinearExtrapolation) {
  cv::Mat a(2, 2, CV_32FC1, cv::Scalar(0.5f)), b(2, 2, CV_32FC1, cv::Scalar(0.4f));
  b.at<float>(1, 1) = 0.9f;
  auto p = PredictIrradiance(a, b, 0.5, 0.002);
  ASSERT_TRUE(p.ok());
  EXPECT_NEAR(p->at<float>(0, 0), 0.55f, 1e-6);
  EXPECT_NEAR(p->at<float>(1, 1), 0.3f, 1e-6);
  auto q = PredictIrradiance(a, b, 20.0, 0.002);
  ASSERT_TRUE(q.ok());
  EXPECT_NEAR(q->at<float>(0, 0), 1.0f, 1e-6);    // clamped to 1
  EXPECT_NEAR(q->at<float>(1, 1), 0.002f, 1e-6);  // clamped to the black floor
  EXPECT_EQ(PredictIrradiance(a, b, -1, 0).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
