// A stored scan's stack as a folder to reconstruct from. The server keeps each scan's raw stack
// once, as the stack.zip artifact users download (issue 14: a folder beside its own archive
// doubled every scan's footprint); a reconstruction of a stored scan reads a private extraction
// that goes with its job.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "core/status.h"
#include "server/data_store.h"
#include "server/owned_folder.h"

namespace inspection {

struct StoredStackFolder {
  std::filesystem::path dir;
  // Set when `dir` is an extraction: removed when the last holder lets go. Null for a scan
  // folder of the pre-archive layout (scans/<scan_id>/), read in place.
  std::shared_ptr<const OwnedFolder> extraction;
};

// NOT_FOUND naming scan_id when no succeeded scan job has that id or its stack was deleted;
// DATA_LOSS when the archive is missing or corrupt on the server; RESOURCE_EXHAUSTED "data disk
// full" when the extraction (under the store's uploads/) runs out of space. Nothing is left on
// any error.
// on_file (may be empty): (extraction folder, file's relative path) once each extracted file is
// on disk, stack.json first (UnzipToFolder), so the frames can decode while the rest is extracted.
using StoredFileCallback = std::function<void(const std::filesystem::path&, const std::string&)>;
StatusOr<StoredStackFolder> OpenStoredStack(DataStore& store, const std::string& scan_id,
                                            const StoredFileCallback& on_file = {});

}  // namespace inspection
