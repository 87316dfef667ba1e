// Dense depth (core/sff/dense_depth.h) on maps whose true depth is known.
#include "core/sff/dense_depth.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "core/sff/depth_postprocess.h"

namespace inspection {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();

// The stage positions of a 30-frame stack at 2 um steps from first_um.
std::vector<double> ThirtyFramesFrom(double first_um) {
  std::vector<double> z;
  for (int k = 0; k < 30; ++k) z.push_back(first_um + 2.0 * k);
  return z;
}

// Two surfaces side by side: left half dark at 100 um, right half bright at 200 um. Each half
// is measured only in a sparse grid (every 8th pixel); the guide's edge must keep the halves apart.
TEST(DenseDepthTest, FillsEveryPixelAndStopsAtTheGuideEdge) {
  const cv::Size size(96, 64);
  cv::Mat guide(size, CV_8UC1, cv::Scalar(40));
  guide(cv::Rect(48, 0, 48, 64)).setTo(220);
  cv::Mat depth(size, CV_32FC1, cv::Scalar(kNan));
  for (int y = 0; y < size.height; y += 8)
    for (int x = 2; x < size.width; x += 8) depth.at<float>(y, x) = x < 48 ? 100.f : 200.f;
  for (const bool fallback : {false, true}) {
    DenseDepthOptions o;
    if (!fallback) o.fallback_support = 0.0;
    auto dense = DensifyDepth(depth, cv::Mat(), guide, o);
    ASSERT_TRUE(dense.ok()) << dense.status().ToString();
    ASSERT_EQ(cv::countNonZero(*dense == *dense), size.area());
    double max_left_err = 0, max_right_err = 0;
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const double v = dense->at<float>(y, x);
        if (x < 48) max_left_err = std::max(max_left_err, std::abs(v - 100.0));
        else max_right_err = std::max(max_right_err, std::abs(v - 200.0));
      }
    // Across the edge the guide's colour difference (180 levels, sigma 4) cuts the smoothing.
    // With the fallback (default) both fits see the same sparse measurements, r ~ 1, so the
    // weakly edge-aware fit keeps a share of 1 - 1 / (1 + 0.3^2) = 8 %, which leaks a little
    // across the edge: 3.6 of the 100 um step measured.
    EXPECT_LT(max_left_err, fallback ? 5.0 : 2.0);
    EXPECT_LT(max_right_err, fallback ? 5.0 : 2.0);
    // Measured pixels keep their values exactly.
    EXPECT_EQ(dense->at<float>(8, 10), 100.f);
    EXPECT_EQ(dense->at<float>(8, 50), 200.f);
  }
}

// The solve grid: full size for the small maps, reduced at camera size so that the cost stays
// tens of milliseconds (DenseDepthOptions::auto_solve_max_pixels = 200000).
TEST(DenseDepthTest, SolveGridShrinksAtCameraSize) {
  const DenseDepthOptions o;
  EXPECT_EQ(DenseSolveDownscale(cv::Size(256, 256), o), 1);
  EXPECT_EQ(DenseSolveDownscale(cv::Size(400, 300), o), 1);
  EXPECT_EQ(DenseSolveDownscale(cv::Size(800, 600), o), 2);
  EXPECT_EQ(DenseSolveDownscale(cv::Size(1600, 1200), o), 4);
  EXPECT_EQ(DenseSolveDownscale(cv::Size(4000, 3000), o), 8);
  DenseDepthOptions forced;
  forced.solve_downscale = 2;
  EXPECT_EQ(DenseSolveDownscale(cv::Size(256, 256), forced), 2);
}

