// Deleting stored data: a finished job (record, events, artifacts, stored stack), a scan's raw
// stack alone, pins, and the retention sweep that applies RetentionPolicy (data_lifecycle.h):
// oldest finished, unpinned jobs first, never a queued or running job nor a scan a running
// reconstruction reads. Rows go before files, so nothing is ever served from a missing file.
// RetentionSweeper runs the sweep on its own thread every interval and stops promptly.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/util/status.h"
#include "server/storage/data_lifecycle.h"
#include "server/storage/data_store.h"
#include "server/jobs/job_manager.h"

namespace inspection {

struct DeleteOutcome {
  std::string id;
  int64_t bytes_freed = 0;  // file bytes removed from the data directory
  int artifacts_deleted = 0;
};

struct SweepReport {
  int64_t bytes_before = 0;  // finished jobs' bytes (artifacts and stored stacks) before the sweep
  int64_t bytes_after = 0;
  std::vector<std::string> deleted;  // oldest first
};

// Bytes of every regular file below `folder` (0 when it does not exist).
int64_t FolderBytes(const std::filesystem::path& folder);

class DataJanitor {
 public:
  DataJanitor(DataStore* store, JobManager* jobs) : store_(store), jobs_(jobs) {}

  // NOT_FOUND for an unknown job; FAILED_PRECONDITION while it is queued, running or read.
  StatusOr<DeleteOutcome> DeleteJob(const std::string& job_id);
  // The scan's stored stack and its stack.zip artifact; the job and its depth results stay.
  StatusOr<DeleteOutcome> DeleteScan(const std::string& scan_id);
  Status Pin(const std::string& job_id, bool pinned);
  StatusOr<SweepReport> Sweep(const RetentionPolicy& policy, int64_t now_unix_s);

 private:
  DataStore* store_;
  JobManager* jobs_;
};

class RetentionSweeper {
 public:
  // Sweeps every `interval` once Start()ed; a policy without limits sweeps nothing.
  RetentionSweeper(DataJanitor* janitor, RetentionPolicy policy, std::chrono::seconds interval)
      : janitor_(janitor), policy_(policy), interval_(interval) {}
  ~RetentionSweeper() { Stop(); }

  void Start();
  void Stop();  // wakes the thread and joins it (a sweep in progress finishes first)
  // One sweep now on the caller's thread (tests, admins), serialised with the background one.
  StatusOr<SweepReport> SweepNow();
  const RetentionPolicy& policy() const { return policy_; }

 private:
  void Loop();

  DataJanitor* janitor_;
  const RetentionPolicy policy_;
  const std::chrono::seconds interval_;
  std::mutex sweep_mu_;  // one sweep at a time
  std::mutex mu_;        // guards stopping_
  std::condition_variable cv_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace inspection
