// File helpers for artifacts: content digests for integrity checks and the stack archive.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/util/status.h"

struct zip;  // libzip

namespace inspection {

// Lowercase hex SHA-256 of a file's bytes.
StatusOr<std::string> Sha256File(const std::filesystem::path& path);

// Zips every regular file below `folder` (paths relative to it) into `zip_path`, stored without
// compression: the frames are PNG/TIFF already, and storing keeps the archive fast to write.
Status ZipFolder(const std::filesystem::path& folder, const std::filesystem::path& zip_path);

// Reads the files of a zip archive (the stack.zip artifact) into memory or to disk, by entry name.
// Opening checks every entry name: relative paths without ".." (anything else: DATA_LOSS naming
// the entry), so nothing read can land outside a target folder. The archive file stays open
// while the reader lives (removing it meanwhile does not cut the reader off).
// Thread-safe: libzip's archive handle is not, so each read takes a lock (it copies stored
// bytes; the callers decode them in parallel outside it).
class ZipReader {
 public:
  static StatusOr<std::shared_ptr<ZipReader>> Open(const std::filesystem::path& zip_path);
  ~ZipReader();
  ZipReader(const ZipReader&) = delete;
  ZipReader& operator=(const ZipReader&) = delete;

  // The file entries (directory entries left out), in archive order.
  const std::vector<std::string>& files() const { return files_; }
  bool Contains(const std::string& name) const;
  // The whole entry; DATA_LOSS "stored stack: entry '<name>' is corrupt" when it fails its CRC.
  StatusOr<std::string> Read(const std::string& name) const;
  // Writes the entry to `target` (its folder created); a failed write returns WriteFailure's
  // status (RESOURCE_EXHAUSTED "data disk full" on ENOSPC). The caller removes what is left.
  Status Extract(const std::string& name, const std::filesystem::path& target) const;

 private:
  explicit ZipReader(zip* archive) : archive_(archive) {}
  zip* archive_;
  std::vector<std::string> files_;
  std::map<std::string, int64_t> index_;  // entry name -> libzip index
  mutable std::mutex mu_;                 // guards archive_
};

// Extracts every file of `zip_path` into `folder` (created), stack.json first. Errors as
// ZipReader's; on any error the caller removes `folder`.
Status UnzipToFolder(const std::filesystem::path& zip_path, const std::filesystem::path& folder);

}  // namespace inspection
