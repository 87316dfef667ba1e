// Lateral alignment end to end on the simulated rig: with 1-3 % focus breathing per
// 100 um and a few px of drift, scans aligned by the calibrated model and stored stacks aligned
// by an estimate come back to within 10 % of the unperturbed rig's RMSE; unaligned they are
// measurably worse. Ground truth: in the grid of the stack's middle frame (the reference).
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <filesystem>

#include "core/metrology/depth_metrics.h"
#include "core/sff/stack_reconstruct.h"
#include "devices/sim/simulated_rig.h"
#include "server/procedures/calibration_procedure.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

struct Case {
  const char* specimen;
  double breathing_percent;       // per 100 um
  double drift_x_px, drift_y_px;  // per 100 um
};

SimulatedRigOptions RigOptions(const Case& c, bool perturbed) {
  SimulatedRigOptions o;
  o.specimen = c.specimen;
  o.camera_size = {640, 480};
  o.seed = 7;
  if (perturbed) {
    o.focus_breathing_percent_per_100um = c.breathing_percent;
    o.lateral_drift_x_px_per_100um = c.drift_x_px;
    o.lateral_drift_y_px_per_100um = c.drift_y_px;
  }
  return o;
}

struct Scored {
  DepthErrorStats error;
  AlignmentFigures alignment;
};

DepthErrorStats Score(const DepthResult& depth, const cv::Mat& truth) {
  return CompareDepth(depth.depth_um, truth, 1e9, 3);  // border: half the 7 px focus window
}

