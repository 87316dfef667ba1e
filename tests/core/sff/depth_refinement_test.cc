// Depth refinement, fill and fusion (core/sff/depth_refinement.h, depth_fill.h, depth_fusion.h) on
// maps whose right answer is known: steps aligned with guide edges, spikes, holes.
#include "core/sff/depth_refinement.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "core/sff/depth_fill.h"
#include "core/sff/depth_fusion.h"

namespace inspection {
namespace {

const float kNaN = std::nanf("");

// 8-bit colour guide: colour A left of column `edge`, colour B from it on (equal luminance-ish,
// different hue, so only a colour guide separates them well).
cv::Mat StepGuide(cv::Size size, int edge) {
  cv::Mat g(size, CV_8UC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      g.at<cv::Vec3b>(y, x) = x < edge ? cv::Vec3b(40, 160, 200) : cv::Vec3b(200, 150, 60);
  return g;
}

cv::Mat StepDepth(cv::Size size, int edge, float left, float right) {
  cv::Mat d(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) d.at<float>(y, x) = x < edge ? left : right;
  return d;
}

TEST(DepthRefinementTest, WeightedMedianMovesASmearedEdgeOntoTheGuideEdgeAndRemovesSpikes) {
  const cv::Size size(32, 24);
  const cv::Mat guide = StepGuide(size, 16);
  // The focus window smeared the far side's depth 2 px into the near object (columns 14, 15).
  cv::Mat depth = StepDepth(size, 14, 10.f, 20.f);
  depth.at<float>(5, 5) = 50.f;  // a spurious focus peak
  depth.at<float>(8, 8) = kNaN;  // not measured: stays NaN
  cv::Mat conf(size, CV_32F, cv::Scalar(0.9f));
  DepthRefinementOptions o;
  o.method = DepthRefinement::kWeightedMedian;
  o.radius_px = 4;
  auto r = RefineDepth(depth, conf, guide, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      if (y == 8 && x == 8) {
        EXPECT_TRUE(std::isnan(r->at<float>(y, x)));
        continue;
      }
      EXPECT_EQ(r->at<float>(y, x), x < 16 ? 10.f : 20.f) << x << "," << y;
    }
}

TEST(DepthRefinementTest, LowConfidenceNeighboursDoNotVote) {
  const cv::Size size(15, 15);
  const cv::Mat guide(size, CV_8UC1, cv::Scalar(100));
  cv::Mat depth(size, CV_32F, cv::Scalar(5.f));
  cv::Mat conf(size, CV_32F, cv::Scalar(1.f));
  // Most of the window says 9, but with confidence 0: the 5s decide.
  for (int y = 0; y < 15; ++y)
    for (int x = 0; x < 11; ++x) {
      depth.at<float>(y, x) = 9.f;
      conf.at<float>(y, x) = 0.f;
    }
  DepthRefinementOptions o;
  o.radius_px = 5;
  auto r = RefineDepth(depth, conf, guide, o);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->at<float>(7, 12), 5.f);
  // A pixel whose window holds only unconfident pixels keeps its own depth.
  EXPECT_EQ(r->at<float>(7, 0), 9.f);
}

TEST(DepthRefinementTest, GuidedFilterKeepsPlanesAndGuideAlignedStepsAndRemovesNoise) {
  const cv::Size size(64, 48);
  std::mt19937 rng(1);
  std::normal_distribution<float> noise(0.f, 0.5f);
  // A plane under a flat guide: the filter returns the plane with the noise reduced ~(2r+1)x.
  cv::Mat plane(size, CV_32F), noisy(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      plane.at<float>(y, x) = 100.f + 0.2f * x - 0.1f * y;
      noisy.at<float>(y, x) = plane.at<float>(y, x) + noise(rng);
    }
  DepthRefinementOptions o;
  o.method = DepthRefinement::kGuidedFilter;
  o.radius_px = 4;
  auto r = RefineDepth(noisy, cv::Mat(), cv::Mat(size, CV_8UC1, cv::Scalar(90)), o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const cv::Rect inner(8, 8, size.width - 16, size.height - 16);  // box sums reflect at the border
  const double before = cv::norm(noisy(inner), plane(inner), cv::NORM_L2) / std::sqrt(inner.area());
  const double after = cv::norm((*r)(inner), plane(inner), cv::NORM_L2) / std::sqrt(inner.area());
  EXPECT_NEAR(before, 0.5, 0.05);
  EXPECT_LT(after, 0.1);
  // A depth step on a guide edge (dark | bright) stays a step: within 0.5 of each side one pixel
  // from the edge.
  cv::Mat guide(size, CV_8UC1, cv::Scalar(30));
  guide.colRange(30, size.width).setTo(220);
  const cv::Mat step = StepDepth(size, 30, 10.f, 20.f);
  auto s = RefineDepth(step, cv::Mat(), guide, o);
  ASSERT_TRUE(s.ok());
  EXPECT_NEAR(s->at<float>(20, 28), 10.f, 0.5f);
  EXPECT_NEAR(s->at<float>(20, 31), 20.f, 0.5f);
}

TEST(DepthRefinementTest, BadInputIsNamed) {
  const cv::Mat d(4, 4, CV_32F, cv::Scalar(1.f));
  DepthRefinementOptions o;
  o.radius_px = 0;
  EXPECT_NE(RefineDepth(d, cv::Mat(), cv::Mat(4, 4, CV_8UC1), o).status().message().find("radius_px"),
            std::string::npos);
  o = DepthRefinementOptions{};
  EXPECT_NE(RefineDepth(d, cv::Mat(), cv::Mat(5, 4, CV_8UC1), o).status().message().find("guide"), std::string::npos);
  EXPECT_EQ(RefineDepth(d, cv::Mat(), cv::Mat(4, 4, CV_32FC1), o).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(RefineDepth(cv::Mat(4, 4, CV_64F), cv::Mat(), cv::Mat(4, 4, CV_8UC1), o).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ParseDepthRefinement("guided-filter").value(), DepthRefinement::kGuidedFilter);
  EXPECT_FALSE(ParseDepthRefinement("median").ok());
}

TEST(DepthFillTest, GuidedFillTakesDepthFromTheSurfaceThatLooksAlike) {
  // Left surface (colour A) at depth 10, right surface (colour B) at 30; a large textureless
  // hole spans the boundary. Guided, each side of the hole is filled from its own surface.
  const cv::Size size(64, 40);
  const int edge = 29;  // not on a pyramid cell boundary
  const cv::Mat guide = StepGuide(size, edge);
  cv::Mat depth = StepDepth(size, edge, 10.f, 30.f);
  const cv::Rect hole(8, 8, 48, 24);
  depth(hole).setTo(kNaN);
  const cv::Mat measured = depth.clone();
  DepthFillOptions o;
  auto f = FillDepth(depth, cv::Mat(), guide, o);
  ASSERT_TRUE(f.ok()) << f.status().ToString();
  double worst_guided = 0;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const float v = f->at<float>(y, x);
      ASSERT_TRUE(std::isfinite(v));
      if (!hole.contains({x, y})) {
        EXPECT_EQ(v, measured.at<float>(y, x));  // measured pixels unchanged
      } else if (std::abs(x - edge) >= 2) {
        worst_guided = std::max(worst_guided, std::abs(v - (x < edge ? 10.0 : 30.0)));
      }
    }
  // Coarse cells straddling the boundary carry a mix of both surfaces and both colours; with
  // guide_sigma 0.05 they leak < 1 unit of the 20 into the hole, with 0.02 nothing visible.
  EXPECT_LT(worst_guided, 1.0);
  o.guide_sigma = 0.02;
  auto sharp = FillDepth(depth, cv::Mat(), guide, o);
  ASSERT_TRUE(sharp.ok());
  for (int y = hole.y; y < hole.y + hole.height; ++y)
    for (int x = hole.x; x < hole.x + hole.width; ++x)
      EXPECT_NEAR(sharp->at<float>(y, x), x < edge ? 10.0 : 30.0, 0.1) << x << "," << y;
  // Plain push-pull (no guide) blends the two surfaces across the hole: beside the boundary it is
  // several units off.
  o.guide_sigma = 0;
  auto plain = FillDepth(depth, cv::Mat(), cv::Mat(), o);
  ASSERT_TRUE(plain.ok());
  EXPECT_GT(std::abs(plain->at<float>(20, edge - 2) - 10.f), 3.f);
  EXPECT_GT(std::abs(plain->at<float>(20, edge + 2) - 30.f), 3.f);
}

TEST(DepthFillTest, PlainFillOfAHoleInAPlaneStaysBetweenItsBorderValues) {
  const cv::Size size(48, 48);
  cv::Mat depth(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) depth.at<float>(y, x) = 50.f + 0.5f * x;
  cv::Mat holed = depth.clone();
  cv::circle(holed, {24, 24}, 9, cv::Scalar(kNaN), cv::FILLED);
  DepthFillOptions o;
  o.guide_sigma = 0;
  auto f = FillDepth(holed, cv::Mat(), cv::Mat(), o);
  ASSERT_TRUE(f.ok());
  // The hole spans x = 15..33 (depth 57.5..66.5); push-pull is smooth, not planar: within 2 units
  // of the plane and inside the border's range.
  for (int y = 15; y <= 33; ++y)
    for (int x = 15; x <= 33; ++x) {
      const float v = f->at<float>(y, x);
      EXPECT_NEAR(v, depth.at<float>(y, x), 2.0) << x << "," << y;
      EXPECT_GE(v, 57.f);
      EXPECT_LE(v, 67.f);
    }
}

TEST(DepthFillTest, NothingOrEverythingMeasuredIsReturnedAsIs) {
  DepthFillOptions o;
  o.guide_sigma = 0;
  const cv::Mat all_nan(8, 8, CV_32F, cv::Scalar(kNaN));
  auto a = FillDepth(all_nan, cv::Mat(), cv::Mat(), o);
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(cv::countNonZero(*a == *a), 0);  // still all NaN
  const cv::Mat full(8, 8, CV_32F, cv::Scalar(3.f));
  auto b = FillDepth(full, cv::Mat(), cv::Mat(), o);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(cv::norm(*b, full, cv::NORM_INF), 0.0);
  o.guide_sigma = -1;
  EXPECT_NE(FillDepth(full, cv::Mat(), cv::Mat(), o).status().message().find("guide_sigma"), std::string::npos);
}

TEST(DepthFusionTest, MostConfidentAndWeightedRules) {
  cv::Mat d1(1, 3, CV_32F), d2(1, 3, CV_32F), c1(1, 3, CV_32F), c2(1, 3, CV_32F);
  d1.at<float>(0, 0) = 10.f;
  c1.at<float>(0, 0) = 0.9f;
  d2.at<float>(0, 0) = 14.f;
  c2.at<float>(0, 0) = 0.3f;
  d1.at<float>(0, 1) = 10.f;
  c1.at<float>(0, 1) = 0.1f;
  d2.at<float>(0, 1) = 20.f;
  c2.at<float>(0, 1) = 0.2f;
  d1.at<float>(0, 2) = kNaN;
  c1.at<float>(0, 2) = 0.9f;
  d2.at<float>(0, 2) = 7.f;
  c2.at<float>(0, 2) = 0.5f;
  auto m = FuseDepthMaps({d1, d2}, {c1, c2}, DepthFusionRule::kMostConfident, 0.4);
  ASSERT_TRUE(m.ok());
  EXPECT_EQ(m->depth_um.at<float>(0, 0), 10.f);
  EXPECT_TRUE(std::isnan(m->depth_um.at<float>(0, 1)));  // best confidence 0.2 < 0.4
  EXPECT_EQ(m->depth_um.at<float>(0, 2), 7.f);           // the NaN depth does not count
  EXPECT_FLOAT_EQ(m->confidence.at<float>(0, 0), 0.9f);
  auto w = FuseDepthMaps({d1, d2}, {c1, c2}, DepthFusionRule::kConfidenceWeighted, 0.0);
  ASSERT_TRUE(w.ok());
  EXPECT_FLOAT_EQ(w->depth_um.at<float>(0, 0), (10.f * 0.9f + 14.f * 0.3f) / 1.2f);
  EXPECT_FLOAT_EQ(w->depth_um.at<float>(0, 1), (10.f * 0.1f + 20.f * 0.2f) / 0.3f);
  // First confident: map 1 where it reaches 0.4, else map 2 where that does.
  auto f = FuseDepthMaps({d1, d2}, {c1, c2}, DepthFusionRule::kFirstConfident, 0.25);
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f->depth_um.at<float>(0, 0), 10.f);
  EXPECT_TRUE(std::isnan(f->depth_um.at<float>(0, 1)));  // 0.1 and 0.2 both below 0.25
  EXPECT_EQ(f->depth_um.at<float>(0, 2), 7.f);
  EXPECT_FLOAT_EQ(f->confidence.at<float>(0, 2), 0.5f);
  EXPECT_EQ(FuseDepthMaps({d1}, {c1, c2}, DepthFusionRule::kMostConfident, 0.4).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(FuseDepthMaps({d1, cv::Mat(2, 2, CV_32F)}, {c1, c2}, DepthFusionRule::kMostConfident, 0.4).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