// On the reduced grid (2 and 4 times) the joint bilateral upsampling puts every pixel on its own
// side of a guide edge that no block boundary follows (x = 397): two sloped surfaces 100 um
// apart, each measured on a sparse grid, come back within a few um at every pixel, right up to
// the edge, and measured pixels keep their depth.
TEST(DenseDepthTest, ReducedSolveGridKeepsEdgesAndMeasuredDepth) {
  const cv::Size size(800, 600);
  const int edge = 397;
  cv::Mat guide(size, CV_8UC3, cv::Scalar(40, 60, 50));
  guide(cv::Rect(edge, 0, size.width - edge, size.height)).setTo(cv::Scalar(210, 190, 200));
  auto truth = [&](int x, int y) { return x < edge ? 100.0 + 0.02 * x : 200.0 + 0.03 * y; };
  cv::Mat depth(size, CV_32FC1, cv::Scalar(kNan));
  for (int y = 1; y < size.height; y += 6)
    for (int x = 3; x < size.width; x += 6) depth.at<float>(y, x) = float(truth(x, y));
  for (const int k : {2, 4}) {
    DenseDepthOptions o;
    o.solve_downscale = k;
    o.fallback_support = 0.0;  // the edge-aware fit alone: the leak across the edge is the upsampling's
    auto dense = DensifyDepthWithSupport(depth, cv::Mat(), guide, o);
    ASSERT_TRUE(dense.ok()) << dense.status().ToString();
    ASSERT_EQ(cv::countNonZero(dense->depth_um == dense->depth_um), size.area());
    double max_err = 0, max_err_at_edge = 0;
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const double e = std::abs(dense->depth_um.at<float>(y, x) - truth(x, y));
        max_err = std::max(max_err, e);
        if (std::abs(x - edge) <= 2) max_err_at_edge = std::max(max_err_at_edge, e);
      }
    EXPECT_LT(max_err, 5.0) << "k = " << k;
    EXPECT_LT(max_err_at_edge, 5.0) << "k = " << k;
    EXPECT_EQ(dense->depth_um.at<float>(7, 9), depth.at<float>(7, 9));
    EXPECT_EQ(dense->inferred.at<uint8_t>(7, 9), 0);
    EXPECT_EQ(dense->inferred.at<uint8_t>(8, 9), 255);
    EXPECT_GT(dense->agreement.at<float>(7, 9), 0.5f);
  }
}

// An untextured region walled off by guide edges, with no measurement inside: the background
// (depth 50) all round it, except one side where a measured foreground strip (depth 10) meets it
// across a weaker edge. The edge-aware fit alone gives the region the strip's depth (the weakest
// edge wins); the fallback, seeing the much larger measured background, gives it the
// background's.
TEST(DenseDepthTest, FallbackFillsAWalledOffRegionFromItsSurroundings) {
  const cv::Size size(128, 96);
  cv::Mat guide(size, CV_8UC1, cv::Scalar(60));
  cv::Mat depth(size, CV_32FC1, cv::Scalar(50.f));
  const cv::Rect region(40, 30, 40, 36), strip(80, 30, 6, 36);
  guide(region).setTo(200);
  guide(strip).setTo(190);
  depth(region).setTo(kNan);
  depth(strip).setTo(10.f);
  DenseDepthOptions o;
  o.fallback_support = 0.0;
  auto edge_only = DensifyDepth(depth, cv::Mat(), guide, o);
  o.fallback_support = 0.3;
  auto with_fallback = DensifyDepth(depth, cv::Mat(), guide, o);
  ASSERT_TRUE(edge_only.ok() && with_fallback.ok());
  const cv::Point centre(60, 48);
  // Measured: 10.0 edge-aware only, 40.8 with the fallback (the strip keeps a share).
  EXPECT_LT(edge_only->at<float>(centre), 12.f);
  EXPECT_GT(with_fallback->at<float>(centre), 35.f);
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

// A surface sloping in y, measured only on the left half: the right half (an untextured wall
// reaching the image edge) must be extrapolated sideways. The constant model averages the rows
// around each pixel, pulling the top and bottom towards the middle; the local plane carries the
// slope on.
TEST(DenseDepthTest, LocalPlanesCarryTheSlopeIntoAnUnmeasuredRegion) {
  const cv::Size size(96, 64);
  cv::Mat guide(size, CV_8UC1, cv::Scalar(128));
  cv::Mat depth(size, CV_32FC1, cv::Scalar(kNan));
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < 48; ++x) depth.at<float>(y, x) = 10.f + 0.4f * y;
  DenseDepthOptions o = Local();
  o.local_planes = false;
  auto constant = DensifyDepth(depth, cv::Mat(), guide, o);
  o.local_planes = true;
  auto planes = DensifyDepth(depth, cv::Mat(), guide, o);
  ASSERT_TRUE(constant.ok() && planes.ok());
  double err_constant = 0, err_planes = 0;
  for (int y = 0; y < size.height; ++y)
    for (int x = 48; x < size.width; ++x) {
      const double truth = 10.0 + 0.4 * y;
      err_constant = std::max(err_constant, std::abs(constant->at<float>(y, x) - truth));
      err_planes = std::max(err_planes, std::abs(planes->at<float>(y, x) - truth));
    }
  // 48 px beyond the last measured column the plane, shrunk by the slope's ridge, is 1.6 um off.
  EXPECT_GT(err_constant, 5.0);
  EXPECT_LT(err_planes, 2.0);
}

