// Dense depth (core/sff/dense_depth.h) on maps whose true depth is known.
#include "core/sff/dense_depth.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/sff/depth_postprocess.h"

namespace inspection {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();

// Two surfaces side by side: left half dark at 100 um, right half bright at 200 um. Each half
// is measured only in a sparse grid (every 8th pixel); the guide's edge must keep the halves apart.
TEST(DenseDepthTest, FillsEveryPixelAndStopsAtTheGuideEdge) {
  const cv::Size size(96, 64);
  cv::Mat guide(size, CV_8UC1, cv::Scalar(40));
  guide(cv::Rect(48, 0, 48, 64)).setTo(220);
  cv::Mat depth(size, CV_32FC1, cv::Scalar(kNan));
  for (int y = 0; y < size.height; y += 8)
    for (int x = 2; x < size.width; x += 8) depth.at<float>(y, x) = x < 48 ? 100.f : 200.f;
  auto dense = DensifyDepth(depth, cv::Mat(), guide, DenseDepthOptions{});
  ASSERT_TRUE(dense.ok()) << dense.status().ToString();
  ASSERT_EQ(cv::countNonZero(*dense == *dense), size.area());
  double max_left_err = 0, max_right_err = 0;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double v = dense->at<float>(y, x);
      if (x < 48) max_left_err = std::max(max_left_err, std::abs(v - 100.0));
      else max_right_err = std::max(max_right_err, std::abs(v - 200.0));
    }
  // Across the edge the guide's colour difference (180 levels, sigma 12) cuts the smoothing.
  EXPECT_LT(max_left_err, 2.0);
  EXPECT_LT(max_right_err, 2.0);
  // Measured pixels keep their values exactly.
  EXPECT_EQ(dense->at<float>(8, 10), 100.f);
  EXPECT_EQ(dense->at<float>(8, 50), 200.f);
}

// Moderate smoothing (lambda 256, sigma 12): the support stays local, so a hole takes the depths
// around it. (The default's lambda 4096, tuned on natural scenes where holes are large, spreads
// far: on this small map it is nearer a global weighted mean.)
DenseDepthOptions Local() {
  DenseDepthOptions o;
  o.lambda = 256.0;
  o.sigma_color = 12.0;
  return o;
}

// A plane with a large unmeasured hole in a uniform guide: the fit interpolates the plane.
TEST(DenseDepthTest, InterpolatesAPlaneAcrossAHole) {
  const cv::Size size(80, 60);
  cv::Mat guide(size, CV_16UC3, cv::Scalar(30000, 30000, 30000));
  cv::Mat depth(size, CV_32FC1), confidence(size, CV_32FC1, cv::Scalar(0.9f));
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) depth.at<float>(y, x) = 50.f + 0.25f * x;
  depth(cv::Rect(30, 20, 20, 20)).setTo(kNan);
  auto dense = DensifyDepth(depth, confidence, guide, Local());
  ASSERT_TRUE(dense.ok()) << dense.status().ToString();
  double max_err = 0;
  for (int y = 20; y < 40; ++y)
    for (int x = 30; x < 50; ++x) max_err = std::max(max_err, std::abs(dense->at<float>(y, x) - (50.0 + 0.25 * x)));
  // 20 px hole, slope 0.25 um/px: a nearest-edge fill would be off by up to 2.5 um.
  EXPECT_LT(max_err, 1.5);
}

TEST(DenseDepthTest, RejectsBadInputNamingIt) {
  cv::Mat depth(10, 10, CV_32FC1, cv::Scalar(1.f)), guide(10, 10, CV_8UC1, cv::Scalar(0));
  DenseDepthOptions bad;
  bad.lambda = 0;
  auto r = DensifyDepth(depth, cv::Mat(), guide, bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().ToString().find("dense.lambda"), std::string::npos);
  auto r2 = DensifyDepth(depth, cv::Mat(), cv::Mat(5, 5, CV_8UC1), DenseDepthOptions{});
  ASSERT_FALSE(r2.ok());
  EXPECT_NE(r2.status().ToString().find("guide"), std::string::npos);
  // Nothing measured: returned as it is.
  cv::Mat none(10, 10, CV_32FC1, cv::Scalar(kNan));
  auto r3 = DensifyDepth(none, cv::Mat(), guide, DenseDepthOptions{});
  ASSERT_TRUE(r3.ok());
  EXPECT_EQ(cv::countNonZero(*r3 == *r3), 0);
}

// Through the post-processing: every pixel has depth, inferred ones keep confidence below the
// threshold (the documented encoding of measured vs inferred).
TEST(DenseDepthTest, PostProcessDenseMarksInferredByConfidence) {
  DepthResult raw;
  const cv::Size size(40, 30);
  raw.depth_um.create(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) raw.depth_um.at<float>(y, x) = 100.f + 0.5f * x;
  raw.confidence = cv::Mat(size, CV_32FC1, cv::Scalar(0.9f));
  raw.confidence(cv::Rect(10, 10, 10, 10)).setTo(0.1f);
  raw.all_in_focus = cv::Mat(size, CV_8UC1, cv::Scalar(100));
  raw.frame_count = 30;
  std::vector<double> z;
  for (int k = 0; k < 30; ++k) z.push_back(90.0 + 2.0 * k);
  DepthPostProcessOptions o;
  o.consistency = false;
  o.dense = true;
  o.dense_options = Local();
  DepthPostProcessFigures figures;
  auto r = PostProcessDepth(raw, z, 7, o, &figures);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_DOUBLE_EQ(r->valid_fraction, 1.0);
  EXPECT_NEAR(figures.filled_fraction, 100.0 / size.area(), 1e-12);
  EXPECT_EQ(cv::countNonZero(r->confidence < 0.4f), 100);
  // The hole's centre: true 107.5 um. The normalised filter is a weighted mean of the measured
  // depths around it (constant, not linear, extrapolation), pulled towards the wider measured
  // side (x 20..39 against 0..9): 109.2 measured; a nearest-value fill is off by up to 2.5.
  EXPECT_NEAR(r->depth_um.at<float>(15, 15), 107.5f, 2.0f);
}

}  // namespace
}  // namespace inspection
