// Work folders under uploads/ on a data folder that several replicas share (a reconstruct pool):
// which of them a live writer still holds, and the removal of those whose writer died (a replica
// killed with -9 while it received an upload leaves a partial folder that no job refers to).
//  - LiveWorkFolders: the folders this process holds (DataStore::NewUploadFolder); TouchAll
//    stamps their modification time, so other replicas see them alive.
//  - OrphanUploadSweeper: removes a folder of uploads/ that no work-queue row names (the stored
//    input of a queued or ended job) and whose modification time has not changed for
//    `stale_after` on the sweeper's own clock. Only a change of the time is judged, never its
//    value, so clocks of different hosts need not agree.
// A writer touches every folder it holds at least every stale_after / 3 (the JobManager ties both
// to pool_lease_s), so a live upload, also one stalled on a slow client or decoding, is never
// taken for an orphan; a replica frozen longer than stale_after loses its folder as it loses its
// lease (its upload then fails, or its job fails naming the missing input).
// Thread-safe.
#pragma once

#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>

#include "core/util/status.h"

namespace inspection {

class DataStore;

class LiveWorkFolders {
 public:
  // Holds `path` until the returned token goes (OwnedFolder keeps it).
  std::shared_ptr<void> Hold(const std::filesystem::path& path);
  bool Held(const std::filesystem::path& path) const;
  // Sets each held folder's modification time to now (a folder not created yet is passed over).
  void TouchAll() const;

 private:
  mutable std::mutex mu_;                   // guards held_
  std::multiset<std::filesystem::path> held_;
};

class OrphanUploadSweeper {
 public:
  // `store`: its uploads/ is swept, its work queue says what is stored input, its
  // live_work_folders() what this process holds. Must outlive the sweeper.
  OrphanUploadSweeper(DataStore* store, std::chrono::milliseconds stale_after);

  // One pass at `now` (the sweeper's steady clock). Returns the folders removed; an error when
  // the work queue cannot be read (nothing removed then).
  StatusOr<int> Sweep(std::chrono::steady_clock::time_point now = std::chrono::steady_clock::now());

 private:
  struct Seen {
    std::filesystem::file_time_type mtime;
    std::chrono::steady_clock::time_point since;  // when this mtime was first seen
  };
  DataStore* const store_;
  const std::chrono::milliseconds stale_after_;
  std::mutex mu_;                       // guards seen_ (one sweep at a time)
  std::map<std::string, Seen> seen_;    // folder name in uploads/ -> its last seen mtime
};

}  // namespace inspection
