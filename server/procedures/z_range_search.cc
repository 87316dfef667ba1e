// Automatic z range: the coarse sweep on the rig, the range it finds and the fine scan over it
// (z_range_search.h; core/sff/z_range_search.h for the maths).
#include "server/procedures/z_range_search.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "core/io/frame_statistics.h"
#include "core/illumination/texture_pattern.h"
#include "server/procedures/illumination_strategy.h"

namespace inspection {
namespace fs = std::filesystem;

StatusOr<ZRangeSearchSettings> ResolveZRangeSearch(const ZRangeSearchSettings& requested, double fine_step_um,
                                                   const ScanDefaults& defaults, const Stage& stage) {
  ZRangeSearchSettings s = requested;
  const bool default_window = s.window_start_um == 0.0 && s.window_end_um == 0.0;
  if (default_window) {
    s.window_start_um = std::min(defaults.z_start_um, defaults.z_end_um);
    s.window_end_um = std::max(defaults.z_start_um, defaults.z_end_um);
  }
  if (s.coarse_step_um == 0.0) {
    s.coarse_step_um =
        defaults.focus_search_step_um > 0.0 ? defaults.focus_search_step_um : kDefaultCoarseSteps * fine_step_um;
  }
  if (s.margin_um == 0.0) {
    s.margin_um = std::max(kDefaultMarginSteps * fine_step_um, kDefaultMarginCoarseSteps * s.coarse_step_um);
  }
  if (!(s.margin_um >= 0.0) || !std::isfinite(s.margin_um)) {
    return Status::InvalidArgument(
        "z_range_search.margin_um must be >= 0 (0 = the default: 1.5 fine steps, at least an eighth of the coarse "
        "step)");
  }
  // The window and step checks, with the fields' names.
  INSPECT_RETURN_IF_ERROR(
      CoarseSweepZ(s, stage.min_z_um(), stage.max_z_um(), kMaxCoarseFrames, "z_range_search.").status());
  return s;
}

namespace {

// The coarse sweep: stage, capture, raw/ file, focus curves, progress event per frame.
struct CoarseSweep {
  std::vector<double> z_um;
  std::vector<StackFrame> frames;
  std::vector<StackFrame> refine_frames;  // after the sweep, at the found range's ends
  ZRangeEstimate estimate;
  double settled_percent = 0.0;  // when the sweep ended
  bool stopped_early = false;    // before the window's end: the field had settled
};

StatusOr<CoarseSweep> RunCoarseSweep(Rig& rig, const ScanPlan& plan, const fs::path& stack_dir,
                                     const std::function<void(const ScanFrameEvent&)>& on_frame,
                                     const std::atomic<bool>& cancel, ScanOutcome& stats) {
  const ZRangeSearchSettings& s = *plan.z_range_search;
  Stage& stage = rig.stage();
  Camera& camera = rig.camera();
  CoarseSweep sweep;
  INSPECT_ASSIGN_OR_RETURN(sweep.z_um,
                           CoarseSweepZ(s, stage.min_z_um(), stage.max_z_um(), kMaxCoarseFrames, "z_range_search."));
  const ZRangeSearchOptions search_options;
  INSPECT_ASSIGN_OR_RETURN(
      ZRangeAccumulator acc,
      ZRangeAccumulator::Create(search_options, camera.frame_size(), camera.bit_depth()));
  // 64/192 rather than 0/255: the same mean as STD's grey 128 without doubling the light on
  // parts exposed for it (clipped squares would hide the pattern's edges).
  const cv::Mat pattern = 64 + 128 * CheckerboardMask(rig.projector().resolution(), kSearchCellProjectorPx);
  const std::string pattern_name = "checkerboard:" + std::to_string(kSearchCellProjectorPx) + ":64:192";
  INSPECT_RETURN_IF_ERROR(rig.projector().Show(pattern).WithContext("z range search: projector"));
  // Half the scan's exposure: the pattern's bright squares (192) at the full exposure would clip
  // shiny parts (coin field, cutter land) and a clipped area shows no focus. The focus curves
  // are compared per pixel, so the dimmer frames cost nothing but a little noise.
  const double exposure_us = std::max(1.0, std::round(0.5 * plan.exposure_us));
  if (camera.exposure_us() != exposure_us) INSPECT_RETURN_IF_ERROR(camera.SetExposure(exposure_us));
  const int n = int(sweep.z_um.size());
  // Progress counts the sweep and the refinement frames it may add.
  const int planned = n + ZRangeAccumulator::kMaxRefinementFrames;
  // One capture of the search: stage, frame, raw/ file, statistics, progress event.
  auto capture = [&](int i, double z_um, const char* what, std::vector<StackFrame>* record) -> StatusOr<cv::Mat> {
    const std::string name = std::string(what) + " frame " + std::to_string(i);
    if (cancel.load()) return Status::Cancelled("scan cancelled in the z range search at " + name);
    INSPECT_RETURN_IF_ERROR(stage.MoveTo(z_um).WithContext(name + ": stage"));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, camera.Capture());
    if (frame.size() != camera.frame_size()) return Status::Internal(name + ": camera delivered an unexpected size");
    const std::string file = "raw/" + RawFrameName(i, what, 0);
    if (!cv::imwrite((stack_dir / file).string(), frame, {cv::IMWRITE_PNG_COMPRESSION, 1})) {
      return Status::Internal("cannot write " + file);
    }
    record->push_back({file, z_um, camera.exposure_us(), pattern_name});
    const FrameStatistics st = ComputeFrameStatistics(frame, camera.bit_depth());
    stats.capture_statistics.push_back(st);
    stats.capture_is_stack_frame.push_back(false);
    if (on_frame) {
      ScanFrameEvent ev;
      ev.index = i;
      ev.count = planned;
      INSPECT_ASSIGN_OR_RETURN(ev.z_um, stage.position_um());
      ev.exposure_us = camera.exposure_us();
      ev.statistics = st;
      ev.acquisition = i;
      ev.stack_frame = false;
      ev.z_range_search = true;
      on_frame(ev);
    }
    return frame;
  };
  for (int i = 0; i < n; ++i) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, capture(i, sweep.z_um[size_t(i)], "coarse", &sweep.frames));
    INSPECT_RETURN_IF_ERROR(acc.PushFrame(frame, sweep.z_um[size_t(i)]));
    // The rest of the window can hold no more focus than the few unsettled pixels'
    // (ZRangeSearchOptions::stop_settled_percent): skip it.
    if (search_options.stop_settled_percent > 0.0 && i + 1 < n) {
      sweep.settled_percent = acc.SettledPercent();
      if (sweep.settled_percent >= search_options.stop_settled_percent) {
        sweep.stopped_early = true;
        break;
      }
    }
  }
  if (!sweep.stopped_early) sweep.settled_percent = acc.SettledPercent();
  INSPECT_ASSIGN_OR_RETURN(const ZRangeEstimate first, acc.Finish());
  // The range's ends resampled at twice the density (ZRangeAccumulator::PlanRefinement).
  const std::vector<double> refine_z = acc.PlanRefinement(first);
  for (size_t j = 0; j < refine_z.size(); ++j) {
    const int i = int(sweep.frames.size() + j);
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, capture(i, refine_z[j], "refine", &sweep.refine_frames));
    INSPECT_RETURN_IF_ERROR(acc.PushRefinementFrame(frame, refine_z[j]));
  }
  // The refined samples drop the pixels they show to be halos; should that leave too few
  // peaks, the sweep's own estimate stands.
  StatusOr<ZRangeEstimate> refined = acc.Finish();
  sweep.estimate = refined.ok() ? std::move(refined).value() : first;
  return sweep;
}

}  // namespace

