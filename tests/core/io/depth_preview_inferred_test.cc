// The depth preview marks inferred pixels (core/io/depth_export.h): dimmed and hatched, measured
// pixels drawn exactly as without a mask.
#include <gtest/gtest.h>

#include "core/io/depth_export.h"

namespace inspection {
namespace {

TEST(DepthPreviewInferredTest, InferredPixelsAreDimmedAndHatched) {
  cv::Mat depth(40, 60, CV_32FC1);
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) depth.at<float>(y, x) = float(x);
  cv::Mat inferred(depth.size(), CV_8UC1, cv::Scalar(0));
  inferred(cv::Rect(30, 0, 30, 40)).setTo(255);
  auto plain = RenderDepthPreview(depth);
  auto marked = RenderDepthPreview(depth, inferred);
  ASSERT_TRUE(plain.ok() && marked.ok());
  // Measured half: identical.
  EXPECT_EQ(cv::norm((*plain)(cv::Rect(0, 0, 30, 40)), (*marked)(cv::Rect(0, 0, 30, 40)), cv::NORM_INF), 0.0);
  // Inferred: the hatch (x + y divisible by 4) grey, the rest at 55 %.
  EXPECT_EQ((*marked).at<cv::Vec3b>(2, 34), cv::Vec3b(128, 128, 128));
  const cv::Vec3b p = plain->at<cv::Vec3b>(3, 34), m = marked->at<cv::Vec3b>(3, 34);
  for (int c = 0; c < 3; ++c) EXPECT_EQ(int(m[c]), int(p[c] * 0.55)) << c;
  // A mask of the wrong size is refused, naming it.
  auto bad = RenderDepthPreview(depth, cv::Mat(5, 5, CV_8UC1, cv::Scalar(0)));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().ToString().find("inferred"), std::string::npos);
}

}  // namespace
}  // namespace inspection
