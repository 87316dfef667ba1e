// Correlation focus measure (thesis 5.4.2, eq. 5.24-5.26): the NCC against a window computed by
// hand, the tiled streaming engine against the whole-frame reference (borders, tile seams),
// ISFF-FAST's first local maximum above the threshold and the work it skips, and bad input.
#include "core/sff/ncc_focus.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

cv::Mat RandomImage(cv::Size size, uint64_t seed, double lo = 20, double hi = 230, double blur = 0.8) {
  cv::RNG rng(seed);
  cv::Mat m(size, CV_32FC1);
  rng.fill(m, cv::RNG::UNIFORM, lo, hi);
  if (blur > 0) cv::GaussianBlur(m, m, {0, 0}, blur);
  return m;
}

cv::Mat To8U(const cv::Mat& f) {
  cv::Mat o;
  f.convertTo(o, CV_8U);
  return o;
}

// eq. 5.25 written out for the 7 x 7 window centred at (x0, y0) (inside the image); sigma_w: the
// frame patch's standard deviation.
double HandNcc(const cv::Mat& w8, const cv::Mat& t, int x0, int y0, double* sigma_w = nullptr) {
  double mw = 0, mt = 0;
  for (int dy = -3; dy <= 3; ++dy)
    for (int dx = -3; dx <= 3; ++dx) {
      mw += w8.at<uint8_t>(y0 + dy, x0 + dx);
      mt += t.at<float>(y0 + dy, x0 + dx);
    }
  mw /= 49;
  mt /= 49;
  double num = 0, sw = 0, st = 0;
  for (int dy = -3; dy <= 3; ++dy)
    for (int dx = -3; dx <= 3; ++dx) {
      const double a = w8.at<uint8_t>(y0 + dy, x0 + dx) - mw, b = t.at<float>(y0 + dy, x0 + dx) - mt;
      num += a * b;
      sw += a * a;
      st += b * b;
    }
  if (sigma_w) *sigma_w = std::sqrt(sw / 49);
  return num / std::sqrt(sw * st);
}

TEST(NccFocusTest, MatchesHandComputedWindow) {
  const cv::Mat t = RandomImage({24, 20}, 1);
  // A frame that is the template blurred, brightened and scaled, plus its own grain.
  cv::Mat w;
  cv::GaussianBlur(t, w, {0, 0}, 1.2);
  w = 0.6 * w + 40 + 0.3 * RandomImage({24, 20}, 2, -30, 30, 0);
  const cv::Mat w8 = To8U(w);
  cv::Mat ncc, focus, weighted;
  ASSERT_TRUE(ComputeNccFocus(w8, t, 7, 7, CorrelationFocusValue::kShiftedSum, &ncc, &focus).ok());
  ASSERT_TRUE(ComputeNccFocus(w8, t, 7, 7, CorrelationFocusValue::kContrastWeighted, &ncc, &weighted).ok());
  for (const cv::Point p : {cv::Point(3, 3), cv::Point(10, 9), cv::Point(20, 16)}) {
    EXPECT_NEAR(ncc.at<float>(p), HandNcc(w8, t, p.x, p.y), 1e-5) << p;
  }
  // A specific hand value: the window at (10, 9) correlates but is not identical.
  const double c = HandNcc(w8, t, 10, 9);
  EXPECT_GT(c, 0.3);
  EXPECT_LT(c, 0.999);
  // eq. 5.26 at (10, 9): sum over the 7 x 7 window of (C + 1).
  double fm = 0;
  for (int dy = -3; dy <= 3; ++dy)
    for (int dx = -3; dx <= 3; ++dx) fm += ncc.at<float>(9 + dy, 10 + dx) + 1.0;
  EXPECT_NEAR(focus.at<float>(9, 10), fm, 1e-3);
  // The contrast-weighted value: sum over U of C sigma_w (= cov(w, t) / sigma_t), by hand.
  double weighted_fm = 0;
  for (int dy = -3; dy <= 3; ++dy)
    for (int dx = -3; dx <= 3; ++dx) {
      double sigma_w = 0;
      const double c_here = HandNcc(w8, t, 10 + dx, 9 + dy, &sigma_w);
      weighted_fm += c_here * sigma_w;
    }
  EXPECT_GT(weighted_fm, 0.0);
  EXPECT_NEAR(weighted.at<float>(9, 10), weighted_fm, 1e-4 * weighted_fm);
  // At the corner U reflects the NCC map without repeating the edge (BORDER_REFLECT_101).
  double corner = 0;
  for (int dy = -3; dy <= 3; ++dy)
    for (int dx = -3; dx <= 3; ++dx) corner += ncc.at<float>(std::abs(dy), std::abs(dx)) + 1.0;
  EXPECT_NEAR(focus.at<float>(0, 0), corner, 1e-3);
}

