// Held work folders and the sweep of dead writers' uploads (work_folders.h).
#include "server/storage/work_folders.h"

#include <spdlog/spdlog.h>

#include <system_error>
#include <vector>

#include "server/storage/data_store.h"

namespace inspection {
namespace fs = std::filesystem;

std::shared_ptr<void> LiveWorkFolders::Hold(const fs::path& path) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    held_.insert(path);
  }
  // The token's deleter lets go; `this` outlives every token (the DataStore owns both).
  return std::shared_ptr<void>(nullptr, [this, path](void*) {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = held_.find(path); it != held_.end()) held_.erase(it);
  });
}

bool LiveWorkFolders::Held(const fs::path& path) const {
  std::lock_guard<std::mutex> lock(mu_);
  return held_.count(path) > 0;
}

void LiveWorkFolders::TouchAll() const {
  std::vector<fs::path> paths;
  {
    std::lock_guard<std::mutex> lock(mu_);
    paths.assign(held_.begin(), held_.end());
  }
  for (const fs::path& p : paths) {
    std::error_code ec;
    const auto before = fs::last_write_time(p, ec);
    if (ec) continue;  // not created yet, or gone with its job
    // Never the same time twice: the sweeper judges a change, and a coarse clock might repeat.
    auto now = fs::file_time_type::clock::now();
    if (now <= before) now = before + std::chrono::microseconds(1);
    fs::last_write_time(p, now, ec);
  }
}

OrphanUploadSweeper::OrphanUploadSweeper(DataStore* store, std::chrono::milliseconds stale_after)
    : store_(store), stale_after_(stale_after) {}

StatusOr<int> OrphanUploadSweeper::Sweep(std::chrono::steady_clock::time_point now) {
  std::lock_guard<std::mutex> lock(mu_);
  // The folders first, the queue after: a folder that becomes a job's stored input meanwhile is
  // in the queue when it is read.
  std::map<std::string, fs::file_time_type> listed;
  std::error_code ec;
  for (auto it = fs::directory_iterator(store_->uploads_dir(), ec); !ec && it != fs::directory_iterator();
       it.increment(ec)) {
    std::error_code mec;
    const auto mtime = fs::last_write_time(it->path(), mec);
    if (!mec) listed.emplace(it->path().filename().string(), mtime);
  }
  INSPECT_ASSIGN_OR_RETURN(std::vector<std::string> inputs, store_->WorkInputDirs());
  std::set<std::string> referenced;
  for (const std::string& dir : inputs) {
    const fs::path rel(dir);
    if (rel.has_parent_path() && rel.parent_path() == "uploads") referenced.insert(rel.filename().string());
  }
  int removed = 0;
  for (const auto& [name, mtime] : listed) {
    const fs::path path = store_->uploads_dir() / name;
    if (referenced.count(name) || store_->live_work_folders().Held(path)) {
      seen_.erase(name);
      continue;
    }
    auto it = seen_.find(name);
    if (it == seen_.end() || it->second.mtime != mtime) {
      seen_[name] = {mtime, now};  // new, or its writer touched it: alive
      continue;
    }
    if (now - it->second.since < stale_after_) continue;
    std::error_code rec;
    fs::remove_all(path, rec);
    if (rec) {
      spdlog::warn("uploads: cannot remove the orphaned folder {}: {}", path.string(), rec.message());
      continue;
    }
    spdlog::warn("uploads: removed {}: no job refers to it and its writer has not touched it for {} ms (it stopped)",
                 name, std::chrono::duration_cast<std::chrono::milliseconds>(now - it->second.since).count());
    seen_.erase(it);
    ++removed;
  }
  for (auto it = seen_.begin(); it != seen_.end();) it = listed.count(it->first) ? std::next(it) : seen_.erase(it);
  return removed;
}

}  // namespace inspection