class StackAlignmentScanTest : public ::testing::TestWithParam<Case> {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("stack_alignment_scan_test_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A default-range STD scan; the stack is kept under dir_/name.
  StatusOr<ScanOutcome> Scan(Rig& rig, std::optional<FrameAlignment> alignment, const CalibrationBundle* bundle,
                             const std::string& name) {
    const ScanDefaults d = rig.scan_defaults();
    INSPECT_ASSIGN_OR_RETURN(ScanPlan plan,
                             MakeScanPlan(d.z_start_um, d.z_end_um, d.z_step_um, d.exposure_us, rig.stage()));
    plan.alignment = alignment;
    std::atomic<bool> cancel{false};
    return RunScan(rig, plan, dir_ / name, nullptr, cancel, bundle);
  }

  fs::path dir_;
};

void Print(const char* what, const DepthErrorStats& e, const AlignmentFigures* a = nullptr) {
  std::printf("  %-22s RMSE %.3f um  bias %+.3f um  sigma %.3f um  valid %.1f %%", what, e.rmse_um, e.mean_error_um,
              e.stddev_error_um, e.valid_percent);
  if (a) {
    std::printf("  (scale %.2f %%, shift %.2f px, seen %.1f %%)", a->max_scale_change_percent, a->max_shift_px,
                a->seen_by_every_frame_percent);
  }
  std::printf("\n");
}

TEST_P(StackAlignmentScanTest, AlignmentRestoresTheUnperturbedAccuracy) {
  const Case c = GetParam();
  std::printf("%s, breathing %.1f %%/100um, drift (%.1f, %.1f) px/100um\n", c.specimen, c.breathing_percent,
              c.drift_x_px, c.drift_y_px);
  // Unperturbed rig: the baseline.
  auto plain = CreateSimulatedRig(RigOptions(c, false));
  ASSERT_TRUE(plain.ok());
  auto base = Scan(**plain, FrameAlignment::kNone, nullptr, "plain");
  ASSERT_TRUE(base.ok()) << base.status().ToString();
  const DepthErrorStats e0 = Score(base->depth, base->ground_truth_um);
  Print("unperturbed", e0);

  auto rig = CreateSimulatedRig(RigOptions(c, true));
  ASSERT_TRUE(rig.ok());
  CalibrationOptions co;
  co.steps = {CalibrationStep::kFocusBreathing};
  std::atomic<bool> cancel{false};
  auto bundle = RunCalibration(**rig, co, nullptr, nullptr, cancel);
  ASSERT_TRUE(bundle.ok()) << bundle.status().ToString();
  ASSERT_EQ((*rig)->simulation()->specimen(), c.specimen);  // the calibration restored it

  auto none = Scan(**rig, FrameAlignment::kNone, &*bundle, "none");
  ASSERT_TRUE(none.ok()) << none.status().ToString();
  EXPECT_EQ(none->alignment.alignment, FrameAlignment::kNone);
  const DepthErrorStats en = Score(none->depth, none->ground_truth_um);
  Print("breathing, unaligned", en);

  auto calibrated = Scan(**rig, std::nullopt, &*bundle, "calibrated");  // the default with the model
  ASSERT_TRUE(calibrated.ok()) << calibrated.status().ToString();
  EXPECT_EQ(calibrated->alignment.alignment, FrameAlignment::kCalibrated);
  const DepthErrorStats ec = Score(calibrated->depth, calibrated->ground_truth_um);
  Print("calibrated", ec, &calibrated->alignment);
  // stack.json names what the engine saw: the calibrated model and every frame's transform;
  // the unaligned scan says none.
  auto written = ReadStackManifest(dir_ / "calibrated");
  ASSERT_TRUE(written.ok()) << written.status().ToString();
  ASSERT_TRUE(written->alignment.has_value());
  EXPECT_EQ(written->alignment->alignment, "calibrated");
  EXPECT_EQ(written->alignment->method, "model");
  EXPECT_FALSE(written->alignment->still);
  EXPECT_EQ(written->alignment->max_scale_change_percent, calibrated->alignment.max_scale_change_percent);
  ASSERT_EQ(written->alignment->frames.size(), written->frames.size());
  for (size_t i = 0; i < written->frames.size(); ++i) {
    for (int k = 0; k < 6; ++k) {
      EXPECT_EQ(written->alignment->frames[i].affine[size_t(k)], calibrated->alignment.frame_from_reference[i](k / 3, k % 3));
    }
  }
  auto written_none = ReadStackManifest(dir_ / "none");
  ASSERT_TRUE(written_none.ok() && written_none->alignment.has_value());
  EXPECT_EQ(written_none->alignment->alignment, "none");
  EXPECT_TRUE(written_none->alignment->frames.empty());

  // The stored (unaligned) stack, reconstructed with an estimate from its own frames.
  auto manifest = ReadStackManifest(dir_ / "none");
  ASSERT_TRUE(manifest.ok());
  StackFolderAlignment a;
  a.alignment = FrameAlignment::kEstimate;
  AlignmentFigures figures;
  auto estimated = ReconstructStackFolder(dir_ / "none", *manifest, SffOptions{}, nullptr, cancel, a, &figures);
  ASSERT_TRUE(estimated.ok()) << estimated.status().ToString();
  EXPECT_EQ(figures.alignment, FrameAlignment::kEstimate);
  const DepthErrorStats ee = Score(*estimated, none->ground_truth_um);
  Print("estimated", ee, &figures);

  EXPECT_LT(ec.rmse_um, 1.10 * e0.rmse_um);
  EXPECT_LT(ee.rmse_um, 1.10 * e0.rmse_um);
  EXPECT_GT(en.rmse_um, 1.25 * e0.rmse_um);  // measurably worse without alignment
  // Alignment shrinks the field by what the frames do not all see, no more.
  EXPECT_GT(calibrated->alignment.seen_by_every_frame_percent, 90.0);
  EXPECT_LT(calibrated->alignment.seen_by_every_frame_percent, 100.0);
}

INSTANTIATE_TEST_SUITE_P(Specimens, StackAlignmentScanTest,
                         ::testing::Values(Case{"skew5", 3.0, 4.0, -3.0}, Case{"wedge", 1.0, 3.0, 2.0},
                                           Case{"skew10", 2.0, -3.0, 3.0}),
                         [](const auto& info) { return std::string(info.param.specimen); });

}  // namespace
}  // namespace inspection
