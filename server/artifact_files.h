// File helpers for artifacts: content digests for integrity checks and the stack archive.
#pragma once

#include <filesystem>
#include <string>

#include "core/status.h"

namespace inspection {

// Lowercase hex SHA-256 of a file's bytes.
StatusOr<std::string> Sha256File(const std::filesystem::path& path);

// Zips every regular file below `folder` (paths relative to it) into `zip_path`, stored without
// compression: the frames are PNG/TIFF already, and storing keeps the archive fast to write.
Status ZipFolder(const std::filesystem::path& folder, const std::filesystem::path& zip_path);

}  // namespace inspection
