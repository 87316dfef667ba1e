// The post-processing pipeline (core/sff/depth_postprocess.h): threshold, consistency, refinement,
// fill, in that order, on a map whose good and bad pixels are known.
#include "core/sff/depth_postprocess.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace inspection {
namespace {

// A tilted plane (depth 100 + 0.5 x um, z steps of 2 um) measured with confidence 0.9, except a
// block of noise peaks (confidence 0.8: the curve's own SNR is fooled) and a textureless block
// (confidence 0.1).
DepthResult Synthetic() {
  DepthResult r;
  const cv::Size size(48, 40);
  r.depth_um.create(size, CV_32F);
  r.confidence = cv::Mat(size, CV_32F, cv::Scalar(0.9f));
  r.all_in_focus = cv::Mat(size, CV_8UC1, cv::Scalar(120));
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(100.f, 140.f);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      r.depth_um.at<float>(y, x) = 100.f + 0.5f * x;
      if (y >= 26 && x < 14) r.depth_um.at<float>(y, x) = u(rng);
    }
  r.confidence(cv::Rect(30, 0, 18, 12)).setTo(0.1f);
  r.frame_count = 30;
  return r;
}

std::vector<double> Z() {
  std::vector<double> z;
  for (int k = 0; k < 30; ++k) z.push_back(90.0 + 2.0 * k);
  return z;
}

TEST(DepthPostProcessTest, DefaultsRejectLowConfidenceAndInconsistentPixelsOnly) {
  DepthResult raw = Synthetic();
  // The threshold is inclusive, in float: exactly 0.4f is kept, the float just below is not.
  raw.confidence.at<float>(2, 2) = 0.4f;
  raw.confidence.at<float>(2, 3) = std::nextafter(0.4f, 0.f);
  const cv::Mat raw_depth = raw.depth_um.clone(), raw_confidence = raw.confidence.clone();
  DepthPostProcessFigures figures;
  auto r = PostProcessDepth(raw, Z(), 7, DepthPostProcessOptions{}, &figures);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  // The input is left as it was (the result has its own pixels).
  EXPECT_EQ(cv::norm(raw.depth_um, raw_depth, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(raw.confidence, raw_confidence, cv::NORM_INF), 0.0);
  EXPECT_FALSE(std::isnan(r->depth_um.at<float>(2, 2)));
  EXPECT_TRUE(std::isnan(r->depth_um.at<float>(2, 3)));
  // Rejected by consistency = above the threshold and now without depth, with confidence 0.
  const cv::Mat above = raw.confidence >= 0.4f, rejected = above & (r->confidence == 0.f);
  EXPECT_GT(cv::countNonZero(rejected), 0);
  EXPECT_EQ(cv::countNonZero(rejected & (r->depth_um == r->depth_um)), 0);
  EXPECT_NEAR(figures.consistency_rejected_fraction, double(cv::countNonZero(rejected)) / rejected.total(), 1e-12);
  // Low confidence: NaN, confidence kept (it says why).
  EXPECT_TRUE(std::isnan(r->depth_um.at<float>(5, 40)));
  EXPECT_FLOAT_EQ(r->confidence.at<float>(5, 40), 0.1f);
  // Noise block: NaN and confidence 0, as is the plane within radius 4 (window 7 / 2 + 1) of it.
  EXPECT_TRUE(std::isnan(r->depth_um.at<float>(32, 5)));
  EXPECT_EQ(r->confidence.at<float>(32, 5), 0.f);
  EXPECT_TRUE(std::isnan(r->depth_um.at<float>(32, 17)));
  EXPECT_FALSE(std::isnan(r->depth_um.at<float>(32, 19)));
  // The plane is kept as it was: consistency ignores its slope.
  EXPECT_EQ(r->depth_um.at<float>(10, 10), 105.f);
  EXPECT_EQ(r->depth_um.at<float>(39, 47), 100.f + 0.5f * 47);
  const double kept = double(cv::countNonZero(r->depth_um == r->depth_um)) / r->depth_um.total();
  EXPECT_NEAR(r->valid_fraction, kept, 1e-12);
  EXPECT_GT(r->valid_fraction, 0.6);
  EXPECT_LT(r->valid_fraction, 0.8);

  // Without consistency, the noise block survives the threshold.
  DepthPostProcessOptions plain;
  plain.consistency = false;
  auto p = PostProcessDepth(raw, Z(), 7, plain);
  ASSERT_TRUE(p.ok());
  EXPECT_FALSE(std::isnan(p->depth_um.at<float>(32, 5)));
}

TEST(DepthPostProcessTest, FillCompletesTheMapAndLeavesMeasuredPixels) {
  const DepthResult raw = Synthetic();
  DepthPostProcessOptions o;
  o.fill_low_confidence = true;
  o.refinement.method = DepthRefinement::kWeightedMedian;
  auto r = PostProcessDepth(raw, Z(), 7, o);
  ASSERT_TRUE(r.ok());
  EXPECT_DOUBLE_EQ(r->valid_fraction, 1.0);
  EXPECT_EQ(r->depth_um.at<float>(10, 10), 105.f);  // the median of a plane's window is the plane
  // The filled noise block lies within the plane's range there (x < 14: 100..107).
  for (int y = 26; y < 40; ++y)
    for (int x = 0; x < 14; ++x) {
      EXPECT_GE(r->depth_um.at<float>(y, x), 99.f);
      EXPECT_LE(r->depth_um.at<float>(y, x), 112.f);
    }
}

TEST(DepthPostProcessTest, BadInputIsNamed) {
  const DepthResult raw = Synthetic();
  DepthPostProcessOptions o;
  o.min_confidence = 2;
  EXPECT_NE(PostProcessDepth(raw, Z(), 7, o).status().message().find("min_confidence"), std::string::npos);
  o = DepthPostProcessOptions{};
  EXPECT_NE(PostProcessDepth(raw, {5.0}, 7, o).status().message().find("z_um"), std::string::npos);
  o.consistency_options.max_residual_z_steps = -1;
  EXPECT_NE(PostProcessDepth(raw, Z(), 7, o).status().message().find("max_residual_z_steps"), std::string::npos);
  EXPECT_EQ(PostProcessDepth(DepthResult{}, Z(), 7, DepthPostProcessOptions{}).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