TEST(NccFocusTest, InvariantToGainAndOffsetAndSignOfContrast) {
  const cv::Mat t = RandomImage({16, 16}, 3);
  cv::Mat ncc;
  ASSERT_TRUE(ComputeNccFocus(To8U(t * 0.5 + 60), t, 7, 1, CorrelationFocusValue::kShiftedSum, &ncc, nullptr).ok());
  EXPECT_NEAR(ncc.at<float>(8, 8), 1.0, 2e-3);  // 8-bit rounding only
  ASSERT_TRUE(ComputeNccFocus(To8U(250 - t), t, 7, 1, CorrelationFocusValue::kShiftedSum, &ncc, nullptr).ok());
  EXPECT_NEAR(ncc.at<float>(8, 8), -1.0, 2e-3);
  // A flat frame has no correlation (defined as 0, not NaN).
  ASSERT_TRUE(ComputeNccFocus(cv::Mat(16, 16, CV_8UC1, cv::Scalar(90)), t, 7, 1, CorrelationFocusValue::kShiftedSum,
                              &ncc, nullptr)
                  .ok());
  EXPECT_EQ(ncc.at<float>(8, 8), 0.0f);
}

// A stack whose frames are the template blurred by |z - z0(x)| at each pixel: a tilted plane.
struct TiltedStack {
  cv::Mat templ;
  std::vector<cv::Mat> frames;
  std::vector<double> z;
};

TiltedStack MakeTilted(cv::Size size, int n, uint64_t seed) {
  TiltedStack s;
  s.templ = RandomImage(size, seed);
  for (int k = 0; k < n; ++k) {
    s.z.push_back(10.0 * k);
    cv::Mat f(size, CV_32FC1);
    for (int x = 0; x < size.width; ++x) {
      const double focus_z = 10.0 * (n - 1) * (x + 0.5) / size.width;
      const double sigma = 0.3 + 0.12 * std::abs(s.z.back() - focus_z);
      cv::Mat col;
      cv::GaussianBlur(s.templ, col, {0, 0}, sigma);
      col.col(x).copyTo(f.col(x));
    }
    s.frames.push_back(To8U(f));
  }
  return s;
}

TEST(NccFocusTest, TiledEngineMatchesWholeFrameReference) {
  const TiltedStack s = MakeTilted({45, 29}, 7, 4);
  for (CorrelationFocusValue value : {CorrelationFocusValue::kContrastWeighted, CorrelationFocusValue::kShiftedSum})
    for (DepthInterpolation interp :
         {DepthInterpolation::kMaximum, DepthInterpolation::kGaussian, DepthInterpolation::kLineFit}) {
      // Reference: per-frame focus maps, discrete maximum and interpolated peak per pixel.
      std::vector<cv::Mat> fm(s.frames.size());
      for (size_t k = 0; k < s.frames.size(); ++k) {
        cv::Mat ncc;
        ASSERT_TRUE(ComputeNccFocus(s.frames[k], s.templ, 5, 3, value, &ncc, &fm[k]).ok());
      }
      NccFocusOptions o;
      o.focus_value = value;
      o.correlation_window_px = 5;
      o.summation_window_px = 3;
      o.interpolation = interp;
      o.min_confidence = 0.0;
      o.tile_px = 8;  // many tile seams in a 45 x 29 image
      o.threads = 3;
      auto engine = NccFocusEngine::Create(o, s.templ, CV_8UC1);
      ASSERT_TRUE(engine.ok()) << engine.status().ToString();
      const size_t bytes = (*engine)->state_bytes();
      for (size_t k = 0; k < s.frames.size(); ++k) ASSERT_TRUE((*engine)->PushFrame(s.frames[k], s.z[k]).ok());
      EXPECT_EQ((*engine)->state_bytes(), bytes);  // O(pixels), not O(pixels x frames)
      auto r = (*engine)->Finish();
      ASSERT_TRUE(r.ok()) << r.status().ToString();
      for (int y = 0; y < 29; ++y)
        for (int x = 0; x < 45; ++x) {
          std::vector<double> f;
          for (const cv::Mat& m : fm) f.push_back(m.at<float>(y, x));
          const FocusPeak p = InterpolateFocusCurve(interp, s.z, f, 2);
          ASSERT_NEAR(r->depth_um.at<float>(y, x), p.z_um, 2e-3)
              << x << "," << y << " " << CorrelationFocusValueName(value);
          const int m = int(std::max_element(f.begin(), f.end()) - f.begin());
          ASSERT_EQ((*engine)->max_index().at<int16_t>(y, x), m);
        }
      // The all-in-focus grey comes from the chosen frame.
      const int m = (*engine)->max_index().at<int16_t>(14, 20);
      EXPECT_EQ(r->all_in_focus.at<uint8_t>(14, 20), s.frames[m].at<uint8_t>(14, 20));
    }
}

