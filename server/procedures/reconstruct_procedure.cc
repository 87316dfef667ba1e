#include "server/procedures/reconstruct_procedure.h"

#include <opencv2/imgcodecs.hpp>

namespace inspection {
namespace fs = std::filesystem;

StatusOr<DepthResult> ReconstructStackFolder(const fs::path& dir, const StackManifest& manifest,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel) {
  std::unique_ptr<SffEngine> engine;
  const int count = int(manifest.frames.size());
  for (int i = 0; i < count; ++i) {
    if (cancel.load()) return Status::Cancelled("reconstruction cancelled at frame " + std::to_string(i));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, LoadStackFrame(dir, manifest, size_t(i)));
    if (!engine) {
      INSPECT_ASSIGN_OR_RETURN(engine, SffEngine::Create(options, frame.size(), frame.type()));
    }
    const std::string name = "frame " + std::to_string(i) + " (" + manifest.frames[i].file + ")";
    INSPECT_RETURN_IF_ERROR(engine->PushFrame(frame, manifest.frames[i].z_um).WithContext(name));
    if (on_frame) on_frame(i, count, manifest.frames[i].z_um, ComputeFrameStatistics(frame, manifest.bit_depth));
  }
  if (!engine) return Status::InvalidArgument("stack has no frames");
  return engine->Finish();
}

StatusOr<std::vector<DepthArtifactFile>> WriteDepthArtifacts(const DepthResult& r, const fs::path& dir,
                                                             const DepthExportMeta& meta,
                                                             const std::vector<DepthExportKind>& extras) {
  std::vector<DepthArtifactFile> files;
  INSPECT_RETURN_IF_ERROR(WriteDepthTiff(dir / "depth.tiff", r.depth_um, meta));
  files.push_back({DepthExportKind::kDepthTiff, dir / "depth.tiff"});
  INSPECT_RETURN_IF_ERROR(WriteConfidenceTiff(dir / "confidence.tiff", r.confidence, meta));
  files.push_back({DepthExportKind::kConfidenceTiff, dir / "confidence.tiff"});
  if (!cv::imwrite((dir / "all_in_focus.png").string(), r.all_in_focus)) {
    return Status::Internal("cannot write all_in_focus.png");
  }
  files.push_back({DepthExportKind::kAllInFocusPng, dir / "all_in_focus.png"});
  INSPECT_RETURN_IF_ERROR(WriteDepthPreviewPng(dir / "depth_preview.png", r.depth_um));
  files.push_back({DepthExportKind::kDepthPreviewPng, dir / "depth_preview.png"});
  for (DepthExportKind k : extras) {
    switch (k) {
      case DepthExportKind::kDepthPng16:
        INSPECT_RETURN_IF_ERROR(WriteDepthPng16(dir / "depth16.png", r.depth_um, meta));
        files.push_back({k, dir / "depth16.png"});
        break;
      case DepthExportKind::kDepthPly:
        INSPECT_RETURN_IF_ERROR(WriteDepthPly(dir / "depth.ply", r.depth_um, meta));
        files.push_back({k, dir / "depth.ply"});
        break;
      case DepthExportKind::kDepthX3p:
        INSPECT_RETURN_IF_ERROR(WriteDepthX3p(dir / "depth.x3p", r.depth_um, meta));
        files.push_back({k, dir / "depth.x3p"});
        break;
      default:
        return Status::InvalidArgument("export kind is not an extra export");
    }
  }
  return files;
}

}  // namespace inspection
