// OwnedFolder: a work folder of the server (an uploaded stack, a scan or result files being
// written) that is removed when its owner lets go, so no failure path leaves half-written data
// behind. Release() once the folder has been moved into place or is to be kept.
// Not thread-safe; movable, not copyable (share it through a shared_ptr).
#pragma once

#include <filesystem>
#include <system_error>
#include <utility>

namespace inspection {

class OwnedFolder {
 public:
  OwnedFolder() = default;
  explicit OwnedFolder(std::filesystem::path path) : path_(std::move(path)) {}
  ~OwnedFolder() { Remove(); }
  OwnedFolder(const OwnedFolder&) = delete;
  OwnedFolder& operator=(const OwnedFolder&) = delete;
  OwnedFolder(OwnedFolder&& other) noexcept : path_(std::exchange(other.path_, {})) {}
  OwnedFolder& operator=(OwnedFolder&& other) noexcept {
    if (this != &other) {
      Remove();
      path_ = std::exchange(other.path_, {});
    }
    return *this;
  }

  const std::filesystem::path& path() const { return path_; }
  // The folder is no longer ours to remove (moved into the store, or kept on purpose).
  void Release() { path_.clear(); }

 private:
  void Remove() {
    std::error_code ec;  // best effort: a folder that cannot be removed is emptied at next start
    if (!path_.empty()) std::filesystem::remove_all(path_, ec);
  }

  std::filesystem::path path_;
};

}  // namespace inspection
