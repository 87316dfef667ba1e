// Reconstruct procedure: a stored stack folder runs through the streaming SFF engine frame by
// frame (ReconstructStackFolder, core/sff/stack_reconstruct.h); this writes the result's artifacts.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/io/depth_export.h"
#include "core/sff/sff_engine.h"
#include "core/io/stack.h"
#include "core/sff/stack_reconstruct.h"  // ReconstructStackFolder: the stack folder -> engine loop
#include "core/util/status.h"

namespace inspection {

enum class DepthExportKind {
  kDepthTiff,
  kConfidenceTiff,
  kAllInFocusPng,
  kDepthPreviewPng,
  kDepthPng16,
  kDepthPly,
  kDepthX3p,
  kGroundTruthTiff
};

struct DepthArtifactFile {
  DepthExportKind kind;
  std::filesystem::path path;  // media types: server/results/result_publisher.h
};

// Writes depth.tiff, confidence.tiff, all_in_focus.png, depth_preview.png and the requested
// extras (kDepthPng16, kDepthPly, kDepthX3p) into dir, each file by its own task on up to
// `threads` threads (0 = all hardware threads; 1 = one after another): they are independent.
// Returns them in that order. On error (the first failing file in that order), files already
// written stay for the caller to discard with the folder.
StatusOr<std::vector<DepthArtifactFile>> WriteDepthArtifacts(const DepthResult& result,
                                                             const std::filesystem::path& dir,
                                                             const DepthExportMeta& meta,
                                                             const std::vector<DepthExportKind>& extras,
                                                             int threads = 0);

}  // namespace inspection
