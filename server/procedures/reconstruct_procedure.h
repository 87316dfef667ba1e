// Reconstruct procedure: runs a stored stack folder through the streaming SFF engine, frame by
// frame as if from the camera, and writes the depth artifacts of a result.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/depth_export.h"
#include "core/frame_statistics.h"
#include "core/sff_engine.h"
#include "core/stack.h"
#include "core/status.h"

namespace inspection {

// (frame index, frame count, z_um, statistics)
using StackFrameCallback = std::function<void(int, int, double, const FrameStatistics&)>;

StatusOr<DepthResult> ReconstructStackFolder(const std::filesystem::path& dir, const StackManifest& manifest,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel);

enum class DepthExportKind { kDepthTiff, kConfidenceTiff, kAllInFocusPng, kDepthPreviewPng, kDepthPng16, kDepthPly,
                             kDepthX3p, kGroundTruthTiff };

struct DepthArtifactFile {
  DepthExportKind kind;
  std::filesystem::path path;  // media types: server/result_publisher.h
};

// Writes depth.tiff, confidence.tiff, all_in_focus.png, depth_preview.png and the requested
// extras (kDepthPng16, kDepthPly, kDepthX3p) into dir. On error, files already written stay for
// the caller to discard with the folder.
StatusOr<std::vector<DepthArtifactFile>> WriteDepthArtifacts(const DepthResult& result, const std::filesystem::path& dir,
                                                             const DepthExportMeta& meta,
                                                             const std::vector<DepthExportKind>& extras);

}  // namespace inspection
