// Automatic z range: a coarse sweep over the search window finds where the specimen's
// focus lies (core/sff/z_range_search.h), then the normal scan (scan_procedure.h) runs over that
// range plus the margin at the requested step. After the sweep, 2-4 frames refine the found
// range's ends (ZRangeAccumulator::PlanRefinement). The search's frames are stored under
// raw/ of the stack ("frame_<i>_coarse0.png", "frame_<i>_refine0.png") and recorded in
// stack.json's "z_range_search" ("coarse_frames", "refine_frames").
//
// The coarse frames are captured under a projected checkerboard (cells of kSearchCellProjectorPx
// projector pixels, 0/255, the STD exposure) instead of STD's uniform grey: through the shared
// objective the pattern is sharp on the specimen only at focus, so textureless parts (lens,
// mirror: no focus signal under uniform light) are found too, and on textured parts it adds
// to their texture. No calibration is needed for it.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>

#include "core/calibration/calibration_bundle.h"
#include "core/sff/z_range_search.h"
#include "core/util/status.h"
#include "devices/rig.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {

// The pattern's cell is kSearchCellProjectorPx (core/sff/z_range_search.h): 3.4 camera pixels
// per projector pixel on the thesis rig, a period of ~14 camera pixels, resolved by the focus
// measure at 1/4 scale.
// Most coarse frames one search may take (a window / step needing more is INVALID_ARGUMENT).
inline constexpr int kMaxCoarseFrames = 200;
inline constexpr double kDefaultCoarseSteps = 4.0;
// The fine scan takes at least this many frames, whatever the part's height: a flat part gets
// its focus frame and 3 steps on each side (the largest margin). The SFF engine's
// confidence (core/sff/depth_interpolation.h FocusConfidence) estimates each curve's noise from its
// second differences away from the peak; on short stacks most of those hold the peak's own
// flanks, which it weights down (FocusCurveSummary::flank_terms). Measured at 5 um steps
// (autorange-evaluate, 3 seeds, 512x384, STD): plane and step1um at 7 frames 91-100 % valid
// (12 frames were needed before the flank weighting; 7 then kept 3-64 %); skew5 at 320x240, 9
// frames, 99.4-99.6 % (87 % before). Textureless parts under STD (mirror) get a wrong depth on
// 2.8-3.1 % of their pixels at 7 frames, 0.1 % at 12.
inline constexpr int kMinFineFrames = 7;
inline constexpr double kDefaultMarginSteps = 1.5;
// The margin covers the search's own error, which is set by the coarse step, not the fine one.
// Before the refinement frames (ZRangeAccumulator::PlanRefinement) it was up to 4 um
// inwards at 20 um coarse steps (the cutter's top: its clipped land resolves no peak) and a
// quarter coarse step was needed: 1.5 fine steps alone (3 um at 2 um steps) cut the cutter's
// top (93 % coverage at seed 23). The refinement halves the sampling at the ends, and an
// eighth of the coarse step (2.5 um) keeps every part whole (autorange-evaluate at 2 um steps,
// 3 seeds, 30 runs: 100 % coverage, margins 0.8-4.1 steps).
inline constexpr double kDefaultMarginCoarseSteps = 0.125;

// Defaults for a request that leaves them unset (0): window = the rig's default scan range
// (RigStatus.scan_defaults: where parts sit on this rig); coarse step = the rig's
// focus_search_step_um (set by its optics, not by the fine step: a 1 um fine step would take
// 4 um coarse steps, 5x the frames the search pattern needs, and a 10 um one 40 um steps that
// miss its focus), or kDefaultCoarseSteps fine steps on a rig that does not know it; margin =
// kDefaultMarginSteps fine steps but at least kDefaultMarginCoarseSteps coarse steps. Checks
// the window against the stage travel and the step against the window; errors name the field
// under "z_range_search.".
StatusOr<ZRangeSearchSettings> ResolveZRangeSearch(const ZRangeSearchSettings& requested, double fine_step_um,
                                                   const ScanDefaults& defaults, const Stage& stage);

// Runs the coarse sweep and its refinement, chooses the range and runs RunScan over it.
// plan.z_range_search must be set and plan.z_step_um > 0 (plan.z_um is replaced). on_frame sees
// the search's frames with z_range_search = true first (index 0.. over the sweep, then the
// refinement; count = the window's coarse frames + kMaxRefinementFrames), then the scan's
// frames. The outcome's manifest carries the record (also written to stack.json);
// images_acquired and capture_statistics include the search's frames.
// FAILED_PRECONDITION when the sweep finds no focus (core/sff/z_range_search.h).
StatusOr<ScanOutcome> RunScanWithZRangeSearch(Rig& rig, const ScanPlan& plan, const std::filesystem::path& stack_dir,
                                              const std::function<void(const ScanFrameEvent&)>& on_frame,
                                              const std::atomic<bool>& cancel, const CalibrationBundle* bundle);

}  // namespace inspection