// Wrong peaks: a plane with 5 % of its measured pixels 30 um off. The robust fit replaces them by
// the plane (and marks them inferred); the plain fit keeps them (keep_measured) and smears them
// into the hole.
TEST(DenseDepthTest, RobustFitRejectsOutliers) {
  const cv::Size size(64, 64);
  cv::Mat guide(size, CV_8UC1, cv::Scalar(90));
  cv::Mat depth(size, CV_32FC1), truth(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) truth.at<float>(y, x) = depth.at<float>(y, x) = 50.f + 0.2f * x + 0.1f * y;
  int outliers = 0;
  for (int y = 0; y < size.height; y += 5)
    for (int x = (y / 5) % 4; x < size.width; x += 4) {
      depth.at<float>(y, x) += 30.f;
      ++outliers;
    }
  depth(cv::Rect(24, 24, 16, 16)).setTo(kNan);
  DenseDepthOptions o = Local();
  o.local_planes = true;
  o.robust_iterations = 0;
  o.reject_scale = 0.0;  // no outlier test at all
  auto plain = DensifyDepthWithSupport(depth, cv::Mat(), guide, o);
  o.robust_iterations = 3;
  auto robust = DensifyDepthWithSupport(depth, cv::Mat(), guide, o);
  ASSERT_TRUE(plain.ok() && robust.ok());
  auto MaxErr = [&](const cv::Mat& d) {
    double e = 0;
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) e = std::max(e, double(std::abs(d.at<float>(y, x) - truth.at<float>(y, x))));
    return e;
  };
  EXPECT_GT(MaxErr(plain->depth_um), 29.0);  // the outliers themselves are kept
  EXPECT_LT(MaxErr(robust->depth_um), 2.0);
  // The hole and (nearly) all outliers are inferred, every other pixel measured.
  const int inferred = cv::countNonZero(robust->inferred);
  EXPECT_LE(inferred, outliers + 16 * 16);
  EXPECT_GE(inferred, int(0.9 * outliers) + 16 * 16);
  EXPECT_EQ(cv::countNonZero(plain->inferred), 16 * 16);
  // Outliers agree little with the fit, the rest well (the Cauchy scale is floored at 1e-3 of
  // the measured range on this noise-free plane).
  EXPECT_LT(robust->agreement.at<float>(0, 0), 0.1f);
  EXPECT_GT(robust->agreement.at<float>(1, 1), 0.5f);
  // Support: 1 amid the measurements, lower in the hole's centre.
  EXPECT_GT(robust->support.at<float>(2, 2), 0.5f);
  EXPECT_LT(robust->support.at<float>(32, 32), robust->support.at<float>(2, 2));
}

