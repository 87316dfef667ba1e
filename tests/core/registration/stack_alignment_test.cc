// Frame registration and the focus-breathing model (core/registration/frame_registration.h,
// core/registration/stack_alignment.h) on synthetic frames with known scale, rotation and shift.
#include "core/registration/stack_alignment.h"
#include "core/sff/stack_reconstruct.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <string>
#include <opencv2/imgproc.hpp>
#include <random>

namespace inspection {
namespace {

// Band-limited random texture (grey ~128 +- 60), larger detail than one pixel.
cv::Mat Texture(cv::Size size, unsigned seed) {
  cv::Mat t(size, CV_32F);
  std::mt19937 rng(seed);
  std::normal_distribution<float> n(0.f, 1.f);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) t.at<float>(y, x) = n(rng);
  cv::GaussianBlur(t, t, cv::Size(0, 0), 1.5);
  cv::Scalar mean, sd;
  cv::meanStdDev(t, mean, sd);
  return 128.0 + (t - mean[0]) * (40.0 / sd[0]);
}

// The texture seen through `t` (reference -> frame), blurred by blur_px, with noise, 8-bit.
cv::Mat Render(const cv::Mat& texture, const SimilarityTransform& t, double blur_px, unsigned seed) {
  const cv::Point2d c((texture.cols - 1) * 0.5, (texture.rows - 1) * 0.5);
  // The frame pixel p shows the texture at F^-1(p).
  cv::Mat warped;
  cv::warpAffine(texture, warped, FrameFromReference(t, c), texture.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT_101);
  if (blur_px > 0) cv::GaussianBlur(warped, warped, cv::Size(0, 0), blur_px);
  cv::Mat noise(texture.size(), CV_32F);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
  cv::Mat out;
  cv::Mat(warped + noise).convertTo(out, CV_8U);
  return out;
}

TEST(FrameRegistrationTest, RecoversScaleRotationAndShiftBetweenDifferentlyBlurredFrames) {
  const cv::Mat texture = Texture({640, 480}, 3);
  SimilarityTransform truth;
  truth.scale = 1.021;
  truth.rotation_rad = 0.004;
  truth.shift_x_px = 3.6;
  truth.shift_y_px = -2.3;
  const cv::Mat reference = Render(texture, {}, 0.8, 1);
  const cv::Mat frame = Render(texture, truth, 1.6, 2);  // another defocus
  auto r = RegisterFrame(reference, frame, {});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_NEAR(r->transform.scale, truth.scale, 5e-4);
  EXPECT_NEAR(r->transform.rotation_rad, truth.rotation_rad, 5e-4);
  EXPECT_NEAR(r->transform.shift_x_px, truth.shift_x_px, 0.1);
  EXPECT_NEAR(r->transform.shift_y_px, truth.shift_y_px, 0.1);
  EXPECT_GT(r->correlation, 0.9);
}

// The AVX2 kernel (float lanes per row, where the CPU has it) and the portable double loop give
// the same transform to far below the registration's accuracy, on a transform with every part.
TEST(FrameRegistrationTest, VectorisedAndPortableSumsGiveTheSameTransform) {
  const cv::Mat texture = Texture({640, 480}, 5);
  SimilarityTransform truth;
  truth.scale = 0.985;
  truth.rotation_rad = -0.003;
  truth.shift_x_px = -4.2;
  truth.shift_y_px = 1.7;
  const cv::Mat reference = Render(texture, {}, 0.8, 3);
  const cv::Mat frame = Render(texture, truth, 1.4, 4);
  FrameRegistrationOptions portable;
  portable.use_simd = false;
  auto a = RegisterFrame(reference, frame, {});
  auto b = RegisterFrame(reference, frame, portable);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_NEAR(a->transform.scale, b->transform.scale, 1e-6);
  EXPECT_NEAR(a->transform.rotation_rad, b->transform.rotation_rad, 1e-6);
  EXPECT_NEAR(a->transform.shift_x_px, b->transform.shift_x_px, 1e-4);
  EXPECT_NEAR(a->transform.shift_y_px, b->transform.shift_y_px, 1e-4);
  EXPECT_NEAR(a->correlation, b->correlation, 1e-6);
  EXPECT_NEAR(b->transform.scale, truth.scale, 5e-4);
  EXPECT_NEAR(b->transform.shift_x_px, truth.shift_x_px, 0.1);
}

// Frames over twice max_side_px are first shrunk by a whole factor as stored (8 or 16 bit), then
// in float: the transform is still found to the same accuracy in full-frame pixels.
TEST(FrameRegistrationTest, LargeFramesShrunkByAWholeFactorFirstRegisterAsAccurately) {
  const cv::Mat texture = Texture({1200, 900}, 4);  // shrink 2 (as stored), then 600 -> 512 in float
  SimilarityTransform truth;
  truth.scale = 0.988;
  truth.rotation_rad = -0.003;
  truth.shift_x_px = -5.2;
  truth.shift_y_px = 2.7;
  const cv::Mat reference = Render(texture, {}, 1.0, 1), frame = Render(texture, truth, 1.8, 2);
  for (int depth : {CV_8U, CV_16U}) {
    cv::Mat a, b;
    reference.convertTo(a, depth, depth == CV_16U ? 256.0 : 1.0);
    frame.convertTo(b, depth, depth == CV_16U ? 256.0 : 1.0);
    auto r = RegisterFrame(a, b, {});
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_NEAR(r->transform.scale, truth.scale, 5e-4) << depth;
    EXPECT_NEAR(r->transform.rotation_rad, truth.rotation_rad, 5e-4) << depth;
    EXPECT_NEAR(r->transform.shift_x_px, truth.shift_x_px, 0.15) << depth;
    EXPECT_NEAR(r->transform.shift_y_px, truth.shift_y_px, 0.15) << depth;
  }
}

TEST(FrameRegistrationTest, LargeDriftIsFoundByThePhaseCorrelationStart) {
  const cv::Mat texture = Texture({512, 384}, 5);
  SimilarityTransform truth;
  truth.shift_x_px = -23.0;
  truth.shift_y_px = 17.5;
  auto r = RegisterFrame(Render(texture, {}, 0.7, 1), Render(texture, truth, 0.7, 2), {});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_NEAR(r->transform.shift_x_px, -23.0, 0.1);
  EXPECT_NEAR(r->transform.shift_y_px, 17.5, 0.1);
  EXPECT_NEAR(r->transform.scale, 1.0, 5e-4);
}

TEST(FrameRegistrationTest, FeaturelessOrUnrelatedFramesFailWithAClearStatus) {
  cv::Mat flat(256, 256, CV_8U, cv::Scalar(128));
  cv::Mat noisy = flat.clone();
  cv::randn(noisy, 128, 2);
  auto r = RegisterFrame(flat, noisy, {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition) << r.status().ToString();
  auto u = RegisterFrame(Render(Texture({256, 256}, 1), {}, 0.7, 1), Render(Texture({256, 256}, 2), {}, 0.7, 2), {});
  ASSERT_FALSE(u.ok());
  EXPECT_EQ(u.status().code(), StatusCode::kFailedPrecondition) << u.status().ToString();
  auto small = RegisterFrame(cv::Mat(16, 16, CV_8U), cv::Mat(16, 16, CV_8U), {});
  EXPECT_EQ(small.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(small.status().message().find("32x32"), std::string::npos);
}

// A stack through z with known breathing, rotation and drift, each frame at its own defocus.
struct BreathingStack {
  std::vector<cv::Mat> frames;
  std::vector<double> z_um;
  FocusBreathingModel truth;
};

BreathingStack MakeStack(cv::Size size, int n, double dz, double scale, double rot, double dx, double dy,
                         double blur_per_um = 0.05) {
  BreathingStack s;
  s.truth.frame_size = size;
  s.truth.reference_z_um = 0.0;
  s.truth.scale_change_per_100um = scale;
  s.truth.rotation_rad_per_100um = rot;
  s.truth.shift_x_px_per_100um = dx;
  s.truth.shift_y_px_per_100um = dy;
  const cv::Mat texture = Texture(size, 9);
  const double z_focus = dz * (n - 1) * 0.4;
  for (int i = 0; i < n; ++i) {
    const double z = i * dz;
    s.z_um.push_back(z);
    s.frames.push_back(Render(texture, s.truth.At(z), 0.6 + blur_per_um * std::abs(z - z_focus), 100 + i));
  }
  return s;
}

TEST(StackAlignmentTest, EstimatesTheBreathingModelFromNeighbourPairs) {
  const BreathingStack s = MakeStack({512, 384}, 15, 10.0, 0.025, 0.003, 4.0, -2.5);
  auto m = EstimateFocusBreathing([&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; }, s.z_um, {});
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_NEAR(m->scale_change_per_100um, 0.025, 5e-4);
  EXPECT_NEAR(m->rotation_rad_per_100um, 0.003, 4e-4);
  EXPECT_NEAR(m->shift_x_px_per_100um, 4.0, 0.15);
  EXPECT_NEAR(m->shift_y_px_per_100um, -2.5, 0.15);
  EXPECT_LT(m->fit_rms_px, 0.3);
  EXPECT_EQ(m->frames, 15);
  // The last frame's corners land within 0.5 px of the truth.
  const cv::Matx23d a = m->FrameFromReference(140.0, 0.0), b = s.truth.FrameFromReference(140.0, 0.0);
  const cv::Vec3d corner(511, 383, 1);
  EXPECT_LT(cv::norm(a * corner - b * corner), 0.5);
}

// neighbour pairs registered concurrently give the sequential estimate bit for bit.
TEST(StackAlignmentTest, ConcurrentPairsGiveTheSequentialModelExactly) {
  const BreathingStack s = MakeStack({320, 240}, 11, 10.0, 0.02, 0.002, 3.0, -2.0);
  auto load = [&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; };
  auto sequential = EstimateFocusBreathing(load, s.z_um, {});
  ASSERT_TRUE(sequential.ok()) << sequential.status().ToString();
  for (int threads : {0, 2, 3}) {
    StackAlignmentOptions o;
    o.threads = threads;
    auto concurrent = EstimateFocusBreathing(load, s.z_um, o);
    ASSERT_TRUE(concurrent.ok()) << concurrent.status().ToString();
    EXPECT_EQ(concurrent->scale_change_per_100um, sequential->scale_change_per_100um) << threads;
    EXPECT_EQ(concurrent->rotation_rad_per_100um, sequential->rotation_rad_per_100um) << threads;
    EXPECT_EQ(concurrent->shift_x_px_per_100um, sequential->shift_x_px_per_100um) << threads;
    EXPECT_EQ(concurrent->shift_y_px_per_100um, sequential->shift_y_px_per_100um) << threads;
    EXPECT_EQ(concurrent->fit_rms_px, sequential->fit_rms_px) << threads;
    EXPECT_EQ(concurrent->frames, sequential->frames) << threads;
  }
  // A frame of another size is still named, concurrently or not.
  std::vector<cv::Mat> frames = s.frames;
  frames[6] = cv::Mat(200, 300, CV_8UC1, cv::Scalar(0));
  auto bad = [&](int i) -> StatusOr<cv::Mat> { return frames[size_t(i)]; };
  StackAlignmentOptions o;
  o.threads = 2;
  const Status a = EstimateFocusBreathing(bad, s.z_um, {}).status(), b = EstimateFocusBreathing(bad, s.z_um, o).status();
  EXPECT_EQ(a.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(a.message(), "frame 6 differs in size");
  EXPECT_EQ(b.code(), a.code());
  EXPECT_EQ(b.message(), a.message());
}

// A stack that does not move is decided by the half-size estimate alone (each frame loaded
// once); a moving one gets the full estimate, exactly the model without the coarse pass.
TEST(StackAlignmentTest, CoarseEstimateFirstDecidesStacksThatDoNotMove) {
  for (const bool moving : {false, true}) {
    SCOPED_TRACE(moving ? "moving" : "still");
    const BreathingStack s = moving ? MakeStack({512, 384}, 13, 10.0, 0.02, 0.002, 3.0, -2.0)
                                    : MakeStack({512, 384}, 13, 10.0, 0.0, 0.0, 0.0, 0.0);
    int loads = 0;
    auto counting = [&](int i) -> StatusOr<cv::Mat> {
      ++loads;
      return s.frames[size_t(i)];
    };
    StackAlignmentOptions full_only;
    full_only.coarse_first = false;
    auto full = EstimateFocusBreathing(counting, s.z_um, full_only);
    ASSERT_TRUE(full.ok()) << full.status().ToString();
    const int full_loads = loads;
    loads = 0;
    auto m = EstimateFocusBreathing(counting, s.z_um, {});
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    if (!moving) {
      EXPECT_EQ(loads, full_loads) << "one estimate, at half size";
      EXPECT_LT(MaxCornerDisplacementPx(*m, s.z_um), kNegligibleAlignmentPx);
      EXPECT_LT(MaxCornerDisplacementPx(*full, s.z_um), kNegligibleAlignmentPx);
      auto aligner = StackAligner::Create(*m, FrameAlignment::kEstimate, s.z_um, s.frames[0].size());
      ASSERT_TRUE(aligner.ok());
      EXPECT_FALSE(aligner->warps());
    } else {
      EXPECT_EQ(loads, 2 * full_loads) << "the coarse pass, then the full estimate";
      EXPECT_EQ(m->scale_change_per_100um, full->scale_change_per_100um);
      EXPECT_EQ(m->rotation_rad_per_100um, full->rotation_rad_per_100um);
      EXPECT_EQ(m->shift_x_px_per_100um, full->shift_x_px_per_100um);
      EXPECT_EQ(m->shift_y_px_per_100um, full->shift_y_px_per_100um);
      EXPECT_NEAR(m->scale_change_per_100um, 0.02, 5e-4);
    }
  }
}

// The estimate's rates are tested against their pairs' scatter (FocusBreathingModel::
// still_statistic): an apparent scale that grows by 0.4 % and shrinks back through the stack (as
// defocus makes a still scene look, 1.3 px at the corners) is no linear breathing: its median
// rate is within the scatter, the rate is 0 and the frames stay as captured (a shift rate of
// ~0.01 px per 100 um may come out significant, and stays: it moves nothing). The same 0.4 % as a
// constant rate (real breathing) is significant, kept and warped.
TEST(StackAlignmentTest, RatesThatReverseThroughTheStackAreNotBreathing) {
  const cv::Size size(512, 384);
  const cv::Mat texture = Texture(size, 9);
  const int n = 13;
  for (const bool reversing : {true, false}) {
    SCOPED_TRACE(reversing ? "reversing" : "constant rate");
    std::vector<cv::Mat> frames;
    std::vector<double> z_um;
    for (int i = 0; i < n; ++i) {
      const double z = 10.0 * i, u = double(i) / (n - 1);
      SimilarityTransform t;
      t.scale = 1.0 + 0.004 * (reversing ? 1.0 - std::abs(2.0 * u - 1.0) : u);
      z_um.push_back(z);
      frames.push_back(Render(texture, t, 0.6 + 0.02 * std::abs(z - 50.0), 300 + unsigned(i)));
    }
    StackAlignmentOptions o;
    o.coarse_first = false;
    auto m = EstimateFocusBreathing([&](int i) -> StatusOr<cv::Mat> { return frames[size_t(i)]; }, z_um, o);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    ASSERT_GT(m->still_threshold, 2.5);  // Student t, 11 degrees of freedom, 1 % over four rates
    auto aligner = StackAligner::Create(*m, FrameAlignment::kEstimate, z_um, size);
    ASSERT_TRUE(aligner.ok()) << aligner.status().ToString();
    EXPECT_GT(m->still_statistic, 0.0);
    if (reversing) {
      EXPECT_EQ(m->scale_change_per_100um, 0.0);
      EXPECT_LT(MaxCornerDisplacementPx(*m, z_um), kNegligibleAlignmentPx);
      EXPECT_FALSE(aligner->warps());
      EXPECT_TRUE(aligner->figures().still);
    } else {
      EXPECT_GT(m->still_statistic, m->still_threshold);
      EXPECT_NEAR(m->scale_change_per_100um, 0.004 / 1.2, 3e-4);  // 0.4 % over 120 um
      EXPECT_TRUE(aligner->warps());
      EXPECT_EQ(aligner->figures().still_statistic, m->still_statistic);
    }
  }
}

// The still floor is the caller's: a model moving the corners by 0.75 px warps a rig's scan
// (kNegligibleAlignmentPx, 0.5 px) and leaves an imported stack's default as captured
// (kImportedWarpPaysPx, 1.5 px); a negative floor is an invalid argument.
TEST(StackAlignmentTest, TheStillFloorIsTheCallers) {
  FocusBreathingModel m;
  m.frame_size = cv::Size(400, 300);
  m.shift_x_px_per_100um = 1.5;  // 100 um of stack: 0.75 px either side of the middle frame
  const std::vector<double> z_um = {0, 25, 50, 75, 100};
  EXPECT_NEAR(MaxCornerDisplacementPx(m, z_um), 0.75, 1e-9);
  auto rig = StackAligner::Create(m, FrameAlignment::kEstimate, z_um, m.frame_size);
  ASSERT_TRUE(rig.ok());
  EXPECT_TRUE(rig->warps());
  EXPECT_EQ(kImportedWarpPaysPx, 1.5);
  auto imported = StackAligner::Create(m, FrameAlignment::kEstimate, z_um, m.frame_size, kImportedWarpPaysPx);
  ASSERT_TRUE(imported.ok());
  EXPECT_FALSE(imported->warps());
  EXPECT_TRUE(imported->figures().still);
  EXPECT_NEAR(imported->figures().max_corner_displacement_px, 0.75, 1e-9);
  const Status bad = StackAligner::Create(m, FrameAlignment::kEstimate, z_um, m.frame_size, -1.0).status();
  EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.message(), "min_motion_px must be >= 0");
}

// An imported stack's default (no --alignment, stack.json without illumination) leaves a stack
// whose significant motion moves no corner by kImportedWarpPaysPx (1.5 px) as captured, and says
// so with the figures; one moving more is warped with its transforms recovered. A rig's scan of
// the slowly moving stack keeps the 0.5 px floor and is warped.
TEST(StackAlignmentTest, ImportedDefaultLeavesMotionBelowTheWarpFloorAsCapturedAndSaysSo) {
  const cv::Size size(480, 360);
  const std::atomic<bool> cancel{false};
  struct Case {
    const char* name;
    double dx_per_100um, dy_per_100um;  // 13 frames 10 um apart: the ends are 60 um from the middle
    const char* illumination;
  };
  for (const Case& c : {Case{"imported, 1.1 px", 1.8333, 0.0, ""}, Case{"imported, 3.4 px", 5.0, -2.5, ""},
                        Case{"rig scan, 1.1 px", 1.8333, 0.0, "STD"}}) {
    SCOPED_TRACE(c.name);
    const BreathingStack s = MakeStack(size, 13, 10.0, 0.0, 0.0, c.dx_per_100um, c.dy_per_100um);
    const double corner_px = 0.6 * std::hypot(c.dx_per_100um, c.dy_per_100um);
    StackManifest manifest;
    manifest.illumination = c.illumination;
    for (size_t i = 0; i < s.frames.size(); ++i) manifest.frames.push_back({"f" + std::to_string(i), s.z_um[i], 0.0, ""});
    StackFrameSource source;
    source.frame = [&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; };
    StackFolderAlignment a;
    a.alignment = FrameAlignment::kEstimate;
    a.fall_back_to_none = true;  // the default
    AlignmentFigures f;
    auto r = ReconstructStackFrames(manifest, source, SffOptions{}, {}, cancel, a, &f);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_EQ(f.alignment, FrameAlignment::kEstimate);
    EXPECT_EQ(f.method, "model");
    EXPECT_GT(f.still_statistic, f.still_threshold);  // the motion is significant in every case
    EXPECT_NEAR(f.max_corner_displacement_px, corner_px, 0.15);
    ASSERT_EQ(f.frame_from_reference.size(), 13u);
    if (std::string(c.name) == "imported, 1.1 px") {
      EXPECT_TRUE(f.still);
      EXPECT_DOUBLE_EQ(f.seen_by_every_frame_percent, 100.0);
      // The still line's "why": the motion, its significance and the floor.
      EXPECT_NE(f.decision.find("the frames move (still statistic "), std::string::npos) << f.decision;
      EXPECT_NE(f.decision.find("px at most at the corners, below the 1.5 px where a warp starts to pay in depth "
                                "accuracy; used as captured"),
                std::string::npos)
          << f.decision;
      const double said = std::atof(f.decision.substr(f.decision.find(" but by ") + 8).c_str());
      EXPECT_NEAR(said, corner_px, 0.15) << f.decision;
      continue;
    }
    // Warped: every frame's transform within 0.25 px of the truth at the frame's corners.
    EXPECT_FALSE(f.still);
    EXPECT_TRUE(f.decision.empty()) << f.decision;
    EXPECT_LT(f.seen_by_every_frame_percent, 100.0);
    for (int i = 0; i < 13; ++i) {
      const cv::Matx23d truth = s.truth.FrameFromReference(s.z_um[size_t(i)], s.z_um[6]);
      for (cv::Vec3d p : {cv::Vec3d(0, 0, 1), cv::Vec3d(479, 0, 1), cv::Vec3d(0, 359, 1), cv::Vec3d(479, 359, 1)})
        EXPECT_LT(cv::norm(f.frame_from_reference[size_t(i)] * p - truth * p), 0.25) << "frame " << i;
    }
  }
}

// a long stack registers a chain of frames `stride` apart (max_pairs); the model
// matches the truth as the all-neighbour estimate does, and a pair is named by its frames.
TEST(StackAlignmentTest, LongStacksRegisterAChainOfFramesStrideApart) {
  const BreathingStack s = MakeStack({256, 192}, 41, 5.0, 0.02, 0.002, 3.0, -2.0, 0.03);
  auto load = [&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; };
  int loads = 0;
  auto counting = [&](int i) -> StatusOr<cv::Mat> {
    ++loads;
    return s.frames[size_t(i)];
  };
  StackAlignmentOptions every, chain;
  every.max_pairs = 0;
  chain.max_pairs = 10;  // stride 4: frames 0, 4, ..., 40
  chain.coarse_first = false;  // one pass, so the loads count the chain (the coarse pass: above)
  auto all = EstimateFocusBreathing(load, s.z_um, every);
  auto strided = EstimateFocusBreathing(counting, s.z_um, chain);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  ASSERT_TRUE(strided.ok()) << strided.status().ToString();
  EXPECT_EQ(loads, 11);
  EXPECT_EQ(strided->frames, 41);
  for (const FocusBreathingModel* m : {&*all, &*strided}) {
    EXPECT_NEAR(m->scale_change_per_100um, 0.02, 5e-4);
    EXPECT_NEAR(m->rotation_rad_per_100um, 0.002, 4e-4);
    EXPECT_NEAR(m->shift_x_px_per_100um, 3.0, 0.2);
    EXPECT_NEAR(m->shift_y_px_per_100um, -2.0, 0.2);
  }
  // Frames from 18 on jump 6 px sideways: the jump falls inside the chain's pair 16->20, which
  // disagrees with the model, and is named so.
  std::vector<cv::Mat> jumped = s.frames;
  for (int i = 18; i < 41; ++i) {
    cv::warpAffine(s.frames[size_t(i)], jumped[size_t(i)], cv::Matx23d(1, 0, 6, 0, 1, 0), s.frames[0].size(),
                   cv::INTER_LINEAR, cv::BORDER_REFLECT_101);
  }
  chain.max_failed_pair_share = 0.05;
  auto failed = EstimateFocusBreathing([&](int i) -> StatusOr<cv::Mat> { return jumped[size_t(i)]; }, s.z_um, chain);
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(failed.status().message().find("1 of 10 disagree"), std::string::npos) << failed.status().ToString();
  EXPECT_NE(failed.status().message().find(": 16->20)"), std::string::npos) << failed.status().ToString();
  chain.max_pairs = 1;
  EXPECT_EQ(EstimateFocusBreathing(load, s.z_um, chain).status().code(), StatusCode::kInvalidArgument);
}

TEST(StackAlignmentTest, AlignerWarpsEveryFrameOntoTheMiddleFrame) {
  const BreathingStack s = MakeStack({320, 240}, 9, 10.0, 0.03, 0.0, 6.0, 3.0, 0.0);  // all frames equally sharp
  auto a = StackAligner::Create(s.truth, FrameAlignment::kCalibrated, s.z_um, {320, 240});
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->figures().reference_frame, 4);
  // Frame 8 against frame 4: s = 1.024 / 1.012, shift d8 - s d4 = (4.8, 2.4) - s (2.4, 1.2).
  const double s84 = 1.024 / 1.012;
  EXPECT_NEAR(a->figures().max_scale_change_percent, 100 * (s84 - 1), 1e-9);
  EXPECT_NEAR(a->figures().max_shift_px, std::hypot(4.8 - s84 * 2.4, 2.4 - s84 * 1.2), 1e-9);
  // The first frame warped back matches the reference frame (up to noise and resampling).
  auto w0 = a->Warp(s.frames[0], 0);
  ASSERT_TRUE(w0.ok());
  cv::Mat w, r;
  cv::GaussianBlur(*w0, w, cv::Size(0, 0), 2.5);
  cv::GaussianBlur(s.frames[4], r, cv::Size(0, 0), 2.5);
  const cv::Rect inner(40, 40, 240, 160);
  cv::Mat diff;
  cv::absdiff(w(inner), r(inner), diff);
  EXPECT_LT(cv::mean(diff)[0], 1.0);
  cv::Mat unaligned;
  cv::GaussianBlur(s.frames[0], unaligned, cv::Size(0, 0), 2.5);
  cv::absdiff(unaligned(inner), r(inner), diff);
  EXPECT_GT(cv::mean(diff)[0], 4.0);  // the comparison above can fail
  // Seen by every frame: frames at +-40 um shrink/grow the field by 1.2 % and move it by a few px.
  EXPECT_LT(a->figures().seen_by_every_frame_percent, 99.0);
  EXPECT_GT(a->figures().seen_by_every_frame_percent, 90.0);
  EXPECT_EQ(a->seen_by_every_frame().at<uint8_t>(120, 160), 255);
  EXPECT_EQ(a->seen_by_every_frame().at<uint8_t>(0, 0), 0);
  DepthResult d;
  d.depth_um = cv::Mat(240, 320, CV_32F, cv::Scalar(5.0f));
  d.confidence = cv::Mat(240, 320, CV_32F, cv::Scalar(1.0f));
  MaskUnseenPixels(*a, &d);
  EXPECT_TRUE(std::isnan(d.depth_um.at<float>(0, 0)));
  EXPECT_EQ(d.depth_um.at<float>(120, 160), 5.0f);
  EXPECT_NEAR(d.valid_fraction * 100, a->figures().seen_by_every_frame_percent, 1e-9);
}

TEST(StackAlignmentTest, TooSmallStacksAndFramesAreInvalidArgumentsNamingWhat) {
  const BreathingStack s = MakeStack({128, 96}, 3, 10.0, 0.02, 0.0, 0.0, 0.0);
  auto load = [&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; };
  auto two = EstimateFocusBreathing(load, {0.0, 10.0}, {});
  EXPECT_EQ(two.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(two.status().message().find("at least 3 frames"), std::string::npos);
  auto tiny = EstimateFocusBreathing([](int) -> StatusOr<cv::Mat> { return cv::Mat(20, 20, CV_8U, cv::Scalar(1)); },
                                     {0.0, 10.0, 20.0}, {});
  EXPECT_EQ(tiny.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(tiny.status().message().find("32x32"), std::string::npos);
  FocusBreathingModel m = s.truth;
  auto other = StackAligner::Create(m, FrameAlignment::kCalibrated, s.z_um, {256, 192});
  EXPECT_EQ(other.status().code(), StatusCode::kFailedPrecondition);
}

TEST(StackAlignmentTest, FeaturelessStackFailsToConvergeInsteadOfSmearing) {
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 6; ++i) {
    cv::Mat f(96, 128, CV_8U);
    cv::randn(f, 128, 1.5);
    frames.push_back(f);
  }
  auto m = EstimateFocusBreathing([&](int i) -> StatusOr<cv::Mat> { return frames[size_t(i)]; },
                                  {0, 10, 20, 30, 40, 50}, {});
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(m.status().message().find("did not converge"), std::string::npos) << m.status().ToString();
}

TEST(StackAlignmentTest, NamesParseBothWays) {
  for (FrameAlignment a : {FrameAlignment::kNone, FrameAlignment::kEstimate, FrameAlignment::kCalibrated}) {
    auto p = ParseFrameAlignment(FrameAlignmentName(a));
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(*p, a);
  }
  EXPECT_EQ(ParseFrameAlignment("auto").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