StatusOr<ScanOutcome> RunScanWithZRangeSearch(Rig& rig, const ScanPlan& plan, const fs::path& stack_dir,
                                              const std::function<void(const ScanFrameEvent&)>& on_frame,
                                              const std::atomic<bool>& cancel, const CalibrationBundle* bundle) {
  if (!plan.z_range_search) return Status::Internal("RunScanWithZRangeSearch: the plan asks for no z range search");
  if (!(plan.z_step_um > 0.0)) return Status::InvalidArgument("z_step_um must be > 0 for an automatic z range");
  std::error_code ec;
  fs::create_directories(stack_dir / "raw", ec);
  if (ec) return Status::Internal("cannot create " + stack_dir.string() + ": " + ec.message());
  const auto t0 = std::chrono::steady_clock::now();
  ScanOutcome coarse;
  INSPECT_ASSIGN_OR_RETURN(CoarseSweep sweep, RunCoarseSweep(rig, plan, stack_dir, on_frame, cancel, coarse));

  const ZRangeSearchSettings& s = *plan.z_range_search;
  Stage& stage = rig.stage();
  const FineRange range =
      ChooseFineRange(sweep.estimate, plan.z_step_um, s.margin_um, kMinFineFrames, stage.min_z_um(), stage.max_z_um());
  const double search_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ScanPlan fine = plan;
  fine.z_range_search.reset();
  {
    INSPECT_ASSIGN_OR_RETURN(ScanPlan grid,
                             MakeScanPlan(range.z_start_um, range.z_end_um, plan.z_step_um, plan.exposure_us, stage));
    fine.z_um = std::move(grid.z_um);
  }
  INSPECT_ASSIGN_OR_RETURN(ScanOutcome out, RunScan(rig, fine, stack_dir, on_frame, cancel, bundle));

  ZRangeSearchRecord r;
  r.window_start_um = std::min(s.window_start_um, s.window_end_um);
  r.window_end_um = std::max(s.window_start_um, s.window_end_um);
  r.coarse_step_um = s.coarse_step_um;
  r.margin_um = s.margin_um;
  r.coarse_frames = std::move(sweep.frames);
  r.refine_frames = std::move(sweep.refine_frames);
  r.focus_low_um = sweep.estimate.z_low_um;
  r.focus_high_um = sweep.estimate.z_high_um;
  r.resolved_percent = sweep.estimate.resolved_percent;
  r.settled_percent = sweep.settled_percent;
  r.stopped_early = sweep.stopped_early;
  r.z_start_um = fine.z_um.front();
  r.z_end_um = fine.z_um.back();
  r.search_seconds = search_seconds;
  out.manifest.z_range_search = std::move(r);
  INSPECT_RETURN_IF_ERROR(WriteStackManifest(stack_dir, out.manifest));
  // Every capture of the job, the sweep's first.
  out.images_acquired += int(coarse.capture_statistics.size());
  out.capture_statistics.insert(out.capture_statistics.begin(), coarse.capture_statistics.begin(),
                                coarse.capture_statistics.end());
  out.capture_is_stack_frame.insert(out.capture_is_stack_frame.begin(), coarse.capture_is_stack_frame.begin(),
                                    coarse.capture_is_stack_frame.end());
  return out;
}

}  // namespace inspection