TEST(NccFocusTest, FindsTheTiltedPlaneWithinAStep) {
  const TiltedStack s = MakeTilted({64, 24}, 9, 5);
  NccFocusOptions o;
  o.min_confidence = 0.0;  // 9 frames of a noise-free toy: the accuracy is under test here
  auto engine = NccFocusEngine::Create(o, s.templ, CV_8UC1);
  ASSERT_TRUE(engine.ok());
  for (size_t k = 0; k < s.frames.size(); ++k) ASSERT_TRUE((*engine)->PushFrame(s.frames[k], s.z[k]).ok());
  auto r = (*engine)->Finish();
  ASSERT_TRUE(r.ok());
  double err = 0;
  int n = 0;
  for (int x = 8; x < 56; ++x) {
    const double truth = 80.0 * (x + 0.5) / 64;
    const float d = r->depth_um.at<float>(12, x);
    ASSERT_TRUE(std::isfinite(d)) << x;
    err += std::abs(d - truth);
    ++n;
  }
  EXPECT_LT(err / n, 2.5);  // a quarter of the 10 um step
}

// Frames k = 0..5 built so that every pixel's NCC curve has a first local maximum at frame 1
// (C ~ 0.95) and a higher one at frame 4 (C = 1).
struct TwoPeaks {
  cv::Mat templ;
  std::vector<cv::Mat> frames;
  std::vector<double> z{0, 1, 2, 3, 4, 5};
};

TwoPeaks MakeTwoPeaks() {
  TwoPeaks s;
  s.templ = RandomImage({40, 40}, 6);
  cv::Mat blurred, very;
  cv::GaussianBlur(s.templ, blurred, {0, 0}, 1.5);
  cv::GaussianBlur(s.templ, very, {0, 0}, 4.0);
  const cv::Mat grain = RandomImage({40, 40}, 7, -12, 12, 0);
  s.frames = {To8U(very), To8U(s.templ + grain), To8U(blurred), To8U(very), To8U(s.templ), To8U(blurred)};
  return s;
}

// The two peaks are defined by the NCC, so these runs use the thesis's eq. 5.26 values.
StatusOr<DepthResult> RunTwoPeaks(const TwoPeaks& s, NccFocusOptions o, NccWorkCounters* work, cv::Mat* idx) {
  o.focus_value = CorrelationFocusValue::kShiftedSum;
  o.interpolation = DepthInterpolation::kMaximum;
  o.min_confidence = 0.0;
  auto e = NccFocusEngine::Create(o, s.templ, CV_8UC1);
  if (!e.ok()) return e.status();
  for (size_t k = 0; k < s.frames.size(); ++k) INSPECT_RETURN_IF_ERROR((*e)->PushFrame(s.frames[k], s.z[k]));
  auto r = (*e)->Finish();
  *work = (*e)->work();
  *idx = (*e)->max_index().clone();
  return r;
}

