// Reconstructs a stack folder (core/stack.h) through the streaming SFF engine (thesis 3.1):
// frames are decoded and pushed one at a time, as if from the camera, so memory stays
// O(pixels). The one stack-folder -> engine loop: Reconstruct jobs and the tests use it.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>

#include "core/frame_statistics.h"
#include "core/sff_engine.h"
#include "core/stack.h"
#include "core/status.h"

namespace inspection {

// Called after each frame is pushed: (frame index, frame count, z_um, grey-value statistics).
using StackFrameCallback = std::function<void(int, int, double, const FrameStatistics&)>;

// manifest: as read by ReadStackManifest(dir). on_frame may be empty. cancel is polled before
// each frame: CANCELLED naming the frame. Errors name the frame and its file, e.g.
// "frame 3 (frame_0003.png): ...".
StatusOr<DepthResult> ReconstructStackFolder(const std::filesystem::path& dir, const StackManifest& manifest,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel);

}  // namespace inspection
