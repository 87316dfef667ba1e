#include "server/procedures/reconstruct_procedure.h"

#include <opencv2/imgcodecs.hpp>

namespace inspection {
namespace fs = std::filesystem;

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
