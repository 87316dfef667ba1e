// Free-space reserve, disk-full mapping and the retention selection (see data_lifecycle.h).
#include "server/storage/data_lifecycle.h"

#include <sys/statvfs.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace inspection {

namespace {
constexpr const char* kDiskFull = "data disk full";
constexpr int64_t kMiB = 1 << 20;
}  // namespace

StatusOr<int64_t> FreeDiskBytes(const std::filesystem::path& path) {
  struct statvfs s {};
  if (statvfs(path.c_str(), &s) != 0) {
    return Status::Internal("cannot read free space of " + path.string() + ": " + std::strerror(errno));
  }
  return static_cast<int64_t>(s.f_bavail) * static_cast<int64_t>(s.f_frsize);
}

Status CheckFreeSpaceReserve(const std::filesystem::path& data_dir, int64_t min_free_bytes) {
  if (min_free_bytes <= 0) return Status::Ok();
  INSPECT_ASSIGN_OR_RETURN(int64_t free_bytes, FreeDiskBytes(data_dir));
  if (free_bytes >= min_free_bytes) return Status::Ok();
  return Status::ResourceExhausted("data disk has " + std::to_string(free_bytes / kMiB) +
                                   " MiB free, below the reserve of " + std::to_string(min_free_bytes / kMiB) +
                                   " MiB (--min-free-mb)");
}

Status WriteFailure(int err, const std::string& what) {
  if (err == ENOSPC || err == EDQUOT) return Status::ResourceExhausted(std::string(kDiskFull) + ": " + what);
  return Status::Internal(what + ": " + std::strerror(err));
}

bool IsDiskFull(const Status& status) {
  return status.code() == StatusCode::kResourceExhausted && status.message().find(kDiskFull) != std::string::npos;
}

Status RetentionPolicy::Validate() const {
  if (max_age_s < 0) return Status::InvalidArgument("retention.max_age_s must be >= 0");
  if (max_bytes < 0) return Status::InvalidArgument("retention.max_bytes must be >= 0");
  if (keep_last < 0) return Status::InvalidArgument("retention.keep_last must be >= 0");
  return Status::Ok();
}

std::vector<std::string> SelectJobsToDelete(std::vector<StoredJob> jobs, const RetentionPolicy& policy,
                                            int64_t now_unix_s) {
  std::vector<std::string> out;
  if (!policy.enabled()) return out;
  // Newest first, so the first keep_last finished jobs are the protected ones. Jobs that ended
  // in the same second keep their input order reversed: later in the input is newer.
  std::reverse(jobs.begin(), jobs.end());
  std::stable_sort(jobs.begin(), jobs.end(),
                   [](const StoredJob& a, const StoredJob& b) { return a.end_unix_s > b.end_unix_s; });
  int64_t finished_bytes = 0;
  for (const auto& j : jobs) {
    if (j.finished) finished_bytes += j.bytes;
  }
  std::vector<const StoredJob*> candidates;  // finished, unpinned, beyond keep_last
  int finished_seen = 0;
  for (const auto& j : jobs) {
    if (!j.finished) continue;
    if (finished_seen++ < policy.keep_last) continue;
    if (!j.pinned) candidates.push_back(&j);
  }
  // Oldest first.
  std::reverse(candidates.begin(), candidates.end());
  for (const StoredJob* j : candidates) {
    const bool too_old = policy.max_age_s > 0 && now_unix_s - j->end_unix_s > policy.max_age_s;
    const bool over_budget = policy.max_bytes > 0 && finished_bytes > policy.max_bytes;
    if (!too_old && !over_budget) continue;
    out.push_back(j->job_id);
    finished_bytes -= j->bytes;
  }
  return out;
}

}  // namespace inspection
