// Bounded disk use of the data directory: the free-space reserve checked before new work, the
// mapping of a full disk to RESOURCE_EXHAUSTED, and the retention policy that decides which
// finished jobs the sweeper deletes (oldest first; never pinned or unfinished ones).
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

// Bytes available to an unprivileged writer on the file system holding `path`.
StatusOr<int64_t> FreeDiskBytes(const std::filesystem::path& path);

// RESOURCE_EXHAUSTED "data disk has N MiB free, below the reserve of M MiB" when short.
// min_free_bytes <= 0 disables the check.
Status CheckFreeSpaceReserve(const std::filesystem::path& data_dir, int64_t min_free_bytes);

// A write that failed with errno `err`: ENOSPC/EDQUOT become RESOURCE_EXHAUSTED "data disk full"
// (the job's own fault is not the cause, and the admin's fix is space), anything else INTERNAL.
Status WriteFailure(int err, const std::string& what);
// True for a status built by WriteFailure from a full disk, also after WithContext.
bool IsDiskFull(const Status& status);

struct RetentionPolicy {
  int64_t max_age_s = 0;    // finished jobs older than this are deleted; 0 = no age limit
  int64_t max_bytes = 0;    // total bytes of finished jobs' data above this are deleted; 0 = none
  int keep_last = 0;        // the newest N finished jobs are kept whatever the limits say
  Status Validate() const;  // INVALID_ARGUMENT naming the field for negative values
  bool enabled() const { return max_age_s > 0 || max_bytes > 0; }
};

// One job's footprint in the data directory, as the store knows it.
struct StoredJob {
  std::string job_id;
  int64_t end_unix_s = 0;  // when it finished; unfinished jobs are never candidates
  int64_t bytes = 0;       // its scan folder and artifacts
  bool finished = false;   // SUCCEEDED, FAILED or CANCELLED
  bool pinned = false;     // an admin asked to keep it
};

// The jobs to delete, oldest first, so that afterwards no finished, unpinned job outside the
// newest `keep_last` is older than max_age_s and the finished jobs' bytes are <= max_bytes as
// far as deleting unpinned ones can get. Unfinished and pinned jobs are never selected. Jobs
// with the same end second are ordered as given (later = newer).
std::vector<std::string> SelectJobsToDelete(std::vector<StoredJob> jobs, const RetentionPolicy& policy,
                                            int64_t now_unix_s);

}  // namespace inspection
