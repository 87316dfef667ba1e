// Scan procedure: drives the rig through focus (thesis 3.1.2, Fig. 3.3) and streams every frame
// into the SFF engine while writing the stack folder, so the depth map is ready when the last
// frame arrives. Illumination here is the thesis's STD (uniform projector grey 128).
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/frame_statistics.h"
#include "core/sff_engine.h"
#include "core/stack.h"
#include "core/status.h"
#include "devices/rig.h"

namespace inspection {

struct ScanPlan {
  std::vector<double> z_um;       // stage positions in acquisition order
  double exposure_us = 0.0;
  int uniform_grey = 128;          // STD projector pattern
  std::string illumination = "STD";
  SffOptions sff;
  std::string calibration_id;      // recorded in stack.json
};

// Builds the z positions from start to end (inclusive when end falls on the grid) with step
// > 0, in the direction of end. Errors name the request field: z_step_um, z_start_um, ...
// The range must lie within the stage's travel and give 3..5000 frames.
StatusOr<ScanPlan> MakeScanPlan(double z_start_um, double z_end_um, double z_step_um, double exposure_us,
                                const Stage& stage);

struct ScanFrameEvent {
  int index = 0;
  int count = 0;
  double z_um = 0.0;  // position reported by the stage
  double exposure_us = 0.0;
  FrameStatistics statistics;
};

struct ScanOutcome {
  StackManifest manifest;
  DepthResult depth;
  cv::Mat ground_truth_um;  // simulated rig only; empty otherwise
  double acquisition_seconds = 0.0;
  double engine_finish_seconds = 0.0;  // time from the last frame to the depth map
};

// Acquires into stack_dir (created; the caller owns clean-up on failure) and reconstructs.
// Returns CANCELLED as soon as `cancel` is seen between frames; device errors pass through
// (UNAVAILABLE, DEADLINE_EXCEEDED, OUT_OF_RANGE).
StatusOr<ScanOutcome> RunScan(Rig& rig, const ScanPlan& plan, const std::filesystem::path& stack_dir,
                              const std::function<void(const ScanFrameEvent&)>& on_frame,
                              const std::atomic<bool>& cancel);

}  // namespace inspection
