// Type-1 gauge study on the rig (VDA 5, Bosch booklet 10): the same scan repeated on one
// reference part, each repeat measured by the caller. Between repeats the part is re-positioned:
// on the simulated rig by a random placement (devices/sim/simulated_rig.h SetSimulatedPlacement,
// drawn from the seed), which the study puts back when it ends, however it ends; a real rig has
// no such hook (the operator re-places the part) and the placement settings are ignored.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "devices/rig.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {

struct Type1StudyPlan {
  ScanPlan scan;  // every repeat's scan (a recipe's scan section)
  int repeats = 25;
  // Simulated rig: standard deviations of the random placement before every repeat (um).
  double reposition_xy_um = 5.0;
  double reposition_z_um = 2.0;
  uint64_t seed = 1;  // the placements are draws 1..repeats of (seed)
};

// One repeat of the study has been scanned: `repeat` (0-based) of `repeats`; the frame events of
// its scan arrive through on_frame first.
struct Type1StudyProgress {
  int repeat = 0;
  int repeats = 0;
  std::string message;
};

// Measures one repeat's depth map; an error ends the study with it.
using MeasureRepeat = std::function<Status(int repeat, const ScanOutcome& scan)>;

struct Type1StudyScans {
  std::string repositioning;  // e.g. "simulated: random placement, sigma 5 um xy, 2 um z"
};

// Runs plan.repeats scans, each into its own folder below work_dir (removed after its repeat is
// measured; work_dir itself when the study ends), calling `measure` after each. CANCELLED between frames or repeats once `cancel` is
// set. FAILED_PRECONDITION when plan.repeats is below kMinType1Repeats or the placement fails.
StatusOr<Type1StudyScans> RunType1StudyScans(Rig& rig, const Type1StudyPlan& plan,
                                             const std::filesystem::path& work_dir,
                                             const std::function<void(const ScanFrameEvent&, int repeat)>& on_frame,
                                             const std::function<void(const Type1StudyProgress&)>& on_repeat,
                                             const MeasureRepeat& measure, const std::atomic<bool>& cancel,
                                             const CalibrationBundle* bundle);

}  // namespace inspection