TEST(NccFocusTest, FastStopsAtFirstLocalMaximumAboveThreshold) {
  const TwoPeaks s = MakeTwoPeaks();
  cv::Mat ncc1;
  ASSERT_TRUE(ComputeNccFocus(s.frames[1], s.templ, 7, 1, CorrelationFocusValue::kShiftedSum, &ncc1, nullptr).ok());
  const double c1 = cv::mean(ncc1)[0];
  ASSERT_GT(c1, 0.85);
  ASSERT_LT(c1, 0.99);

  NccFocusOptions o;
  o.summation_window_px = 1;
  o.tile_px = 8;
  NccWorkCounters full_work, fast_work, strict_work;
  cv::Mat full_idx, fast_idx, strict_idx;
  auto full = RunTwoPeaks(s, o, &full_work, &full_idx);
  ASSERT_TRUE(full.ok());
  EXPECT_EQ(cv::countNonZero(full_idx != 4), 0);  // global maximum: the exact template
  EXPECT_EQ(full_work.tile_frames, full_work.tile_frames_full);
  EXPECT_EQ(full_work.stopped_pixels, 0);

  o.stop_at_first_maximum = true;
  o.stop_threshold = 0.8;
  auto fast = RunTwoPeaks(s, o, &fast_work, &fast_idx);
  ASSERT_TRUE(fast.ok());
  EXPECT_EQ(cv::countNonZero(fast_idx != 1), 0);
  // Every pixel stopped when frame 2 showed the drop: frames 3..5 were never correlated.
  EXPECT_EQ(fast_work.stopped_pixels, 40 * 40);
  EXPECT_EQ(fast_work.tile_frames, 3 * 25);
  EXPECT_EQ(fast_work.tile_frames_full, 6 * 25);
  EXPECT_EQ(fast_work.pixel_frames, 3 * 40 * 40);
  EXPECT_EQ(fast_work.computed_pixel_frames, 3 * 40 * 40);
  EXPECT_EQ(fast_work.computed_pixel_frames_full, 6 * 40 * 40);
  const cv::Mat fast_depth = fast->depth_um;
  EXPECT_FLOAT_EQ(fast_depth.at<float>(20, 20), 1.0f);

  // Above the first peak's correlation the search goes on to the second.
  o.stop_threshold = 0.999;
  auto strict = RunTwoPeaks(s, o, &strict_work, &strict_idx);
  ASSERT_TRUE(strict.ok());
  EXPECT_EQ(cv::countNonZero(strict_idx != 4), 0);
  EXPECT_GT(strict_work.tile_frames, fast_work.tile_frames);
}

TEST(NccFocusTest, FallsBackToGlobalMaximumBelowThreshold) {
  TwoPeaks s = MakeTwoPeaks();
  // No frame correlates above 0.9 now: every frame is blurred.
  cv::Mat b1, b2;
  cv::GaussianBlur(s.templ, b1, {0, 0}, 2.0);
  cv::GaussianBlur(s.templ, b2, {0, 0}, 3.0);
  s.frames = {To8U(b2), To8U(b1), To8U(b2), To8U(b2), To8U(b1 * 0.9 + 10), To8U(b2)};
  NccFocusOptions o;
  o.stop_at_first_maximum = true;
  o.stop_threshold = 0.999;
  NccWorkCounters work;
  cv::Mat idx;
  auto r = RunTwoPeaks(s, o, &work, &idx);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(work.stopped_pixels, 0);
  EXPECT_EQ(work.tile_frames, work.tile_frames_full);
  // Global maximum: frame 1 or 4 (the same blur), never a sigma-3 frame.
  EXPECT_EQ(cv::countNonZero((idx != 1) & (idx != 4)), 0);
}

TEST(NccFocusTest, RejectsBadInputNamingIt) {
  NccFocusOptions o;
  o.stop_threshold = 1.5;
  EXPECT_NE(o.Validate().message().find("fast_threshold"), std::string::npos);
  o.stop_threshold = 0.0;
  EXPECT_EQ(o.Validate().code(), StatusCode::kInvalidArgument);
  o = {};
  o.correlation_window_px = 6;
  EXPECT_NE(o.Validate().message().find("correlation_window_px"), std::string::npos);
  o = {};
  const cv::Mat t = RandomImage({16, 16}, 8);
  EXPECT_FALSE(NccFocusEngine::Create(o, t, CV_32FC1).ok());
  auto e = NccFocusEngine::Create(o, t, CV_8UC1);
  ASSERT_TRUE(e.ok());
  EXPECT_EQ((*e)->PushFrame(cv::Mat(15, 16, CV_8UC1), 0).code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE((*e)->PushFrame(To8U(t), 0).ok());
  ASSERT_TRUE((*e)->PushFrame(To8U(t), 1).ok());
  const Status back = (*e)->PushFrame(To8U(t), 0.5);
  EXPECT_EQ(back.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(back.message().find("frame 2"), std::string::npos);
  EXPECT_EQ((*e)->Finish().status().code(), StatusCode::kInvalidArgument);  // 2 frames
}

}  // namespace
}  // namespace inspection