// The default outlier test (reject_scale 12, no reweighting): on a plane with 0.5 um noise, 2 %
// of the measured pixels 30 um off (a wrong peak, as a flat pixel next to texture gets) are
// replaced by the fit and counted as inferred; the noisy but right ones stay measured. Through
// the post-processing the rejected pixels rank below min_confidence and below the unmeasured
// pixels amid measurements (their rank is the support times their agreement with the fit).
TEST(DenseDepthTest, DefaultRejectsGrossOutliersWithoutReweighting) {
  const cv::Size size(96, 64);
  cv::Mat depth(size, CV_32FC1), truth(size, CV_32FC1), noise(size, CV_32FC1);
  cv::RNG rng(7);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, 0.5);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      truth.at<float>(y, x) = 50.f + 0.2f * x + 0.1f * y;
      depth.at<float>(y, x) = truth.at<float>(y, x) + noise.at<float>(y, x);
    }
  cv::Mat is_outlier(size, CV_8UC1, cv::Scalar(0));
  int outliers = 0;
  for (int y = 3; y < size.height; y += 7)
    for (int x = (y * 3) % 7; x < size.width; x += 7) {
      depth.at<float>(y, x) += 30.f;
      is_outlier.at<uint8_t>(y, x) = 255;
      ++outliers;
    }
  const cv::Rect hole(40, 20, 12, 12);
  depth(hole).setTo(kNan);
  is_outlier(hole).setTo(0);
  outliers = cv::countNonZero(is_outlier);
  cv::Mat guide(size, CV_8UC1, cv::Scalar(90));
  const DenseDepthOptions o;
  ASSERT_EQ(o.reject_scale, 12.0);
  ASSERT_EQ(o.robust_iterations, 0);
  auto d = DensifyDepthWithSupport(depth, cv::Mat(), guide, o);
  ASSERT_TRUE(d.ok()) << d.status().ToString();
  int rejected_outliers = 0, rejected_good = 0;
  double max_err = 0;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const bool in_hole = hole.contains(cv::Point(x, y));
      if (!in_hole && d->inferred.at<uint8_t>(y, x)) {
        if (is_outlier.at<uint8_t>(y, x)) ++rejected_outliers;
        else ++rejected_good;
      }
      if (is_outlier.at<uint8_t>(y, x))
        max_err = std::max(max_err, double(std::abs(d->depth_um.at<float>(y, x) - truth.at<float>(y, x))));
    }
  EXPECT_GE(rejected_outliers, int(0.95 * outliers));
  EXPECT_LT(rejected_good, int(0.01 * size.area()));
  EXPECT_LT(max_err, 6.0);  // the fit, pulled a little by the other outliers (2 % at +30 um)
  // A right measurement stays exactly as measured.
  EXPECT_EQ(d->depth_um.at<float>(0, 0), depth.at<float>(0, 0));

  DepthResult raw;
  raw.depth_um = depth.clone();
  raw.depth_um(hole).setTo(60.f);
  raw.confidence = cv::Mat(size, CV_32FC1, cv::Scalar(0.9f));
  raw.confidence(hole).setTo(0.1f);
  raw.all_in_focus = guide;
  raw.frame_count = 30;
  const std::vector<double> z = ThirtyFramesFrom(40.0);
  DepthPostProcessOptions po;
  po.consistency = false;
  po.dense = true;
  auto r = PostProcessDepth(raw, z, 7, po);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  int ranked_below = 0, ranked = 0;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      if (is_outlier.at<uint8_t>(y, x) && r->confidence.at<float>(y, x) < 0.4f) {
        ++ranked;
        ranked_below += r->confidence.at<float>(y, x) < r->confidence.at<float>(hole.y, hole.x);
      }
  EXPECT_GE(ranked, int(0.95 * outliers));
  EXPECT_GE(ranked_below, int(0.95 * ranked));
}

