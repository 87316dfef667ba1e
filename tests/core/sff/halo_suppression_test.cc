// Halo suppression (core/sff/halo_suppression.h): on a bright object in front of a dark
// background (tests/core/halo_scene_synthetic.h) the all-in-focus error and the post-processed
// depth error in the halo band fall; pixels it does not move are the engine's bit for bit; a
// stack without a depth jump comes back unchanged; bad options and frames name what is wrong.
#include "core/sff/halo_suppression.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/sff/depth_postprocess.h"
#include <opencv2/imgproc.hpp>

#include "tests/core/halo_scene_synthetic.h"
#include "tests/core/sff_synthetic.h"

namespace inspection {
namespace {

using testing_halo::HaloScene;
using testing_halo::HaloSceneOptions;

using BandError = testing_halo::HaloBandError;

BandError HaloBandError(const HaloScene& s, const DepthResult& r) {
  return testing_halo::HaloBandErrorOf(s, r.depth_um, r.all_in_focus);
}

std::function<StatusOr<cv::Mat>(int)> FramesOf(const std::vector<cv::Mat>& frames) {
  return [&frames](int i) -> StatusOr<cv::Mat> { return frames[size_t(i)]; };
}

SffOptions Unthresholded() {
  SffOptions o;
  o.min_confidence = 0.0;
  return o;
}

TEST(HaloSuppressionTest, HaloBandErrorFallsOnABrightObjectOverADarkBackground) {
  HaloSceneOptions o;
  o.seed = 3;
  const HaloScene s = testing_halo::RenderHaloScene(o);
  auto raw = SffEngine::ReconstructInMemory(Unthresholded(), s.frames, s.z_um);
  ASSERT_TRUE(raw.ok()) << raw.status().ToString();
  HaloSuppressionFigures f;
  auto fixed = SuppressHalos(*raw, FramesOf(s.frames), s.z_um, Unthresholded(), {}, &f);
  ASSERT_TRUE(fixed.ok()) << fixed.status().ToString();
  // The server's post-processing (threshold + consistency) after each.
  auto post_before = PostProcessDepth(*raw, s.z_um, 7, {});
  auto post_after = PostProcessDepth(*fixed, s.z_um, 7, {});
  ASSERT_TRUE(post_before.ok() && post_after.ok());
  const BandError before = HaloBandError(s, *raw), after = HaloBandError(s, *fixed);
  const BandError pb = HaloBandError(s, *post_before), pa = HaloBandError(s, *post_after);
  std::printf("halo band: depth RMSE %.2f -> %.2f frames (post-processed %.2f -> %.2f on %.1f -> %.1f %%), AIF RMS "
              "%.2f -> %.2f grey; moved %.2f %% of %.1f %%\n",
              before.depth_rmse_frames, after.depth_rmse_frames, pb.depth_rmse_frames, pa.depth_rmse_frames,
              pb.valid_percent, pa.valid_percent, before.aif_rms, after.aif_rms, 100 * f.reassigned_fraction,
              100 * f.candidate_fraction);
  // The engine's halo: background pixels 4..13 px from the edge are off by many frames, and the
  // all-in-focus image shows the object's blur there.
  EXPECT_GT(before.depth_rmse_frames, 5.0);
  EXPECT_LT(after.aif_rms, 0.95 * before.aif_rms);
  EXPECT_LE(after.depth_rmse_frames, before.depth_rmse_frames);
  EXPECT_LT(pa.depth_rmse_frames, 0.9 * pb.depth_rmse_frames);  // measured 0.37 -> 0.31
  EXPECT_GE(pa.valid_percent, 0.9 * pb.valid_percent);
  EXPECT_GT(f.reassigned_fraction, 0.01);
  // Only moved pixels change (depth or all-in-focus); confidence never does.
  cv::Mat changed = (raw->depth_um != fixed->depth_um) | (raw->all_in_focus != fixed->all_in_focus);
  EXPECT_LE(cv::countNonZero(changed), std::lround(f.reassigned_fraction * double(raw->depth_um.total())));
  EXPECT_EQ(cv::norm(raw->confidence, fixed->confidence, cv::NORM_INF), 0.0);

  // With the surface's mean depth for pixels without a peak of their own, the unthresholded
  // depth error in the band falls too.
  HaloSuppressionOptions fill;
  fill.depth_from_surface_without_peak = true;
  auto filled = SuppressHalos(*raw, FramesOf(s.frames), s.z_um, Unthresholded(), fill);
  ASSERT_TRUE(filled.ok()) << filled.status().ToString();
  const BandError ff = HaloBandError(s, *filled);
  std::printf("with depth_from_surface_without_peak: depth RMSE %.2f -> %.2f frames\n", before.depth_rmse_frames,
              ff.depth_rmse_frames);
  EXPECT_LT(ff.depth_rmse_frames, 0.85 * before.depth_rmse_frames);
}

TEST(HaloSuppressionTest, StackWithoutADepthJumpIsUnchanged) {
  std::vector<double> z;
  for (int i = 0; i < 21; ++i) z.push_back(2.0 * i);
  const testing::SyntheticStack s = testing::TiltedPlaneStack({96, 80}, z, 12.0, 0.05, 0.02);
  auto raw = SffEngine::ReconstructInMemory(Unthresholded(), s.frames, z);
  ASSERT_TRUE(raw.ok()) << raw.status().ToString();
  HaloSuppressionFigures f;
  auto fixed = SuppressHalos(*raw, FramesOf(s.frames), z, Unthresholded(), {}, &f);
  ASSERT_TRUE(fixed.ok()) << fixed.status().ToString();
  EXPECT_EQ(f.candidate_fraction, 0.0);  // the plane spans < 4 frames within any 31 px window
  EXPECT_EQ(f.reassigned_fraction, 0.0);
  EXPECT_EQ(cv::norm(raw->all_in_focus, fixed->all_in_focus, cv::NORM_INF), 0.0);
  cv::Mat differs = raw->depth_um != fixed->depth_um;
  EXPECT_EQ(cv::countNonZero(differs), 0);
}

TEST(HaloSuppressionTest, BadOptionsNameTheField) {
  const std::pair<void (*)(HaloSuppressionOptions&), const char*> cases[] = {
      {[](HaloSuppressionOptions& o) { o.band_radius_px = 1; }, "band_radius_px"},
      {[](HaloSuppressionOptions& o) { o.layer_half_width_frames = 5; }, "layer_half_width_frames"},
      {[](HaloSuppressionOptions& o) { o.min_jump_frames = 3; }, "min_jump_frames"},
      {[](HaloSuppressionOptions& o) { o.min_layer_support = 0; }, "min_layer_support"},
      {[](HaloSuppressionOptions& o) { o.max_other_layer_ratio = 1; }, "max_other_layer_ratio"},
      {[](HaloSuppressionOptions& o) { o.min_layer_focus_ratio = 0; }, "min_layer_focus_ratio"},
      {[](HaloSuppressionOptions& o) { o.min_own_peak_ratio = NAN; }, "min_own_peak_ratio"},
      {[](HaloSuppressionOptions& o) { o.min_confidence = 1; }, "min_confidence"},
  };
  EXPECT_TRUE(HaloSuppressionOptions{}.Validate().ok());
  for (const auto& [set, field] : cases) {
    HaloSuppressionOptions o;
    set(o);
    const Status s = o.Validate();
    ASSERT_FALSE(s.ok()) << field;
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << field;
    EXPECT_NE(s.message().find(field), std::string::npos) << s.ToString();
  }
}

TEST(HaloSuppressionTest, FrameOfAnotherSizeNamesTheFrame) {
  HaloSceneOptions o;
  o.size = {96, 96};
  o.frames = 12;
  o.foreground_frame = 2;
  o.background_frame = 9;
  const HaloScene s = testing_halo::RenderHaloScene(o);
  auto raw = SffEngine::ReconstructInMemory(Unthresholded(), s.frames, s.z_um);
  ASSERT_TRUE(raw.ok()) << raw.status().ToString();
  std::vector<cv::Mat> bad = s.frames;
  bad[5] = cv::Mat(48, 48, CV_8UC1, cv::Scalar(0));
  auto r = SuppressHalos(*raw, FramesOf(bad), s.z_um, Unthresholded(), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("frame 5"), std::string::npos) << r.status().ToString();
  HaloSuppressionOptions wrong;
  wrong.band_radius_px = 0;
  auto w = SuppressHalos(*raw, FramesOf(s.frames), s.z_um, Unthresholded(), wrong);
  ASSERT_FALSE(w.ok());
  EXPECT_NE(w.status().message().find("halo_suppression: band_radius_px"), std::string::npos) << w.status().ToString();
}

// Colour stacks: focus on the luminance, the all-in-focus value taken from every channel of the
// chosen frame. Grey frames replicated to BGR (luminance = grey exactly) give the grey result.
TEST(HaloSuppressionTest, ColourFramesGiveTheGreyResultInEveryChannel) {
  HaloSceneOptions o;
  o.seed = 3;
  const HaloScene s = testing_halo::RenderHaloScene(o);
  auto raw = SffEngine::ReconstructInMemory(Unthresholded(), s.frames, s.z_um);
  ASSERT_TRUE(raw.ok()) << raw.status().ToString();
  HaloSuppressionFigures grey_figures, colour_figures;
  auto grey = SuppressHalos(*raw, FramesOf(s.frames), s.z_um, Unthresholded(), {}, &grey_figures);
  ASSERT_TRUE(grey.ok()) << grey.status().ToString();
  std::vector<cv::Mat> bgr(s.frames.size());
  for (size_t i = 0; i < s.frames.size(); ++i) cv::cvtColor(s.frames[i], bgr[i], cv::COLOR_GRAY2BGR);
  DepthResult raw_colour = *raw;
  cv::cvtColor(raw->all_in_focus, raw_colour.all_in_focus, cv::COLOR_GRAY2BGR);
  auto colour = SuppressHalos(raw_colour, FramesOf(bgr), s.z_um, Unthresholded(), {}, &colour_figures);
  ASSERT_TRUE(colour.ok()) << colour.status().ToString();
  ASSERT_GT(grey_figures.reassigned_fraction, 0.01);
  EXPECT_EQ(colour_figures.reassigned_fraction, grey_figures.reassigned_fraction);
  EXPECT_EQ(cv::countNonZero(colour->depth_um != grey->depth_um), 0);
  ASSERT_EQ(colour->all_in_focus.type(), CV_8UC3);
  std::vector<cv::Mat> channels;
  cv::split(colour->all_in_focus, channels);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(cv::norm(channels[size_t(c)], grey->all_in_focus, cv::NORM_INF), 0.0) << c;
  // A grey frame where the all-in-focus image is colour names the frame.
  std::vector<cv::Mat> mixed = bgr;
  mixed[4] = s.frames[4];
  auto bad = SuppressHalos(raw_colour, FramesOf(mixed), s.z_um, Unthresholded(), {});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("frame 4"), std::string::npos) << bad.status().ToString();
}

}  // namespace
}  // namespace inspection
