// Natural focal stacks (devices/sim/natural_scene.h): deterministic per seed, truth in frame
// units where focus actually peaks, and defocused foregrounds spreading over the background
// (layered occlusion), which a per-pixel blur of one depth map would not do.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/io/colour.h"
#include "core/sff/focus_measure.h"
#include "devices/sim/natural_scene.h"

namespace inspection {
namespace {

NaturalSceneOptions Small(uint32_t seed) {
  NaturalSceneOptions o;
  o.size = {128, 112};
  o.frames = 16;
  o.seed = seed;
  return o;
}

TEST(NaturalSceneTest, DeterministicPerSeedWithTruthInsideTheStack) {
  auto a = RenderNaturalScene(Small(3));
  auto b = RenderNaturalScene(Small(3));
  auto c = RenderNaturalScene(Small(4));
  ASSERT_TRUE(a.ok() && b.ok() && c.ok()) << a.status().ToString();
  ASSERT_EQ(a->frames.size(), 16u);
  EXPECT_EQ(a->frames[0].type(), CV_8UC3);
  EXPECT_EQ(a->frames[0].size(), cv::Size(128, 112));
  for (size_t k = 0; k < a->frames.size(); ++k) EXPECT_EQ(cv::norm(a->frames[k], b->frames[k], cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a->depth_frames, b->depth_frames, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a->frames[5], c->frames[5], cv::NORM_L1), 0.0);
  EXPECT_EQ(a->description, b->description);

  double lo, hi;
  cv::minMaxLoc(a->depth_frames, &lo, &hi);
  EXPECT_GE(lo, 0.5);  // every surface comes into focus inside the stack
  EXPECT_LE(hi, 15 - 0.5);
  EXPECT_GT(hi - lo, 6);  // and the scene is deep
  const double textured = cv::countNonZero(a->textured) / double(a->textured.total());
  EXPECT_GT(textured, 0.3);
  EXPECT_LT(textured, 0.9);                            // large textureless areas
  EXPECT_GT(cv::countNonZero(a->occlusion_edge), 50);  // depth discontinuities

  NaturalSceneOptions g = Small(3);
  g.colour = false;
  g.bit_depth = 16;
  auto grey = RenderNaturalScene(g);
  ASSERT_TRUE(grey.ok());
  EXPECT_EQ(grey->frames[0].type(), CV_16UC1);
  EXPECT_EQ(cv::norm(grey->depth_frames, a->depth_frames, cv::NORM_INF), 0.0);
}

TEST(NaturalSceneTest, FocusPeaksAtTheTruthOnTexturedSurfaces) {
  for (uint32_t seed : {1u, 2u}) {
    NaturalSceneOptions o = Small(seed);
    o.size = {224, 192};
    auto s = RenderNaturalScene(o);
    ASSERT_TRUE(s.ok());
    // Per pixel, the frame with the largest Tenengrad 5x5 of the luminance.
    cv::Mat best(s->depth_frames.size(), CV_32F, cv::Scalar(-1.f)), best_k(s->depth_frames.size(), CV_32F);
    for (size_t k = 0; k < s->frames.size(); ++k) {
      cv::Mat f;
      ASSERT_TRUE(ComputeFocusMeasure(LuminanceOf(s->frames[k]).value(), FocusMeasure::kTenengrad, 5, &f).ok());
      const cv::Mat better = f > best;
      f.copyTo(best, better);
      best_k.setTo(float(k), better);
    }
    // Clearly textured: local standard deviation of the in-focus luminance >= 4 grey levels
    // (textured materials include faint ones, where a single-pixel argmax is noise-bound).
    cv::Mat lum, mean, sq;
    LuminanceOf(s->all_in_focus).value().convertTo(lum, CV_32F);
    cv::blur(lum, mean, cv::Size(7, 7));
    cv::blur(lum.mul(lum), sq, cv::Size(7, 7));
    // Away from occlusion edges by more than the largest blur radius here (~12 px): near them
    // a defocused foreground edge can out-score the background's own texture (the occlusion
    // error every SFF method has, measured by the evaluation, not the renderer's truth).
    cv::Mat near_edge;
    cv::dilate(s->occlusion_edge, near_edge, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(25, 25)));
    std::vector<double> err;
    for (int y = 8; y < best.rows - 8; ++y)
      for (int x = 8; x < best.cols - 8; ++x) {
        const float m = mean.at<float>(y, x);
        if (!s->textured.at<uint8_t>(y, x) || near_edge.at<uint8_t>(y, x)) continue;
        if (sq.at<float>(y, x) - m * m < 16.f) continue;
        err.push_back(best_k.at<float>(y, x) - s->depth_frames.at<float>(y, x));
      }
    ASSERT_GT(err.size(), 500u);
    const size_t within = size_t(std::count_if(err.begin(), err.end(), [](double e) { return std::abs(e) <= 1.0; }));
    EXPECT_GT(within, 0.9 * err.size()) << "seed " << seed << ": " << within << " of " << err.size();
    std::nth_element(err.begin(), err.begin() + err.size() / 2, err.end());
    EXPECT_LE(std::abs(err[err.size() / 2]), 0.5) << "seed " << seed;  // no offset between truth and focus
  }
}

TEST(NaturalSceneTest, DefocusedForegroundSpreadsOverTheFocusedBackground) {
  auto s = RenderNaturalScene(Small(5));
  ASSERT_TRUE(s.ok());
  const cv::Mat& d = s->depth_frames;
  cv::Mat nearest;
  cv::erode(d, nearest, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(7, 7)));
  // Far-side pixels of an occlusion edge (a surface > 3 frames nearer within 3 px) seen in the
  // frame focused on them differ from the all-in-focus image much more than pixels far from
  // any edge do in their own focus frame: the nearer surface's blur covers them.
  double edge_sum = 0, inner_sum = 0;
  int edge_n = 0, inner_n = 0;
  for (int y = 8; y < d.rows - 8; ++y)
    for (int x = 8; x < d.cols - 8; ++x) {
      const int k = std::clamp(int(std::lround(d.at<float>(y, x))), 0, int(s->frames.size()) - 1);
      const cv::Vec3b f = s->frames[size_t(k)].at<cv::Vec3b>(y, x), a = s->all_in_focus.at<cv::Vec3b>(y, x);
      const double diff = (std::abs(f[0] - a[0]) + std::abs(f[1] - a[1]) + std::abs(f[2] - a[2])) / 3.0;
      if (d.at<float>(y, x) - nearest.at<float>(y, x) > 3.0) {
        edge_sum += diff;
        ++edge_n;
      } else if (!s->occlusion_edge.at<uint8_t>(y, x)) {
        inner_sum += diff;
        ++inner_n;
      }
    }
  ASSERT_GT(edge_n, 30);
  EXPECT_GT(edge_sum / edge_n, 2.0 * (inner_sum / inner_n)) << edge_sum / edge_n << " vs " << inner_sum / inner_n;
}

TEST(NaturalSceneTest, BadOptionsNameTheField) {
  NaturalSceneOptions o;
  o.frames = 2;
  EXPECT_NE(RenderNaturalScene(o).status().message().find("frames"), std::string::npos);
  o = NaturalSceneOptions{};
  o.size = {32, 300};
  EXPECT_NE(RenderNaturalScene(o).status().message().find("size"), std::string::npos);
  o = NaturalSceneOptions{};
  o.bit_depth = 12;
  EXPECT_NE(RenderNaturalScene(o).status().message().find("bit_depth"), std::string::npos);
}

}  // namespace
}  // namespace inspection