TEST(DenseDepthTest, RejectsBadInputNamingIt) {
  cv::Mat depth(10, 10, CV_32FC1, cv::Scalar(1.f)), guide(10, 10, CV_8UC1, cv::Scalar(0));
  DenseDepthOptions bad;
  bad.lambda = 0;
  auto r = DensifyDepth(depth, cv::Mat(), guide, bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().ToString().find("dense.lambda"), std::string::npos);
  DenseDepthOptions bad_robust;
  bad_robust.robust_iterations = -1;
  auto rr = DensifyDepth(depth, cv::Mat(), guide, bad_robust);
  ASSERT_FALSE(rr.ok());
  EXPECT_NE(rr.status().ToString().find("dense.robust_iterations"), std::string::npos);
  DenseDepthOptions bad_reject;
  bad_reject.reject_scale = -1;
  EXPECT_NE(DensifyDepth(depth, cv::Mat(), guide, bad_reject).status().ToString().find("dense.reject_scale"),
            std::string::npos);
  DenseDepthOptions bad_ridge;
  bad_ridge.plane_ridge_px = -1;
  EXPECT_NE(DensifyDepth(depth, cv::Mat(), guide, bad_ridge).status().ToString().find("dense.plane_ridge_px"),
            std::string::npos);
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
  const std::vector<double> z = ThirtyFramesFrom(90.0);
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
  // dense_confidence: inferred pixels get 0.4 x the fit's support (amid measurements: just
  // below 0.4), measured ones keep at least 0.4, the part above scaled by their agreement with
  // the fit.
  EXPECT_GT(r->confidence.at<float>(15, 15), 0.3f);
  EXPECT_LT(r->confidence.at<float>(15, 15), 0.4f);
  // With the local factor (dense_rank_radius_px 8, off by default): also x the square root of
  // the measured share within 8 px (at the hole's centre 189 / 289 of the 17 x 17 box); the
  // hole's corner, nearer the measurements, ranks above its centre.
  DepthPostProcessOptions with_radius = o;
  with_radius.dense_rank_radius_px = 8;
  auto wr = PostProcessDepth(raw, z, 7, with_radius);
  ASSERT_TRUE(wr.ok());
  EXPECT_NEAR(wr->confidence.at<float>(15, 15), r->confidence.at<float>(15, 15) * std::sqrt(189.f / 289.f), 1e-4f);
  EXPECT_GT(wr->confidence.at<float>(10, 10), wr->confidence.at<float>(15, 15));
  EXPECT_LT(wr->confidence.at<float>(10, 10), 0.4f);
  EXPECT_GE(r->confidence.at<float>(0, 0), 0.4f);
  EXPECT_LE(r->confidence.at<float>(0, 0), 0.9f);
  // dense_confidence off: the engine's confidence as it was.
  o.dense_confidence = false;
  auto plain = PostProcessDepth(raw, z, 7, o);
  ASSERT_TRUE(plain.ok());
  EXPECT_FLOAT_EQ(plain->confidence.at<float>(0, 0), 0.9f);
  EXPECT_FLOAT_EQ(plain->confidence.at<float>(15, 15), 0.1f);
}

// DenseDepth::spread_um: the measured depths the fit draws on agree about a local plane amid one
// (tilted) surface, and disagree where an untextured hole hides a depth step that the guide does
// not show, so the fill's value there is a guess between the two sides.
TEST(DenseDepthTest, SpreadIsSmallOnOneSurfaceAndLargeAcrossAHiddenStep) {
  const cv::Size size(96, 64);
  const cv::Mat guide(size, CV_8UC1, cv::Scalar(128));
  const cv::Rect hole(40, 20, 16, 16);
  cv::Mat plane(size, CV_32FC1), step(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      plane.at<float>(y, x) = 100.f + 0.25f * x + 0.1f * y;
      step.at<float>(y, x) = x < 48 ? 100.f : 120.f;
    }
  plane(hole).setTo(kNan);
  step(hole).setTo(kNan);
  DenseDepthOptions o = Local();
  o.reject_scale = 0.0;
  auto on_plane = DensifyDepthWithSupport(plane, cv::Mat(), guide, o);
  auto on_step = DensifyDepthWithSupport(step, cv::Mat(), guide, o);
  ASSERT_TRUE(on_plane.ok() && on_step.ok());
  // The hole's centre and a far corner: a plane fits the surroundings exactly (measured 0 and
  // 0.004 um; with the slope ridge's shrinkage counted as residual it would be 0.6 um).
  EXPECT_LT(on_plane->spread_um.at<float>(28, 48), 0.05f);
  EXPECT_LT(on_plane->spread_um.at<float>(5, 5), 0.05f);
  // Across the 20 um step (hole centre on it): 5.6 um measured; no plane fits both sides.
  EXPECT_GT(on_step->spread_um.at<float>(28, 48), 4.f);
  EXPECT_LT(on_step->spread_um.at<float>(28, 48), 10.f);
  // 43 px away, on one side (guide uniform, so the fit still reaches the far side): 3.4 um.
  EXPECT_LT(on_step->spread_um.at<float>(28, 5), 0.75f * on_step->spread_um.at<float>(28, 48));
}

