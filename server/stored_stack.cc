// OpenStoredStack: find a scan's stack.zip artifact and extract it for one reconstruction.
#include "server/stored_stack.h"

#include <system_error>

#include "server/artifact_files.h"

namespace inspection {
namespace fs = std::filesystem;

StatusOr<StoredStackFolder> OpenStoredStack(DataStore& store, const std::string& scan_id,
                                            const StoredFileCallback& on_file) {
  StoredStackFolder out;
  std::error_code ec;
  const fs::path legacy = store.scans_dir() / scan_id;
  if (fs::is_directory(legacy, ec)) {
    out.dir = legacy;
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
  auto folder = std::make_shared<const OwnedFolder>(store.uploads_dir() / NewId("stack"));
  INSPECT_RETURN_IF_ERROR(UnzipToFolder(zip->path, folder->path(),
                                        [&](const std::string& name) {
                                          if (on_file) on_file(folder->path(), name);
                                        })
                              .WithContext("scan " + scan_id));
  out.dir = folder->path();
  out.extraction = std::move(folder);
  return out;
}

}  // namespace inspection
