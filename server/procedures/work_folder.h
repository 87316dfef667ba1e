// A rig job's own work folder (a study's or a verification's scans): created by Create(), removed
// with everything in it when the WorkFolder goes out of scope, however the job ends (success,
// error, cancel), so nothing of a job that did not finish is left on disk.
#pragma once

#include <filesystem>
#include <string>
#include <system_error>
#include <utility>

#include "core/util/status.h"

namespace inspection {

class WorkFolder {
 public:
  explicit WorkFolder(std::filesystem::path dir) : dir_(std::move(dir)) {}
  ~WorkFolder() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  WorkFolder(const WorkFolder&) = delete;
  WorkFolder& operator=(const WorkFolder&) = delete;

  // INTERNAL naming the folder when it cannot be made.
  Status Create() const {
    std::error_code ec;
    std::filesystem::create_directories(dir_, ec);
    if (ec) return Status::Internal("cannot create " + dir_.string() + ": " + ec.message());
    return Status::Ok();
  }

 private:
  std::filesystem::path dir_;
};

}  // namespace inspection
