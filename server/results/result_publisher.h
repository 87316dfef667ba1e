// ResultPublisher: a job's result files from first byte to publication, shared by scan and
// reconstruct jobs. Files are written into tmp/<job_id>.artifacts/, then each is sized and
// hashed (sha256), the folder moves to artifacts/<job_id>/ in one rename and the artifacts are
// recorded in the store. Until Publish succeeds nothing is visible, and the work folder goes
// with the publisher. Also the one media-type table and the depth summary of a result.
// One per job; not thread-safe.
#pragma once

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

#include "core/io/depth_export.h"
#include "core/sff/sff_engine.h"
#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/storage/data_store.h"
#include "server/storage/owned_folder.h"
#include "server/results/depth_artifacts.h"

namespace inspection {

class ResultPublisher {
 public:
  // Creates the job's work folder under the store's tmp/. threads: how many files are written and
  // hashed at once (0 = all hardware threads, 1 = one after another).
  static StatusOr<ResultPublisher> Create(DataStore* store, const std::string& job_id, int threads = 0);

  // depth.tiff, confidence.tiff, all_in_focus.png, depth_preview.png and the requested extras.
  Status WriteDepth(const DepthResult& depth, const DepthExportMeta& meta,
                    const std::vector<DepthExportKind>& extra_exports);
  // A copy of `source` under its own file name.
  Status CopyFile(v1::ArtifactKind kind, const std::filesystem::path& source);
  // `bytes` as a file named `file_name` (e.g. the inspection report).
  Status WriteBytes(v1::ArtifactKind kind, const std::string& file_name, const std::string& bytes);
  // `folder` as an archive named `file_name` (stored, see ZipFolder).
  Status Zip(v1::ArtifactKind kind, const std::filesystem::path& folder, const std::string& file_name);

  // Publishes every file written so far, in order, and appends them to result->artifacts.
  Status Publish(v1::JobResult* result);

 private:
  ResultPublisher(DataStore* store, std::string job_id, OwnedFolder dir, int threads)
      : store_(store), job_id_(std::move(job_id)), dir_(std::move(dir)), threads_(threads) {}

  DataStore* store_;
  std::string job_id_;
  OwnedFolder dir_;
  int threads_;
  std::vector<std::pair<v1::ArtifactKind, std::filesystem::path>> files_;
};

// The one media-type table of the API's artifacts ("image/tiff", "application/x-ply", ...).
const char* MediaType(v1::ArtifactKind kind);
v1::ArtifactKind ToArtifactKind(DepthExportKind kind);

// Summary of a depth result; compares with ground truth when `truth_um` is given and has the
// same size. The focus window's half width at the image border is left out of the comparison
// (the window sees the border there).
v1::DepthSummary SummariseDepth(const DepthResult& depth, double pixel_size_um, const cv::Mat& truth_um, int window_px);

}  // namespace inspection
