// stack.json of a scan records the alignment the engine saw the frames with: the figures and
// every frame's transform of the scan's aligner (AlignmentRecordOf), for a moving stack and for
// a still one (a model that moves no corner by kNegligibleAlignmentPx: frames left as captured).
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "core/io/stack.h"
#include "core/registration/stack_alignment.h"
#include "server/procedures/scan_alignment.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

class ScanManifestAlignmentTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("scan_manifest_alignment_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Writes 5 frames at z 0, 10, .., 40 um and stack.json with the aligner's record; reads it back.
  StatusOr<StackManifest> WriteAndRead(const StackAligner& aligner) {
    StackManifest m;
    m.illumination = "STD";
    for (int i = 0; i < 5; ++i) {
      const std::string name = "frame_" + std::to_string(i) + ".png";
      cv::imwrite((dir_ / name).string(), cv::Mat(size_, CV_8UC1, cv::Scalar(20 * i)));
      m.frames.push_back({name, 10.0 * i, 1000.0, "uniform:128"});
    }
    m.alignment = AlignmentRecordOf(aligner.figures());
    INSPECT_RETURN_IF_ERROR(WriteStackManifest(dir_, m));
    return ReadStackManifest(dir_);
  }

  FocusBreathingModel Model(double scale_per_100um, double shift_x, double shift_y) const {
    FocusBreathingModel model;
    model.frame_size = size_;
    model.reference_z_um = 20.0;  // the middle frame: its grid is the identity
    model.scale_change_per_100um = scale_per_100um;
    model.shift_x_px_per_100um = shift_x;
    model.shift_y_px_per_100um = shift_y;
    return model;
  }

  const std::vector<double> z_{0, 10, 20, 30, 40};
  const cv::Size size_{64, 48};
  fs::path dir_;
};

TEST_F(ScanManifestAlignmentTest, MovingStackRecordsEveryFramesTransform) {
  // 2 % per 100 um and (5, -3) px per 100 um: the middle frame (z 20) is the reference; frame 0
  // is 0.4 % smaller and shifted by (-1, 0.6) px, frame 4 the opposite.
  auto aligner = StackAligner::Create(Model(0.02, 5.0, -3.0), FrameAlignment::kCalibrated, z_, size_);
  ASSERT_TRUE(aligner.ok()) << aligner.status().ToString();
  ASSERT_TRUE(aligner->warps());
  auto m = WriteAndRead(*aligner);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  ASSERT_TRUE(m->alignment.has_value());
  const StackAlignmentRecord& r = *m->alignment;
  EXPECT_EQ(r.alignment, "calibrated");
  EXPECT_EQ(r.method, "model");
  EXPECT_FALSE(r.still);
  EXPECT_EQ(r.reference_frame, 2);
  EXPECT_NEAR(r.max_scale_change_percent, 0.4, 1e-9);
  EXPECT_NEAR(r.max_shift_px, std::hypot(1.0, 0.6), 1e-9);
  EXPECT_EQ(r.seen_by_every_frame_percent, aligner->figures().seen_by_every_frame_percent);
  EXPECT_LT(r.seen_by_every_frame_percent, 100.0);
  ASSERT_EQ(r.frames.size(), 5u);
  const double expected_scale[] = {0.996, 0.998, 1.0, 1.002, 1.004};
  for (int i = 0; i < 5; ++i) {
    const StackFrameTransform& t = r.frames[size_t(i)];
    EXPECT_EQ(t.frame, i);
    EXPECT_NEAR(t.scale, expected_scale[i], 1e-12) << i;
    EXPECT_NEAR(t.rotation_deg, 0.0, 1e-12) << i;
    EXPECT_NEAR(t.shift_x_px, 0.5 * (i - 2), 1e-12) << i;
    EXPECT_NEAR(t.shift_y_px, -0.3 * (i - 2), 1e-12) << i;
    const cv::Matx23d& a = aligner->frame_from_reference(i);
    for (int k = 0; k < 6; ++k) EXPECT_EQ(t.affine[size_t(k)], a(k / 3, k % 3)) << i << " " << k;
  }
}

TEST_F(ScanManifestAlignmentTest, StillStackRecordsStillAndTheTransforms) {
  // 0.01 % per 100 um: < 0.01 px at the corners of a 64x48 frame, below kNegligibleAlignmentPx.
  auto aligner = StackAligner::Create(Model(1e-4, 0.0, 0.0), FrameAlignment::kCalibrated, z_, size_);
  ASSERT_TRUE(aligner.ok()) << aligner.status().ToString();
  ASSERT_FALSE(aligner->warps());
  auto m = WriteAndRead(*aligner);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  ASSERT_TRUE(m->alignment.has_value());
  const StackAlignmentRecord& r = *m->alignment;
  EXPECT_EQ(r.alignment, "calibrated");
  EXPECT_TRUE(r.still);
  EXPECT_EQ(r.seen_by_every_frame_percent, 100.0);
  ASSERT_EQ(r.frames.size(), 5u);
  EXPECT_NEAR(r.frames[0].scale, 1.0 - 2e-5, 1e-12);
  EXPECT_NEAR(r.frames[4].scale, 1.0 + 2e-5, 1e-12);
}

TEST_F(ScanManifestAlignmentTest, NoAlignerRecordsNone) {
  StackManifest m;
  for (int i = 0; i < 3; ++i) {
    const std::string name = "f" + std::to_string(i) + ".png";
    cv::imwrite((dir_ / name).string(), cv::Mat(size_, CV_8UC1, cv::Scalar(1)));
    m.frames.push_back({name, double(i), 0.0, ""});
  }
  m.alignment = AlignmentRecordOf(AlignmentFigures{});
  ASSERT_TRUE(WriteStackManifest(dir_, m).ok());
  auto back = ReadStackManifest(dir_);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_TRUE(back->alignment.has_value());
  EXPECT_EQ(back->alignment->alignment, "none");
  EXPECT_EQ(back->alignment->method, "");
  EXPECT_FALSE(back->alignment->still);
  EXPECT_TRUE(back->alignment->frames.empty());
}

}  // namespace
}  // namespace inspection
