// Automatic z range maths (core/sff/z_range_search.h) on synthetic coarse sweeps with known
// heights: a textured two-level part blurred by the defocus model (blur sigma grows linearly with
// |height - z|), a textureless field, and the sweep / fine range planning with its errors.
#include "core/sff/z_range_search.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

// A 256x192 frame of two halves at heights h_left / h_right seen with the stage at z: random
// texture, Gaussian blur of sigma 0.6 + 0.4 |h - z| px, read noise 1 grey level.
cv::Mat Frame(double h_left, double h_right, double z, uint64_t seed, bool textured = true,
              double blur_px_per_um = 0.4) {
  cv::Mat texture(192, 256, CV_32F);
  cv::RNG tex(12345);
  tex.fill(texture, cv::RNG::NORMAL, 128.0, textured ? 40.0 : 0.0);
  cv::Mat out(texture.size(), CV_32F);
  const int half = texture.cols / 2;
  for (int side = 0; side < 2; ++side) {
    const double sigma = 0.6 + blur_px_per_um * std::abs((side == 0 ? h_left : h_right) - z);
    cv::Mat blurred;
    cv::GaussianBlur(texture, blurred, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
    const cv::Rect roi(side * half, 0, half, texture.rows);
    blurred(roi).copyTo(out(roi));
  }
  cv::Mat noise(out.size(), CV_32F);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
  out += noise;
  cv::Mat frame;
  out.convertTo(frame, CV_8U);
  return frame;
}

StatusOr<ZRangeEstimate> Sweep(double h_left, double h_right, double z0, double z1, double step,
                                   bool textured = true) {
  INSPECT_ASSIGN_OR_RETURN(ZRangeAccumulator acc,
                           ZRangeAccumulator::Create(ZRangeSearchOptions{}, cv::Size(256, 192), 8));
  uint64_t seed = 1;
  for (double z = z0; z <= z1 + 1e-9; z += step) {
    INSPECT_RETURN_IF_ERROR(acc.PushFrame(Frame(h_left, h_right, z, seed++, textured), z));
  }
  return acc.Finish();
}

TEST(ZRangeAccumulatorTest, FindsBothLevelsOfATwoLevelPartBetweenCoarseFrames) {
  // Heights 233 and 271 um fall between the 20 um frames (at 220, 240, ... and 260, 280).
  auto e = Sweep(233.0, 271.0, 100.0, 400.0, 20.0);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_NEAR(e->z_low_um, 233.0, 4.0);
  EXPECT_NEAR(e->z_high_um, 271.0, 4.0);
  EXPECT_GT(e->resolved_percent, 90.0);
  EXPECT_DOUBLE_EQ(e->at_first_frame_percent, 0.0);
  // Each half's peaks sit at its own height (the map is on the 4x reduced grid).
  EXPECT_NEAR(e->peak_z_um.at<float>(24, 8), 233.0, 4.0);
  EXPECT_NEAR(e->peak_z_um.at<float>(24, 40), 271.0, 4.0);
}

TEST(ZRangeAccumulatorTest, DescendingSweepGivesTheSameRange) {
  auto up = Sweep(233.0, 271.0, 100.0, 400.0, 20.0);
  ASSERT_TRUE(up.ok());
  auto acc = ZRangeAccumulator::Create(ZRangeSearchOptions{}, cv::Size(256, 192), 8);
  ASSERT_TRUE(acc.ok());
  uint64_t seed = 1;
  for (double z = 400.0; z >= 100.0 - 1e-9; z -= 20.0) ASSERT_TRUE(acc->PushFrame(Frame(233, 271, z, seed++), z).ok());
  auto down = acc->Finish();
  ASSERT_TRUE(down.ok()) << down.status().ToString();
  EXPECT_NEAR(down->z_low_um, up->z_low_um, 2.0);
  EXPECT_NEAR(down->z_high_um, up->z_high_um, 2.0);
}

TEST(ZRangeAccumulatorTest, TexturelessFieldIsFailedPreconditionNotAGuess) {
  auto e = Sweep(233.0, 271.0, 100.0, 400.0, 20.0, /*textured=*/false);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(e.status().message().find("no focus found"), std::string::npos) << e.status().message();
}

TEST(ZRangeAccumulatorTest, FocusOutsideTheWindowIsNotFound) {
  // The part at 600 um, the sweep over 100 .. 400 um: every curve rises towards the last frame.
  auto e = Sweep(600.0, 600.0, 100.0, 400.0, 20.0);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.status().code(), StatusCode::kFailedPrecondition);
}

