// OwnedFolder: a work folder of the server (an uploaded stack, a scan or result files being
// written) that is removed when its owner lets go, so no failure path leaves half-written data
// behind. Release() once the folder has been moved into place or is to be kept. A folder on a
// shared data folder may carry a hold (work_folders.h) that keeps it alive for other replicas'
// sweeps while it is owned; the hold goes with Release() or the folder.
// Not thread-safe; movable, not copyable (share it through a shared_ptr).
#pragma once

#include <filesystem>
#include <memory>
#include <system_error>
#include <utility>

namespace inspection {

class OwnedFolder {
 public:
  OwnedFolder() = default;
  explicit OwnedFolder(std::filesystem::path path, std::shared_ptr<void> hold = nullptr)
      : path_(std::move(path)), hold_(std::move(hold)) {}
  ~OwnedFolder() { Remove(); }
  OwnedFolder(const OwnedFolder&) = delete;
  OwnedFolder& operator=(const OwnedFolder&) = delete;
  OwnedFolder(OwnedFolder&& other) noexcept
      : path_(std::exchange(other.path_, {})), hold_(std::move(other.hold_)) {}
  OwnedFolder& operator=(OwnedFolder&& other) noexcept {
    if (this != &other) {
      Remove();
      path_ = std::exchange(other.path_, {});
      hold_ = std::move(other.hold_);
    }
    return *this;
  }

  const std::filesystem::path& path() const { return path_; }
  // The folder is no longer ours to remove (moved into the store, or kept on purpose).
  // Its hold goes too: what refers to it now (a work-queue row) keeps it from the sweep.
  void Release() {
    path_.clear();
    hold_.reset();
  }

 private:
  void Remove() {
    std::error_code ec;  // best effort: a folder that cannot be removed is emptied at next start
    if (!path_.empty()) std::filesystem::remove_all(path_, ec);
    hold_.reset();
  }

  std::filesystem::path path_;
  std::shared_ptr<void> hold_;  // see work_folders.h; null = not held
};

}  // namespace inspection
