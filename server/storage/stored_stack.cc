// OpenStoredStack: find a scan's stack.zip artifact and open it for one reconstruction.
#include "server/storage/stored_stack.h"

#include <system_error>

#include "server/storage/artifact_files.h"
#include "server/storage/data_lifecycle.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {

// The manifest of an archived stack, with ReadStackManifest's errors for a folder.
StatusOr<StackManifest> ReadArchivedManifest(const ZipReader& zip, const std::string& context) {
  if (!zip.Contains(kStackManifestName)) return Status::InvalidArgument("stack.json is missing in the stored stack");
  auto text = zip.Read(kStackManifestName);
  if (!text.ok()) return text.status().WithContext(context);
  INSPECT_ASSIGN_OR_RETURN(StackManifest m, ParseStackManifest(*text));
  for (size_t i = 0; i < m.frames.size(); ++i) {
    if (!zip.Contains(m.frames[i].file)) {
      return Status::InvalidArgument("frame " + std::to_string(i) + " (" + m.frames[i].file + "): file is missing");
    }
  }
  return m;
}

}  // namespace

StatusOr<StoredStack> OpenStoredStack(DataStore& store, const std::string& scan_id, StoredFrames frames) {
  StoredStack out;
  std::error_code ec;
  const fs::path legacy = store.scans_dir() / scan_id;
  if (fs::is_directory(legacy, ec)) {
    out.dir = legacy;
    INSPECT_ASSIGN_OR_RETURN(out.manifest, ReadStackManifest(legacy));
    return out;
  }
  const Status not_found = Status::NotFound("scan_id '" + scan_id + "' not found");
  auto job = store.GetJob(scan_id);
  if (!job.ok() || job->kind() != v1::JOB_KIND_SCAN) return not_found;
  std::string artifact_id;
  for (const v1::Artifact& a : job->result().artifacts()) {
    if (a.kind() == v1::ARTIFACT_KIND_STACK_ZIP) artifact_id = a.artifact_id();
  }
  if (artifact_id.empty()) return not_found;
  auto zip = store.GetArtifact(artifact_id);
  // DeleteScan removes the artifact record with the archive: a scan whose stack was deleted.
  if (!zip.ok()) return Status::NotFound("scan_id '" + scan_id + "' has no stored stack (deleted)");
  if (!fs::is_regular_file(zip->path, ec)) {
    return Status::DataLoss("the stored stack of scan " + scan_id + " is missing on the server");
  }
  const std::string context = "scan " + scan_id;
  auto folder = store.NewUploadFolder("stack");
  if (frames == StoredFrames::kExtracted) {
    INSPECT_RETURN_IF_ERROR(UnzipToFolder(zip->path, folder->path()).WithContext(context));
    INSPECT_ASSIGN_OR_RETURN(out.manifest, ReadStackManifest(folder->path()));
  } else {
    auto reader = ZipReader::Open(zip->path);
    if (!reader.ok()) return reader.status().WithContext(context);
    std::shared_ptr<const ZipReader> archive = std::move(reader).value();
    INSPECT_ASSIGN_OR_RETURN(out.manifest, ReadArchivedManifest(*archive, context));
    fs::create_directories(folder->path(), ec);
    if (ec) return WriteFailure(ec.value(), "cannot create " + folder->path().string());
    // The files the job reads by path; the frames stay in the archive.
    for (const char* name : {kStackManifestName, kGroundTruthDepthName}) {
      if (archive->Contains(name)) {
        INSPECT_RETURN_IF_ERROR(archive->Extract(name, folder->path() / name).WithContext(context));
      }
    }
    out.decode = [archive, manifest = out.manifest, context](int i) -> StatusOr<cv::Mat> {
      if (i < 0 || i >= int(manifest.frames.size())) return Status::OutOfRange("frame index " + std::to_string(i));
      auto bytes = archive->Read(manifest.frames[size_t(i)].file);
      if (!bytes.ok()) return bytes.status().WithContext(context);
      return DecodeStackFrameInMemory(*bytes, manifest, i);
    };
  }
  out.dir = folder->path();
  out.extraction = std::move(folder);
  return out;
}

}  // namespace inspection
