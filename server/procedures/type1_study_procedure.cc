// RunType1StudyScans: repeated scans of one reference part, re-positioned between repeats.
#include "server/procedures/type1_study_procedure.h"
#include "server/procedures/work_folder.h"

#include <spdlog/spdlog.h>

#include <cstdio>

#include "core/metrology/capability.h"
#include "devices/sim/simulated_rig.h"
#include "server/procedures/z_range_search.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {

// Puts the simulated part back where it was loaded when the study ends, however it ends.
class PlacementReset {
 public:
  explicit PlacementReset(Rig* rig) : rig_(rig) {}
  ~PlacementReset() {
    if (rig_ == nullptr) return;
    const Status s = SetSimulatedPlacement(*rig_, {});
    if (!s.ok()) spdlog::warn("type-1 study: the simulated part could not be put back: {}", s.ToString());
  }
  PlacementReset(const PlacementReset&) = delete;
  PlacementReset& operator=(const PlacementReset&) = delete;

 private:
  Rig* rig_;
};

}  // namespace

StatusOr<Type1StudyScans> RunType1StudyScans(Rig& rig, const Type1StudyPlan& plan, const fs::path& work_dir,
                                             const std::function<void(const ScanFrameEvent&, int repeat)>& on_frame,
                                             const std::function<void(const Type1StudyProgress&)>& on_repeat,
                                             const MeasureRepeat& measure, const std::atomic<bool>& cancel,
                                             const CalibrationBundle* bundle) {
  if (plan.repeats < kMinType1Repeats || plan.repeats > kMaxType1Repeats) {
    return Status::FailedPrecondition("repeats must be " + std::to_string(kMinType1Repeats) + ".." +
                                      std::to_string(kMaxType1Repeats) + ", got " + std::to_string(plan.repeats));
  }
  const bool simulated = rig.simulation() != nullptr;
  Type1StudyScans out;
  if (simulated) {
    char text[160];
    std::snprintf(text, sizeof text, "simulated: random placement per repeat, sigma %.3g um xy, %.3g um z",
                  plan.reposition_xy_um, plan.reposition_z_um);
    out.repositioning = text;
  } else {
    out.repositioning = "real rig: the part as the operator placed it for each repeat";
  }
  PlacementReset reset(simulated ? &rig : nullptr);
  std::error_code ec;
  // The work folder goes with the study, however it ends.
  WorkFolder work_folder(work_dir);
  INSPECT_RETURN_IF_ERROR(work_folder.Create());
  for (int i = 0; i < plan.repeats; ++i) {
    if (cancel.load()) return Status::Cancelled("study cancelled before repeat " + std::to_string(i + 1));
    if (simulated) {
      const SimulatedPlacement p =
          RandomSimulatedPlacement(plan.seed, uint64_t(i) + 1, plan.reposition_xy_um, plan.reposition_z_um);
      if (Status s = SetSimulatedPlacement(rig, p); !s.ok()) {
        return Status::FailedPrecondition("repeat " + std::to_string(i + 1) + ": re-positioning the part: " +
                                          s.message());
      }
    }
    const fs::path dir = work_dir / ("repeat-" + std::to_string(i + 1));
    auto frame = [&](const ScanFrameEvent& e) {
      if (on_frame) on_frame(e, i);
    };
    StatusOr<ScanOutcome> scanned = plan.scan.z_range_search
                                        ? RunScanWithZRangeSearch(rig, plan.scan, dir, frame, cancel, bundle)
                                        : RunScan(rig, plan.scan, dir, frame, cancel, bundle);
    if (!scanned.ok()) {
      fs::remove_all(dir, ec);
      if (scanned.status().code() == StatusCode::kCancelled) return scanned.status();
      return Status(scanned.status().code(), "repeat " + std::to_string(i + 1) + ": " + scanned.status().message());
    }
    Status measured = measure(i, *scanned);
    fs::remove_all(dir, ec);
    INSPECT_RETURN_IF_ERROR(measured);
    if (on_repeat) on_repeat({i, plan.repeats, "repeat " + std::to_string(i + 1) + " of " + std::to_string(plan.repeats)});
  }
  return out;
}

}  // namespace inspection
