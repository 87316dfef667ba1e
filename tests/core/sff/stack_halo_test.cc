// Halo suppression on a stack's frames (core/sff/stack_halo.h): the frames come again from the
// StackFrameSource, each released after use, resampled as the engine's alignment did; a still
// or unaligned stack gives SuppressHalos' result bit for bit; an alignment that does not fit the
// stack, or a frame that fails to load, is an error naming it.
#include "core/sff/stack_halo.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <set>

#include "tests/core/halo_scene_synthetic.h"

namespace inspection {
namespace {

using testing_halo::HaloScene;
using testing_halo::HaloSceneOptions;

struct Fixture {
  HaloScene scene;
  StackManifest manifest;
  DepthResult raw;
  SffOptions sff;
};

Fixture Make() {
  Fixture f;
  HaloSceneOptions o;
  o.seed = 5;
  f.scene = testing_halo::RenderHaloScene(o);
  for (size_t i = 0; i < f.scene.frames.size(); ++i) {
    f.manifest.frames.push_back({"frame_" + std::to_string(i) + ".png", f.scene.z_um[i], 0.0, ""});
  }
  f.sff.min_confidence = 0.0;
  auto raw = SffEngine::ReconstructInMemory(f.sff, f.scene.frames, f.scene.z_um);
  EXPECT_TRUE(raw.ok()) << raw.status().ToString();
  if (raw.ok()) f.raw = *raw;
  return f;
}

TEST(StackHaloTest, UnalignedAndStillStacksGiveSuppressHalosResult) {
  const Fixture f = Make();
  ASSERT_FALSE(f.raw.depth_um.empty());
  HaloSuppressionFigures direct_figures;
  auto direct = SuppressHalos(
      f.raw, [&](int i) -> StatusOr<cv::Mat> { return f.scene.frames[size_t(i)]; }, f.scene.z_um, f.sff, {},
      &direct_figures);
  ASSERT_TRUE(direct.ok()) << direct.status().ToString();
  ASSERT_GT(direct_figures.reassigned_fraction, 0.01);

  // A still chain: measured transforms, frames used as stored.
  AlignmentFigures still;
  still.alignment = FrameAlignment::kEstimate;
  still.method = "chain";
  still.still = true;
  still.reference_frame = int(f.scene.frames.size() - 1) / 2;
  still.frame_size = f.scene.frames[0].size();
  still.frame_from_reference.assign(f.scene.frames.size(), cv::Matx23d(1, 0, 0.3, 0, 1, -0.2));
  for (const AlignmentFigures& alignment : {AlignmentFigures{}, still}) {
    std::multiset<int> asked, released;
    StackFrameSource source{[&](int i) -> StatusOr<cv::Mat> {
                              asked.insert(i);
                              return f.scene.frames[size_t(i)];
                            },
                            [&](int i) { released.insert(i); }, {}};
    HaloSuppressionFigures figures;
    auto r = SuppressStackHalos(f.raw, f.manifest, source, alignment, f.sff, {}, &figures);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_EQ(figures.reassigned_fraction, direct_figures.reassigned_fraction);
    EXPECT_EQ(cv::countNonZero(r->depth_um != direct->depth_um), 0);
    EXPECT_EQ(cv::norm(r->all_in_focus, direct->all_in_focus, cv::NORM_INF), 0.0);
    // Two passes, each frame released after each use.
    for (int i = 0; i < int(f.scene.frames.size()); ++i) {
      EXPECT_EQ(asked.count(i), 2u) << i;
      EXPECT_EQ(released.count(i), 2u) << i;
    }
  }
}

TEST(StackHaloTest, WarpedStackIsReadAsTheEngineSawIt) {
  const Fixture f = Make();
  ASSERT_FALSE(f.raw.depth_um.empty());
  // Every frame shows the scene 3 px to the left (frame x = scene x + 3); the alignment maps the
  // reference grid back (frame x = reference x - 3), so the warped frames are the scene's again,
  // apart from the first 3 columns, which no frame saw (masked).
  std::vector<cv::Mat> shifted(f.scene.frames.size());
  const cv::Matx23d left(1, 0, -3, 0, 1, 0);
  for (size_t i = 0; i < shifted.size(); ++i) {
    cv::warpAffine(f.scene.frames[i], shifted[i], left, f.scene.frames[i].size(), cv::INTER_NEAREST,
                   cv::BORDER_REPLICATE);
  }
  AlignmentFigures moved;
  moved.alignment = FrameAlignment::kEstimate;
  moved.method = "chain";
  moved.reference_frame = int(shifted.size() - 1) / 2;
  moved.frame_size = shifted[0].size();
  moved.frame_from_reference.assign(shifted.size(), left);
  StackFrameSource source{[&](int i) -> StatusOr<cv::Mat> { return shifted[size_t(i)]; }, {}, {}};
  HaloSuppressionFigures warped_figures, direct_figures;
  auto warped = SuppressStackHalos(f.raw, f.manifest, source, moved, f.sff, {}, &warped_figures);
  ASSERT_TRUE(warped.ok()) << warped.status().ToString();
  auto direct = SuppressHalos(
      f.raw, [&](int i) -> StatusOr<cv::Mat> { return f.scene.frames[size_t(i)]; }, f.scene.z_um, f.sff, {},
      &direct_figures);
  ASSERT_TRUE(direct.ok());
  // Away from those columns (and the windows that reach them), the same decisions as on the
  // scene's own frames.
  const cv::Rect inner(40, 0, shifted[0].cols - 80, shifted[0].rows);
  EXPECT_EQ(cv::countNonZero(warped->depth_um(inner) != direct->depth_um(inner)), 0);
  // The columns no frame saw lose their depth (as the engine's result does after MaskUnseenPixels).
  EXPECT_TRUE(std::isnan(warped->depth_um.at<float>(10, 0)));
  EXPECT_TRUE(std::isnan(warped->depth_um.at<float>(10, 2)));
  EXPECT_FALSE(std::isnan(warped->depth_um.at<float>(10, 3)));
}

TEST(StackHaloTest, BadAlignmentAndFrameErrorsNameThem) {
  const Fixture f = Make();
  ASSERT_FALSE(f.raw.depth_um.empty());
  AlignmentFigures short_alignment;
  short_alignment.alignment = FrameAlignment::kEstimate;
  short_alignment.method = "chain";
  short_alignment.frame_size = f.scene.frames[0].size();
  short_alignment.frame_from_reference.assign(3, cv::Matx23d(1, 0, 1, 0, 1, 0));
  StackFrameSource good{[&](int i) -> StatusOr<cv::Mat> { return f.scene.frames[size_t(i)]; }, {}, {}};
  auto a = SuppressStackHalos(f.raw, f.manifest, good, short_alignment, f.sff, {});
  ASSERT_FALSE(a.ok());
  EXPECT_EQ(a.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(a.status().message().find("3 frame transforms"), std::string::npos) << a.status().ToString();

  StackFrameSource failing{[&](int i) -> StatusOr<cv::Mat> {
                             if (i == 7) return Status::InvalidArgument("cannot decode");
                             return f.scene.frames[size_t(i)];
                           },
                           {}, {}};
  auto b = SuppressStackHalos(f.raw, f.manifest, failing, AlignmentFigures{}, f.sff, {});
  ASSERT_FALSE(b.ok());
  EXPECT_NE(b.status().message().find("frame 7 (frame_7.png)"), std::string::npos) << b.status().ToString();
}

}  // namespace
}  // namespace inspection
