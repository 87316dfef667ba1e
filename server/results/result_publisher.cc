// ResultPublisher: write, hash (sha256), publish a job's result files into the data store.
#include "server/results/result_publisher.h"

#include <fstream>
#include <system_error>

#include "core/metrology/depth_metrics.h"
#include "core/util/parallel_for.h"
#include "server/storage/artifact_files.h"

namespace inspection {
namespace fs = std::filesystem;

StatusOr<ResultPublisher> ResultPublisher::Create(DataStore* store, const std::string& job_id, int threads) {
  OwnedFolder dir(store->tmp_dir() / (job_id + ".artifacts"));
  std::error_code ec;
  fs::create_directories(dir.path(), ec);
  if (ec) return Status::Internal("cannot create " + dir.path().string() + ": " + ec.message());
  return ResultPublisher(store, job_id, std::move(dir), threads);
}

Status ResultPublisher::WriteDepth(const DepthResult& depth, const DepthExportMeta& meta,
                                   const std::vector<DepthExportKind>& extra_exports) {
  INSPECT_ASSIGN_OR_RETURN(std::vector<DepthArtifactFile> files,
                           WriteDepthArtifacts(depth, dir_.path(), meta, extra_exports, threads_));
  for (const DepthArtifactFile& f : files) files_.push_back({ToArtifactKind(f.kind), f.path});
  return Status::Ok();
}

Status ResultPublisher::CopyFile(v1::ArtifactKind kind, const fs::path& source) {
  const fs::path target = dir_.path() / source.filename();
  std::error_code ec;
  fs::copy_file(source, target, ec);
  if (ec) return Status::Internal("cannot copy " + source.filename().string() + ": " + ec.message());
  files_.push_back({kind, target});
  return Status::Ok();
}

Status ResultPublisher::WriteBytes(v1::ArtifactKind kind, const std::string& file_name, const std::string& bytes) {
  const fs::path target = dir_.path() / file_name;
  std::ofstream out(target, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), std::streamsize(bytes.size()));
  out.close();
  if (!out) return Status::Internal("cannot write " + file_name);
  files_.push_back({kind, target});
  return Status::Ok();
}

Status ResultPublisher::Zip(v1::ArtifactKind kind, const fs::path& folder, const std::string& file_name) {
  const fs::path target = dir_.path() / file_name;
  INSPECT_RETURN_IF_ERROR(ZipFolder(folder, target));
  files_.push_back({kind, target});
  return Status::Ok();
}

Status ResultPublisher::Publish(v1::JobResult* result) {
  const fs::path final_dir = store_->artifacts_dir() / job_id_;
  // Hashing reads every file once; independent files hash concurrently (one slot each).
  std::vector<StatusOr<std::string>> sha(files_.size(), Status::Internal("not hashed"));
  ParallelFor(int(files_.size()), ResolveThreads(threads_),
              [&](int i, int) { sha[size_t(i)] = Sha256File(files_[size_t(i)].second); });
  std::vector<StoredArtifact> stored;
  for (size_t i = 0; i < files_.size(); ++i) {
    const auto& [kind, path] = files_[i];
    StoredArtifact a;
    a.job_id = job_id_;
    a.path = final_dir / path.filename();
    a.artifact.set_artifact_id(NewId("art"));
    a.artifact.set_kind(kind);
    a.artifact.set_file_name(path.filename().string());
    std::error_code ec;
    a.artifact.set_size_bytes(int64_t(fs::file_size(path, ec)));
    if (ec) return Status::Internal("artifact " + path.string() + ": " + ec.message());
    if (!sha[i].ok()) return sha[i].status();
    a.artifact.set_sha256(*sha[i]);
    a.artifact.set_media_type(MediaType(kind));
    stored.push_back(std::move(a));
  }
  std::error_code ec;
  fs::rename(dir_.path(), final_dir, ec);
  if (ec) return Status::Internal("cannot move artifacts into place: " + ec.message());
  dir_ = OwnedFolder(final_dir);  // removed again if recording fails: no artifact without a record
  for (const StoredArtifact& a : stored) {
    INSPECT_RETURN_IF_ERROR(store_->PutArtifact(a));
    *result->add_artifacts() = a.artifact;
  }
  dir_.Release();
  return Status::Ok();
}

const char* MediaType(v1::ArtifactKind k) {
  switch (k) {
    case v1::ARTIFACT_KIND_DEPTH_TIFF:
    case v1::ARTIFACT_KIND_CONFIDENCE_TIFF:
    case v1::ARTIFACT_KIND_GROUND_TRUTH_TIFF:
      return "image/tiff";
    case v1::ARTIFACT_KIND_ALL_IN_FOCUS_PNG:
    case v1::ARTIFACT_KIND_DEPTH_PREVIEW_PNG:
    case v1::ARTIFACT_KIND_DEPTH_PNG16:
      return "image/png";
    case v1::ARTIFACT_KIND_STACK_ZIP:
      return "application/zip";
    case v1::ARTIFACT_KIND_DEPTH_PLY:
      return "application/x-ply";
    case v1::ARTIFACT_KIND_DEPTH_X3P:
      return "application/x-iso25178-x3p";
    case v1::ARTIFACT_KIND_REPORT_HTML:
      return "text/html; charset=utf-8";
    default:
      return "application/octet-stream";
  }
}

v1::ArtifactKind ToArtifactKind(DepthExportKind k) {
  switch (k) {
    case DepthExportKind::kDepthTiff:
      return v1::ARTIFACT_KIND_DEPTH_TIFF;
    case DepthExportKind::kConfidenceTiff:
      return v1::ARTIFACT_KIND_CONFIDENCE_TIFF;
    case DepthExportKind::kAllInFocusPng:
      return v1::ARTIFACT_KIND_ALL_IN_FOCUS_PNG;
    case DepthExportKind::kDepthPreviewPng:
      return v1::ARTIFACT_KIND_DEPTH_PREVIEW_PNG;
    case DepthExportKind::kDepthPng16:
      return v1::ARTIFACT_KIND_DEPTH_PNG16;
    case DepthExportKind::kDepthPly:
      return v1::ARTIFACT_KIND_DEPTH_PLY;
    case DepthExportKind::kDepthX3p:
      return v1::ARTIFACT_KIND_DEPTH_X3P;
    case DepthExportKind::kGroundTruthTiff:
      return v1::ARTIFACT_KIND_GROUND_TRUTH_TIFF;
  }
  return v1::ARTIFACT_KIND_UNSPECIFIED;
}

v1::DepthSummary SummariseDepth(const DepthResult& r, double pixel_size_um, const cv::Mat& truth, int window_px) {
  v1::DepthSummary d;
  d.set_width(r.depth_um.cols);
  d.set_height(r.depth_um.rows);
  d.set_pixel_size_um(pixel_size_um);
  d.set_valid_percent(100.0 * r.valid_fraction);
  auto [lo, hi] = FiniteRange(r.depth_um);
  d.set_z_min_um(lo);
  d.set_z_max_um(hi);
  d.set_frame_count(r.frame_count);
  if (!truth.empty() && truth.size() == r.depth_um.size()) {
    DepthErrorStats e = CompareDepth(r.depth_um, truth, 1e9, window_px / 2);
    d.set_has_ground_truth(true);
    d.set_rmse_um(e.rmse_um);
    d.set_mean_abs_error_um(e.mean_abs_error_um);
  }
  return d;
}

}  // namespace inspection