TEST(ZRangeAccumulatorTest, PushRejectsBadFramesAndBrokenOrder) {
  auto acc = ZRangeAccumulator::Create(ZRangeSearchOptions{}, cv::Size(256, 192), 8);
  ASSERT_TRUE(acc.ok());
  EXPECT_EQ(acc->PushFrame(cv::Mat(10, 10, CV_8UC1), 0.0).code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE(acc->PushFrame(Frame(0, 0, 0, 1), 0.0).ok());
  ASSERT_TRUE(acc->PushFrame(Frame(0, 0, 10, 2), 10.0).ok());
  EXPECT_EQ(acc->PushFrame(Frame(0, 0, 5, 3), 5.0).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(acc->Finish().status().code(), StatusCode::kFailedPrecondition);  // 2 frames
  ZRangeSearchOptions bad;
  bad.window_px = 4;
  EXPECT_EQ(ZRangeAccumulator::Create(bad, cv::Size(256, 192), 8).status().code(), StatusCode::kInvalidArgument);
}

TEST(CoarseSweepZTest, CoversTheWindowAndNamesTheFieldOnBadInput) {
  auto z = CoarseSweepZ({100.0, 190.0, 20.0, 5.0}, 0.0, 1000.0, 200, "s.");
  ASSERT_TRUE(z.ok());
  EXPECT_EQ(*z, (std::vector<double>{100, 120, 140, 160, 180, 190}));
  auto reversed = CoarseSweepZ({190.0, 100.0, 20.0, 5.0}, 0.0, 1000.0, 200, "s.");
  ASSERT_TRUE(reversed.ok());
  EXPECT_EQ(*reversed, *z);  // the window is normalised low .. high
  struct Case {
    ZRangeSearchSettings s;
    const char* field;
  };
  const Case cases[] = {
      {{-10.0, 100.0, 20.0, 0.0}, "s.window_start_um"}, {{100.0, 1100.0, 20.0, 0.0}, "s.window_end_um"},
      {{100.0, 100.0, 20.0, 0.0}, "s.window_start_um"}, {{100.0, 130.0, 20.0, 0.0}, "s.coarse_step_um"},
      {{100.0, 300.0, 0.0, 0.0}, "s.coarse_step_um"},   {{0.0, 1000.0, 1.0, 0.0}, "s.coarse_step_um"},
  };
  for (const Case& c : cases) {
    auto r = CoarseSweepZ(c.s, 0.0, 1000.0, 200, "s.");
    ASSERT_FALSE(r.ok()) << c.field;
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(r.status().message().find(c.field), std::string::npos) << r.status().message();
  }
}

TEST(ChooseFineRangeTest, WholeStepsCentredOnTheRangeWithinTheTravel) {
  ZRangeEstimate e;
  e.z_low_um = 203.0;
  e.z_high_um = 231.0;
  // 203 - 7.5 .. 231 + 7.5 = 43 um -> 9 steps of 5 um = 45 um, the extra 2 um shared.
  FineRange r = ChooseFineRange(e, 5.0, 7.5, 3, 0.0, 25000.0);
  EXPECT_NEAR(r.z_start_um, 194.5, 1e-9);
  EXPECT_NEAR(r.z_end_um, 239.5, 1e-9);
  // A flat part still gets min_frames frames (3 at least), centred on it.
  e.z_low_um = e.z_high_um = 300.0;
  r = ChooseFineRange(e, 5.0, 0.0, 1, 0.0, 25000.0);
  EXPECT_NEAR(r.z_end_um - r.z_start_um, 10.0, 1e-9);
  EXPECT_NEAR(0.5 * (r.z_start_um + r.z_end_um), 300.0, 1e-9);
  r = ChooseFineRange(e, 5.0, 7.5, 12, 0.0, 25000.0);
  EXPECT_NEAR(r.z_end_um - r.z_start_um, 55.0, 1e-9);
  EXPECT_NEAR(0.5 * (r.z_start_um + r.z_end_um), 300.0, 1e-9);
  // At the travel's end the range is shifted inside, not cut.
  e.z_low_um = 2.0;
  e.z_high_um = 20.0;
  r = ChooseFineRange(e, 5.0, 5.0, 3, 0.0, 25000.0);
  EXPECT_DOUBLE_EQ(r.z_start_um, 0.0);
  EXPECT_NEAR(r.z_end_um, 30.0, 1e-9);
}

// The sweep may stop once the field has settled (ZRangeSearchOptions::stop_settled_percent):
// each half of the two-level part counts once the sweep is two frames past its focus frame
// (233 um: frame 240 at index 7, settled from index 9; 271 um: frame 280 at index 9, settled
// from index 11); a textureless half never counts. The 3 of 64 reduced columns whose window
// straddles the 38 um step see both levels (two peaks: not sharp) and never settle; with the
// right half textureless they see the left half's texture alone and settle with it.
TEST(ZRangeAccumulatorTest, FieldSettlesTwoFramesPastEachLevelsFocus) {
  for (bool right_textured : {true, false}) {
    auto acc = ZRangeAccumulator::Create(ZRangeSearchOptions{}, cv::Size(256, 192), 8);
    ASSERT_TRUE(acc.ok());
    EXPECT_DOUBLE_EQ(acc->SettledPercent(), 0.0);
    std::vector<double> settled;
    uint64_t seed = 1;
    for (double z = 100.0; z <= 400.0 + 1e-9; z += 20.0) {
      cv::Mat frame = Frame(233.0, 271.0, z, seed++);
      if (!right_textured) frame(cv::Rect(128, 0, 128, 192)).setTo(128);
      ASSERT_TRUE(acc->PushFrame(frame, z).ok());
      settled.push_back(acc->SettledPercent());
    }
    const std::string which = right_textured ? "textured" : "half textureless";
    const double step_columns = 100.0 * 3.0 / 64.0;
    EXPECT_LT(settled[8], 2.0) << which;
    if (right_textured) {
      EXPECT_NEAR(settled[9], 50.0 - step_columns / 3.0, 1.0);
      EXPECT_NEAR(settled[10], 50.0 - step_columns / 3.0, 1.0);
      EXPECT_NEAR(settled[11], 100.0 - step_columns, 0.5);
      EXPECT_NEAR(settled.back(), 100.0 - step_columns, 0.5);
    } else {
      EXPECT_NEAR(settled[9], 50.0 + 2.0 * step_columns / 3.0 + step_columns / 3.0, 1.0);
      EXPECT_NEAR(*std::max_element(settled.begin(), settled.end()), settled[9], 1e-9);
    }
  }
}

// A sweep of 100 .. 400 um at 20 um with the refinement PlanRefinement asks for; the estimate
// before (*coarse) and after it.
StatusOr<ZRangeEstimate> RefinedSweep(double h_left, double h_right, double blur_px_per_um,
                                          ZRangeEstimate* coarse, std::vector<double>* refine_z) {
  INSPECT_ASSIGN_OR_RETURN(ZRangeAccumulator acc,
                           ZRangeAccumulator::Create(ZRangeSearchOptions{}, cv::Size(256, 192), 8));
  uint64_t seed = 1;
  for (double z = 100.0; z <= 400.0 + 1e-9; z += 20.0) {
    INSPECT_RETURN_IF_ERROR(acc.PushFrame(Frame(h_left, h_right, z, seed++, true, blur_px_per_um), z));
  }
  INSPECT_ASSIGN_OR_RETURN(*coarse, acc.Finish());
  *refine_z = acc.PlanRefinement(*coarse);
  for (double z : *refine_z) {
    INSPECT_RETURN_IF_ERROR(acc.PushRefinementFrame(Frame(h_left, h_right, z, seed++, true, blur_px_per_um), z));
  }
  return acc.Finish();
}

// A flat part between two coarse frames with a focus curve about as wide as the coarse step
// (blur 0.8 px per um): the three coarse samples around the maximum place its vertex up to 7 um
// off, as the coin's field was (its neighbours sit on the curve's tails). Two frames half a
// step either side of the frame nearest the found range bring both ends within 2.5 um.
TEST(ZRangeAccumulatorTest, RefinementFramesBringAFlatPartsEndsToItsHeight) {
  double worst_coarse = 0.0;
  for (double h : {243.0, 247.0, 251.0, 255.0}) {
    ZRangeEstimate coarse;
    std::vector<double> refine_z;
    auto e = RefinedSweep(h, h, 0.8, &coarse, &refine_z);
    ASSERT_TRUE(e.ok()) << e.status().ToString();
    worst_coarse = std::max({worst_coarse, std::abs(coarse.z_low_um - h), std::abs(coarse.z_high_um - h)});
    EXPECT_NEAR(e->z_low_um, h, 2.5) << h;
    EXPECT_NEAR(e->z_high_um, h, 2.5) << h;
    EXPECT_LT(e->z_high_um - e->z_low_um, 3.5) << h;
    // Midpoints between coarse frames, 2 or 3 (the two ends nearest different frames).
    ASSERT_GE(refine_z.size(), 2u) << h;
    ASSERT_LE(refine_z.size(), 3u) << h;
    EXPECT_TRUE(std::is_sorted(refine_z.begin(), refine_z.end()));
    for (double z : refine_z) EXPECT_NEAR(std::fmod(z - 100.0, 20.0), 10.0, 1e-9) << h;
    EXPECT_GE(refine_z.front(), h - 30.0) << h;
    EXPECT_LE(refine_z.back(), h + 30.0) << h;
  }
  EXPECT_GT(worst_coarse, 5.0) << "the coarse samples alone place this part well";
}

TEST(ZRangeAccumulatorTest, RefinementOfATwoLevelPartSamplesBothEnds) {
  ZRangeEstimate coarse;
  std::vector<double> refine_z;
  auto e = RefinedSweep(233.0, 271.0, 0.4, &coarse, &refine_z);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  // The ends are nearest the frames at 240 and 280 um.
  EXPECT_EQ(refine_z, (std::vector<double>{230.0, 250.0, 270.0, 290.0}));
  EXPECT_NEAR(e->z_low_um, 233.0, 2.5);
  EXPECT_NEAR(e->z_high_um, 271.0, 2.5);
  EXPECT_NEAR(e->resolved_percent, coarse.resolved_percent, 1.0);
}

// A refined curve that falls away from its largest sample and rises again by more than 1/e^2
// of it holds two sources of focus energy within one coarse step (a halo beside a surface):
// the pixel is dropped. Here the refinement frame at 250 um shows no texture while the part at
// 248 um is sharpest at 240 and still textured at 260.
TEST(ZRangeAccumulatorTest, RefinedSamplesThatDipAndRiseAgainAreDropped) {
  auto acc = ZRangeAccumulator::Create(ZRangeSearchOptions{}, cv::Size(256, 192), 8);
  ASSERT_TRUE(acc.ok());
  uint64_t seed = 1;
  for (double z = 100.0; z <= 400.0 + 1e-9; z += 20.0) ASSERT_TRUE(acc->PushFrame(Frame(248, 248, z, seed++), z).ok());
  auto coarse = acc->Finish();
  ASSERT_TRUE(coarse.ok());
  EXPECT_GT(coarse->resolved_percent, 90.0);
  EXPECT_EQ(acc->PlanRefinement(*coarse), (std::vector<double>{230.0, 250.0}));  // around 240
  ASSERT_TRUE(acc->PushRefinementFrame(cv::Mat(192, 256, CV_8UC1, cv::Scalar(128)), 250.0).ok());
  auto refined = acc->Finish();
  ASSERT_FALSE(refined.ok());  // every pixel's samples dip at 250 and rise at 260
  EXPECT_EQ(refined.status().code(), StatusCode::kFailedPrecondition);
}

TEST(ZRangeAccumulatorTest, RefinementFramesAreCheckedAndEndTheSweep) {
  auto acc = ZRangeAccumulator::Create(ZRangeSearchOptions{}, cv::Size(256, 192), 8);
  ASSERT_TRUE(acc.ok());
  EXPECT_EQ(acc->PushRefinementFrame(Frame(0, 0, 0, 1), 10.0).code(), StatusCode::kFailedPrecondition);
  for (double z : {0.0, 20.0, 40.0}) ASSERT_TRUE(acc->PushFrame(Frame(20, 20, z, 1), z).ok());
  EXPECT_EQ(acc->PushRefinementFrame(Frame(20, 20, 10, 3), 10.0).code(), StatusCode::kFailedPrecondition);
  ZRangeEstimate flat;
  flat.z_low_um = flat.z_high_um = 20.0;
  EXPECT_EQ(acc->PlanRefinement(flat), (std::vector<double>{10.0, 30.0}));
  EXPECT_EQ(acc->PushRefinementFrame(cv::Mat(10, 10, CV_8UC1), 10.0).code(), StatusCode::kInvalidArgument);
  for (double z : {-5.0, 0.0, 20.0, 25.0, 45.0}) {
    const Status s = acc->PushRefinementFrame(Frame(20, 20, z, 2), z);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << z;
    EXPECT_NE(s.message().find("refinement frame 0"), std::string::npos) << s.message();
  }
  ASSERT_TRUE(acc->PushRefinementFrame(Frame(20, 20, 10, 3), 10.0).ok());
  EXPECT_EQ(acc->refinement_frames(), 1);
  EXPECT_EQ(acc->PushRefinementFrame(Frame(20, 20, 10, 3), 10.0).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(acc->PushFrame(Frame(20, 20, 60, 4), 60.0).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(acc->frames(), 3);
}

TEST(SearchPatternCoarseStepTest, FollowsTheOpticsRoundedDown) {
  // 2 P / (pi k), P = 4 projector px: thesis rig 20.37 -> 20 um.
  EXPECT_DOUBLE_EQ(SearchPatternCoarseStepUm(0.425, 3.4), 20.0);
  EXPECT_DOUBLE_EQ(SearchPatternCoarseStepUm(0.425 / 2.0, 3.4), 40.0);  // half the NA-ish blur: 40.7
  EXPECT_DOUBLE_EQ(SearchPatternCoarseStepUm(5.0, 3.4), 1.5);           // 1.73 -> half um
  EXPECT_DOUBLE_EQ(SearchPatternCoarseStepUm(50.0, 3.4), 0.5);          // never below 0.5
  EXPECT_DOUBLE_EQ(SearchPatternCoarseStepUm(0.0, 3.4), 0.0);           // unknown optics
  EXPECT_DOUBLE_EQ(SearchPatternCoarseStepUm(0.425, 0.0), 0.0);
}

}  // namespace
}  // namespace inspection
