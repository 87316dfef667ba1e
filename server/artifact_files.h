// File helpers for artifacts: content digests for integrity checks and the stack archive.
#pragma once

#include <filesystem>
#include <functional>
#include <string>

#include "core/status.h"

namespace inspection {

// Lowercase hex SHA-256 of a file's bytes.
StatusOr<std::string> Sha256File(const std::filesystem::path& path);

// Zips every regular file below `folder` (paths relative to it) into `zip_path`, stored without
// compression: the frames are PNG/TIFF already, and storing keeps the archive fast to write.
Status ZipFolder(const std::filesystem::path& folder, const std::filesystem::path& zip_path);

// Extracts every file of `zip_path` into `folder` (created). Entry names must be relative paths
// without ".." (anything else: DATA_LOSS naming the entry, nothing is written outside `folder`).
// A failed write returns WriteFailure's status (RESOURCE_EXHAUSTED "data disk full" on ENOSPC);
// on any error the caller removes `folder`.
// on_file (may be empty) is called with each file's entry name once it is complete on disk;
// stack.json is extracted first, so a stack's frames can be decoded as they come.
Status UnzipToFolder(const std::filesystem::path& zip_path, const std::filesystem::path& folder,
                     const std::function<void(const std::string&)>& on_file = {});

}  // namespace inspection
