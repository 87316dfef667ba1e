// Deletion of stored jobs and scans, pins and the retention sweep (retention_sweeper.h).
#include "server/jobs/retention_sweeper.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <ctime>
#include <set>
#include <system_error>
#include <utility>

namespace inspection {
namespace fs = std::filesystem;

namespace {

bool IsFinished(v1::JobState s) {
  return s == v1::JOB_STATE_SUCCEEDED || s == v1::JOB_STATE_FAILED || s == v1::JOB_STATE_CANCELLED;
}

// Lifts the deletion mark whatever way the deletion ends.
class DeletionMark {
 public:
  DeletionMark(JobManager* jobs, std::string id) : jobs_(jobs), id_(std::move(id)) {}
  ~DeletionMark() { jobs_->EndDeletion(id_); }
  DeletionMark(const DeletionMark&) = delete;
  DeletionMark& operator=(const DeletionMark&) = delete;

 private:
  JobManager* jobs_;
  std::string id_;
};

}  // namespace

int64_t FolderBytes(const fs::path& folder) {
  int64_t total = 0;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code size_ec;
    if (it->is_regular_file(size_ec)) {
      const auto n = it->file_size(size_ec);
      if (!size_ec) total += int64_t(n);
    }
  }
  return total;
}

StatusOr<DeleteOutcome> DataJanitor::DeleteJob(const std::string& job_id) {
  INSPECT_ASSIGN_OR_RETURN(v1::Job job, store_->GetJob(job_id));
  INSPECT_RETURN_IF_ERROR(jobs_->BeginDeletion(job_id));
  const DeletionMark mark(jobs_, job_id);
  if (!IsFinished(job.state())) {
    return Status::FailedPrecondition("job " + job_id + " is " + v1::JobState_Name(job.state()) +
                                      "; cancel it before deleting it");
  }
  const fs::path artifacts = store_->artifacts_dir() / job_id;
  const fs::path scan = store_->scans_dir() / job_id;
  DeleteOutcome out;
  out.id = job_id;
  out.bytes_freed = FolderBytes(artifacts) + FolderBytes(scan);
  out.artifacts_deleted = job.result().artifacts_size();
  INSPECT_RETURN_IF_ERROR(store_->DeleteJobRecords(job_id));
  jobs_->Forget(job_id);
  std::error_code ec;
  fs::remove_all(artifacts, ec);
  if (ec) spdlog::warn("job {} deleted; its artifact folder remains: {}", job_id, ec.message());
  fs::remove_all(scan, ec);
  if (ec) spdlog::warn("job {} deleted; its scan folder remains: {}", job_id, ec.message());
  spdlog::info("job {} deleted ({} bytes, {} artifacts)", job_id, out.bytes_freed, out.artifacts_deleted);
  return out;
}

StatusOr<DeleteOutcome> DataJanitor::DeleteScan(const std::string& scan_id) {
  auto job = store_->GetJob(scan_id);
  if (!job.ok() || job->kind() != v1::JOB_KIND_SCAN) return Status::NotFound("scan_id '" + scan_id + "' not found");
  INSPECT_RETURN_IF_ERROR(jobs_->BeginDeletion(scan_id));
  const DeletionMark mark(jobs_, scan_id);
  const fs::path scan = store_->scans_dir() / scan_id;
  std::error_code ec;
  INSPECT_ASSIGN_OR_RETURN(std::vector<StoredArtifact> zips,
                           store_->DeleteArtifactsOfKind(scan_id, v1::ARTIFACT_KIND_STACK_ZIP));
  if (zips.empty() && !fs::exists(scan, ec)) return Status::NotFound("scan_id '" + scan_id + "' has no stored stack");
  jobs_->Forget(scan_id);
  DeleteOutcome out;
  out.id = scan_id;
  out.artifacts_deleted = int(zips.size());
  out.bytes_freed = FolderBytes(scan);
  for (const StoredArtifact& a : zips) {
    const auto n = fs::file_size(a.path, ec);
    if (!ec) out.bytes_freed += int64_t(n);
    fs::remove(a.path, ec);
  }
  fs::remove_all(scan, ec);
  if (ec) spdlog::warn("scan {}: its folder remains: {}", scan_id, ec.message());
  spdlog::info("scan {} stack deleted ({} bytes)", scan_id, out.bytes_freed);
  return out;
}

Status DataJanitor::Pin(const std::string& job_id, bool pinned) {
  INSPECT_RETURN_IF_ERROR(store_->GetJob(job_id).status());
  return store_->SetPinned(job_id, pinned);
}

StatusOr<SweepReport> DataJanitor::Sweep(const RetentionPolicy& policy, int64_t now_unix_s) {
  SweepReport report;
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::Job> finished, store_->FinishedJobs());
  INSPECT_ASSIGN_OR_RETURN(std::vector<std::string> pinned_ids, store_->PinnedJobs());
  const std::set<std::string> pinned(pinned_ids.begin(), pinned_ids.end());
  // Oldest first to the nanosecond: jobs ending within one second keep their true order.
  std::sort(finished.begin(), finished.end(), [](const v1::Job& a, const v1::Job& b) {
    return std::make_pair(a.end_time().seconds(), a.end_time().nanos()) <
           std::make_pair(b.end_time().seconds(), b.end_time().nanos());
  });
  std::vector<StoredJob> stored;
  for (const v1::Job& j : finished) {
    StoredJob s;
    s.job_id = j.job_id();
    s.end_unix_s = j.end_time().seconds();
    s.bytes = FolderBytes(store_->artifacts_dir() / j.job_id()) + FolderBytes(store_->scans_dir() / j.job_id());
    s.finished = true;
    s.pinned = pinned.count(j.job_id()) > 0;
    report.bytes_before += s.bytes;
    stored.push_back(std::move(s));
  }
  report.bytes_after = report.bytes_before;
  for (const std::string& id : SelectJobsToDelete(std::move(stored), policy, now_unix_s)) {
    auto deleted = DeleteJob(id);
    if (!deleted.ok()) {  // e.g. a reconstruction started reading it meanwhile: next sweep
      spdlog::info("retention: job {} kept for now: {}", id, deleted.status().message());
      continue;
    }
    report.bytes_after -= deleted->bytes_freed;
    report.deleted.push_back(id);
  }
  if (!report.deleted.empty()) {
    spdlog::info("retention: deleted {} jobs, finished jobs' data {} -> {} bytes", report.deleted.size(),
                 report.bytes_before, report.bytes_after);
  }
  return report;
}

void RetentionSweeper::Start() {
  if (!policy_.enabled() || thread_.joinable()) return;
  thread_ = std::thread([this] { Loop(); });
}

void RetentionSweeper::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

StatusOr<SweepReport> RetentionSweeper::SweepNow() {
  std::lock_guard<std::mutex> lock(sweep_mu_);
  return janitor_->Sweep(policy_, int64_t(std::time(nullptr)));
}

void RetentionSweeper::Loop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!stopping_) {
    lock.unlock();
    auto report = SweepNow();
    if (!report.ok()) spdlog::error("retention sweep failed: {}", report.status().ToString());
    lock.lock();
    cv_.wait_for(lock, interval_, [this] { return stopping_; });
  }
}

}  // namespace inspection
