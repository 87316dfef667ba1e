// WriteDepthArtifacts: the result files of one depth map (core/io/depth_export.h), written
// concurrently: each is a pure function of the result, so only the wall time changes.
#include "server/results/depth_artifacts.h"

#include <algorithm>
#include <functional>
#include <opencv2/imgcodecs.hpp>

#include "core/util/parallel_for.h"

namespace inspection {
namespace fs = std::filesystem;

StatusOr<std::vector<DepthArtifactFile>> WriteDepthArtifacts(const DepthResult& r, const fs::path& dir,
                                                             const DepthExportMeta& meta,
                                                             const std::vector<DepthExportKind>& extras,
                                                             int threads) {
  struct Task {
    DepthArtifactFile file;
    std::function<Status(const fs::path&)> write;
  };
  std::vector<Task> tasks;
  tasks.push_back({{DepthExportKind::kDepthTiff, dir / "depth.tiff"},
                   [&](const fs::path& p) { return WriteDepthTiff(p, r.depth_um, meta); }});
  tasks.push_back({{DepthExportKind::kConfidenceTiff, dir / "confidence.tiff"},
                   [&](const fs::path& p) { return WriteConfidenceTiff(p, r.confidence, meta); }});
  tasks.push_back({{DepthExportKind::kAllInFocusPng, dir / "all_in_focus.png"}, [&](const fs::path& p) {
                     return cv::imwrite(p.string(), r.all_in_focus) ? Status::Ok()
                                                                    : Status::Internal("cannot write all_in_focus.png");
                   }});
  // Inferred depth (dense, fill) must not pass for measured depth in the preview.
  cv::Mat inferred;
  if (meta.inferred_below_confidence > 0.0 && r.confidence.size() == r.depth_um.size()) {
    inferred = (r.confidence < meta.inferred_below_confidence) & (r.depth_um == r.depth_um);
  }
  tasks.push_back({{DepthExportKind::kDepthPreviewPng, dir / "depth_preview.png"},
                   [&](const fs::path& p) { return WriteDepthPreviewPng(p, r.depth_um, inferred); }});
  for (DepthExportKind k : extras) {
    switch (k) {
      case DepthExportKind::kDepthPng16:
        tasks.push_back({{k, dir / "depth16.png"}, [&](const fs::path& p) { return WriteDepthPng16(p, r.depth_um, meta); }});
        break;
      case DepthExportKind::kDepthPly:
        tasks.push_back({{k, dir / "depth.ply"}, [&](const fs::path& p) { return WriteDepthPly(p, r.depth_um, meta); }});
        break;
      case DepthExportKind::kDepthX3p:
        tasks.push_back({{k, dir / "depth.x3p"}, [&](const fs::path& p) { return WriteDepthX3p(p, r.depth_um, meta); }});
        break;
      default:
        return Status::InvalidArgument("export kind is not an extra export");
    }
  }
  std::vector<Status> written(tasks.size(), Status::Ok());  // one slot per task: no shared writes
  // Started longest first (the preview: colour map and a 3-channel PNG, several times a TIFF's
  // time), so the others fill the remaining threads; the files keep their order.
  std::vector<int> order(tasks.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = int(i);
  std::stable_partition(order.begin(), order.end(),
                        [&](int i) { return tasks[size_t(i)].file.kind == DepthExportKind::kDepthPreviewPng; });
  ParallelFor(int(tasks.size()), ResolveThreads(threads), [&](int k, int) {
    const int i = order[size_t(k)];
    try {
      written[size_t(i)] = tasks[size_t(i)].write(tasks[size_t(i)].file.path);
    } catch (const cv::Exception& e) {  // never across the thread boundary
      written[size_t(i)] = Status::Internal("cannot write " + tasks[size_t(i)].file.path.filename().string() + ": " + e.what());
    }
  });
  std::vector<DepthArtifactFile> files;
  for (size_t i = 0; i < tasks.size(); ++i) {
    INSPECT_RETURN_IF_ERROR(written[i]);
    files.push_back(tasks[i].file);
  }
  return files;
}

}  // namespace inspection