// The dense confidence ranks two unmeasured holes of the same size and support by the spread:
// the one amid a single surface above the one that hides a depth step (default
// dense_rank_spread_z_steps 1: the rank / (1 + (spread / 1 z step)^2)).
TEST(DenseDepthTest, PostProcessRanksAHoleAmidOneSurfaceAboveOneAcrossAStep) {
  DepthResult raw;
  const cv::Size size(128, 64);
  raw.depth_um.create(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) raw.depth_um.at<float>(y, x) = x < 96 ? 100.f : 140.f;
  raw.confidence = cv::Mat(size, CV_32FC1, cv::Scalar(0.9f));
  const cv::Rect on_surface(16, 24, 16, 16), across_step(88, 24, 16, 16);
  raw.confidence(on_surface).setTo(0.1f);
  raw.confidence(across_step).setTo(0.1f);
  // Two objects the guide tells apart (x < 64 dark, the rest bright); the step at x = 96 is
  // inside the bright one, where the guide shows nothing.
  raw.all_in_focus = cv::Mat(size, CV_8UC1, cv::Scalar(60));
  raw.all_in_focus(cv::Rect(64, 0, 64, 64)).setTo(180);
  raw.frame_count = 30;
  const std::vector<double> z = ThirtyFramesFrom(90.0);
  DepthPostProcessOptions o;
  o.consistency = false;
  o.dense = true;
  o.dense_options.reject_scale = 0.0;
  ASSERT_EQ(o.dense_rank_spread_z_steps, 1.0);
  ASSERT_TRUE(o.dense_rank_spread_measured);
  auto ranked = PostProcessDepth(raw, z, 7, o);
  DepthPostProcessOptions support_only = o;
  support_only.dense_rank_spread_z_steps = 0.0;
  auto plain = PostProcessDepth(raw, z, 7, support_only);
  ASSERT_TRUE(ranked.ok() && plain.ok());
  const float a = ranked->confidence.at<float>(32, 24), b = ranked->confidence.at<float>(32, 96);
  const float a0 = plain->confidence.at<float>(32, 24), b0 = plain->confidence.at<float>(32, 96);
  // By support alone the two centres tie (0.337 both: 0.4 x the fit's weight there).
  EXPECT_NEAR(a0, 0.337f, 0.005f);
  EXPECT_NEAR(b0, a0, 0.005f);
  // With the spread: the hole amid one surface keeps its rank (spread 0), the one across the
  // hidden 40 um (20 z step) step drops to 0.015 (spread about 9.4 um: 0.337 / (1 + 4.7^2)).
  EXPECT_NEAR(a, a0, 1e-4f);
  EXPECT_LT(b, 0.1f * a);
  EXPECT_GT(b, 0.f);
  // Still inferred, and the measured pixels still measured: a measured pixel amid one surface
  // keeps its 0.9; one beside the step keeps at least min_confidence.
  EXPECT_LT(a, 0.4f);
  EXPECT_FLOAT_EQ(ranked->confidence.at<float>(5, 5), 0.9f);
  EXPECT_GE(ranked->confidence.at<float>(5, 95), 0.4f);
  EXPECT_LE(ranked->confidence.at<float>(5, 95), plain->confidence.at<float>(5, 95));
  // The depth is the ranking's business only: the same map either way.
  EXPECT_EQ(cv::norm(ranked->depth_um, plain->depth_um, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace inspection
