// JobManager: queues, records and events of every job; the work itself is the JobRunner's.
#include "server/jobs/job_manager.h"

#include <google/protobuf/util/time_util.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <optional>

#include "server/logging/log_format.h"

namespace inspection {
using google::protobuf::util::TimeUtil;
using Clock = std::chrono::steady_clock;

namespace {

// Finished jobs kept in memory; older ones are served from the store.
constexpr size_t kMaxFinishedInMemory = 256;

bool IsTerminal(v1::JobState s) {
  return s == v1::JOB_STATE_SUCCEEDED || s == v1::JOB_STATE_FAILED || s == v1::JOB_STATE_CANCELLED;
}

const char* IdPrefix(v1::JobKind kind) {
  switch (kind) {
    case v1::JOB_KIND_SCAN:
      return "scan";
    case v1::JOB_KIND_CALIBRATE:
      return "cal";
    case v1::JOB_KIND_STUDY:
      return "study";
    default:
      return "rec";
  }
}

// A job that failed writing while the data disk was full failed because of the disk: the
// admin's fix is space, not a bug report. Other failures, and cancellations, stay as they are.
Status DiskFullOr(const Status& failure, bool disk_full_seen) {
  if (!disk_full_seen) return failure;
  const StatusCode c = failure.code();
  const bool write_failure = c == StatusCode::kInternal || c == StatusCode::kUnknown || c == StatusCode::kDataLoss ||
                             failure.message().find("cannot write") != std::string::npos;
  if (!write_failure) return failure;
  return Status::ResourceExhausted("data disk full: " + failure.message());
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// JobRecord

JobRecord::JobRecord(v1::Job job, std::vector<v1::JobEvent> events)
    : job_id_(job.job_id()),
      kind_(job.kind()),
      request_id_(job.request_id()),
      job_(std::move(job)),
      events_(std::move(events)) {}

v1::Job JobRecord::Snapshot() const {
  std::lock_guard<std::mutex> lock(mu_);
  return job_;
}

bool JobRecord::terminal() const {
  std::lock_guard<std::mutex> lock(mu_);
  return IsTerminal(job_.state());
}

bool JobRecord::EventsSince(size_t from, std::chrono::milliseconds timeout, std::vector<v1::JobEvent>* out) const {
  std::unique_lock<std::mutex> lock(mu_);
  cv_.wait_for(lock, timeout, [&] { return events_.size() > from || IsTerminal(job_.state()); });
  for (size_t i = from; i < events_.size(); ++i) out->push_back(events_[i]);
  // The terminal state and the terminal event come in one step (End), so a watcher that sees
  // the end has the last event too.
  return IsTerminal(job_.state());
}

void JobRecord::SetQueuePosition(int position) {
  std::lock_guard<std::mutex> lock(mu_);
  job_.set_queue_position(position);
}

v1::Job JobRecord::MarkRunning() {
  std::lock_guard<std::mutex> lock(mu_);
  job_.set_state(v1::JOB_STATE_RUNNING);
  job_.set_queue_position(0);
  *job_.mutable_start_time() = TimeUtil::GetCurrentTime();
  started_ = Clock::now();
  return job_;
}

bool JobRecord::End(const StatusOr<v1::JobResult>& outcome, const EventFill& fill, const Persist& persist) {
  v1::Job ended;
  v1::JobEvent e;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (IsTerminal(job_.state())) return false;
    if (outcome.ok()) {
      job_.set_state(v1::JOB_STATE_SUCCEEDED);
      *job_.mutable_result() = *outcome;
    } else {
      const Status& s = outcome.status();
      job_.set_state(s.code() == StatusCode::kCancelled ? v1::JOB_STATE_CANCELLED : v1::JOB_STATE_FAILED);
      job_.clear_result();  // a job that did not succeed offers no artifacts
      job_.set_error_code(int(s.code()));
      job_.set_error_message(s.message());
    }
    job_.set_queue_position(0);
    *job_.mutable_end_time() = TimeUtil::GetCurrentTime();
    ended = job_;
    e = NextEventLocked(fill);
    *e.mutable_job() = ended;
    events_.push_back(e);
  }
  persist(ended, e);
  cv_.notify_all();
  return true;
}

v1::JobEvent JobRecord::AppendEvent(const EventFill& fill, const std::function<void(const v1::JobEvent&)>& persist) {
  v1::JobEvent e;
  {
    std::lock_guard<std::mutex> lock(mu_);
    e = NextEventLocked(fill);
    events_.push_back(e);
  }
  // Persisted before watchers wake: an event a client has seen survives a restart.
  persist(e);
  cv_.notify_all();
  return e;
}

v1::JobEvent JobRecord::NextEventLocked(const EventFill& fill) const {
  v1::JobEvent e;
  e.set_job_id(job_id_);
  e.set_sequence(events_.size() + 1);
  *e.mutable_time() = TimeUtil::GetCurrentTime();
  e.set_state(job_.state());
  e.set_remaining_seconds(-1);
  if (started_ != Clock::time_point()) {
    e.set_elapsed_seconds(std::chrono::duration<double>(Clock::now() - started_).count());
  }
  fill(e);
  return e;
}

// ---------------------------------------------------------------------------------------------
// JobManager

JobManager::JobManager(const JobManagerOptions& options, DataStore* store, JobRunner* runner)
    : options_(options), store_(store), runner_(runner) {}

JobManager::~JobManager() { Shutdown(); }

Status JobManager::Start() {
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::Job> unfinished, store_->UnfinishedJobs());
  for (v1::Job& job : unfinished) {
    const bool was_running = job.state() == v1::JOB_STATE_RUNNING;
    INSPECT_ASSIGN_OR_RETURN(std::vector<v1::JobEvent> events, store_->Events(job.job_id()));
    job.set_state(v1::JOB_STATE_FAILED);
    job.set_error_code(int(StatusCode::kAborted));
    job.set_error_message(was_running
                              ? "the server stopped while the job was running; its partial results were discarded"
                              : "the server stopped before the job ran; submit it again");
    *job.mutable_end_time() = TimeUtil::GetCurrentTime();
    job.set_queue_position(0);
    INSPECT_RETURN_IF_ERROR(store_->PutJob(job));
    v1::JobEvent e;
    e.set_job_id(job.job_id());
    e.set_sequence(events.size() + 1);
    *e.mutable_time() = job.end_time();
    e.set_state(job.state());
    e.set_phase(v1::JOB_PHASE_DONE);
    e.set_message(job.error_message());
    *e.mutable_job() = job;
    INSPECT_RETURN_IF_ERROR(store_->AppendEvent(e));
    spdlog::warn("job {} marked failed: {}", job.job_id(), job.error_message());
  }
  rig_thread_ = std::thread([this] { Worker(&rig_queue_, /*rig=*/true); });
  reconstruct_thread_ = std::thread([this] { Worker(&reconstruct_queue_, /*rig=*/false); });
  return Status::Ok();
}

void JobManager::Shutdown() {
  std::vector<RecordPtr> queued;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return;
    stopping_ = true;
    for (auto& [id, r] : live_) r->cancel_requested = true;
    for (Queue* q : {&rig_queue_, &reconstruct_queue_}) {
      for (const QueuedJob& j : *q) queued.push_back(j.record);
      q->clear();  // the work goes now, uploads with it
    }
  }
  work_cv_.notify_all();
  for (const RecordPtr& r : queued) Finish(r, Status::Aborted("the server shut down before the job ran"));
  if (rig_thread_.joinable()) rig_thread_.join();
  if (reconstruct_thread_.joinable()) reconstruct_thread_.join();
}

StatusOr<std::shared_ptr<JobRecord>> JobManager::Submit(v1::JobKind kind, const std::string& request_id,
                                                        const std::string& label, const Prepare& prepare,
                                                        const std::string& owner) {
  if (!request_id.empty()) {
    std::lock_guard<std::mutex> lock(mu_);
    INSPECT_ASSIGN_OR_RETURN(RecordPtr existing, FindDuplicate(kind, request_id));
    if (existing) return existing;
  }
  INSPECT_ASSIGN_OR_RETURN(JobWork work, prepare());
  if (KindOf(work) != kind) return Status::Internal("job work does not match its kind");

  std::lock_guard<std::mutex> lock(mu_);
  if (stopping_) return Status::Unavailable("server is shutting down");
  if (!request_id.empty()) {  // again under the lock: a concurrent duplicate may have won
    INSPECT_ASSIGN_OR_RETURN(RecordPtr existing, FindDuplicate(kind, request_id));
    if (existing) return existing;
  }
  INSPECT_RETURN_IF_ERROR(Admit(kind));
  const auto* reconstruct = std::get_if<ReconstructWork>(&work);
  const std::string source_scan = reconstruct ? reconstruct->source_scan_id : std::string();
  if (!source_scan.empty() && deleting_.count(source_scan)) {
    return Status::NotFound("scan_id '" + source_scan + "' is being deleted");
  }
  v1::Job job;
  job.set_job_id(NewId(IdPrefix(kind)));
  job.set_kind(kind);
  job.set_state(v1::JOB_STATE_QUEUED);
  job.set_request_id(request_id);
  job.set_label(label);
  job.set_owner(owner);
  *job.mutable_create_time() = TimeUtil::GetCurrentTime();
  FillQueuedJob(work, &job);
  INSPECT_RETURN_IF_ERROR(store_->PutJob(job));
  auto r = std::make_shared<JobRecord>(std::move(job));
  const std::string description = DescribeWork(work);
  live_[r->job_id()] = r;
  if (!source_scan.empty()) scan_readers_[r->job_id()] = source_scan;
  Queue& queue = QueueFor(kind);
  queue.push_back({r, std::move(work)});
  // Emitted under mu_, so the QUEUED event is the job's first even if a worker takes it at once.
  const size_t position = queue.size();
  Emit(r, [&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_QUEUED);
    e.set_message("queued at position " + std::to_string(position));
  });
  work_cv_.notify_all();
  spdlog::info("job {} queued: {}", r->job_id(), description);
  return r;
}

StatusOr<JobManager::RecordPtr> JobManager::FindDuplicate(v1::JobKind kind, const std::string& request_id) {
  for (const auto& [id, r] : live_) {
    if (r->kind() == kind && r->request_id() == request_id) return r;
  }
  const std::optional<std::string> id = store_->FindJobByRequestId(kind, request_id);
  if (!id) return RecordPtr();
  INSPECT_ASSIGN_OR_RETURN(v1::Job job, store_->GetJob(*id));
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::JobEvent> events, store_->Events(*id));
  return std::make_shared<JobRecord>(std::move(job), std::move(events));
}

Status JobManager::Admit(v1::JobKind kind) const {
  if (IsRigJob(kind)) {
    // Scans and calibrations never interleave: a scan would use a bundle being replaced, a
    // calibration would find the rig moved.
    // A study is scans: it interleaves with scans, never with a calibration.
    auto scan_like = [](v1::JobKind k) { return k == v1::JOB_KIND_SCAN || k == v1::JOB_KIND_STUDY; };
    const v1::JobKind other = scan_like(kind) ? v1::JOB_KIND_CALIBRATE : v1::JOB_KIND_SCAN;
    auto is_other = [&](const RecordPtr& r) {
      return r && (other == v1::JOB_KIND_SCAN ? scan_like(r->kind()) : r->kind() == other);
    };
    if (is_other(running_rig_) ||
        std::any_of(rig_queue_.begin(), rig_queue_.end(), [&](const QueuedJob& j) { return is_other(j.record); })) {
      return Status::Aborted(std::string(other == v1::JOB_KIND_SCAN ? "a scan" : "a calibration") +
                             " is running or queued; scans and calibrations never interleave, retry after it");
    }
    if (int(rig_queue_.size()) >= options_.rig_queue_capacity) {
      return Status::ResourceExhausted("rig queue is full (" + std::to_string(options_.rig_queue_capacity) +
                                       " jobs waiting); retry later");
    }
    return Status::Ok();
  }
  if (int(reconstruct_queue_.size()) >= options_.reconstruct_queue_capacity) {
    return Status::ResourceExhausted("reconstruct queue is full; retry later");
  }
  return Status::Ok();
}

std::shared_ptr<JobRecord> JobManager::FindLive(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = live_.find(job_id);
  if (it == live_.end()) return nullptr;
  // Queue position is derived, not stored: compute it when asked.
  int position = 0;
  for (const Queue* q : {&rig_queue_, &reconstruct_queue_}) {
    for (size_t i = 0; i < q->size(); ++i) {
      if ((*q)[i].record == it->second) position = int(i) + 1;
    }
  }
  it->second->SetQueuePosition(position);
  return it->second;
}

StatusOr<std::shared_ptr<JobRecord>> JobManager::Find(const std::string& job_id) {
  if (RecordPtr r = FindLive(job_id)) return r;
  INSPECT_ASSIGN_OR_RETURN(v1::Job job, store_->GetJob(job_id));
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::JobEvent> events, store_->Events(job_id));
  return std::make_shared<JobRecord>(std::move(job), std::move(events));
}

StatusOr<v1::Job> JobManager::Cancel(const std::string& job_id) {
  INSPECT_ASSIGN_OR_RETURN(RecordPtr r, Find(job_id));
  if (r->terminal()) return r->Snapshot();
  r->cancel_requested = true;
  bool was_queued = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (Queue* q : {&rig_queue_, &reconstruct_queue_}) {
      auto it = std::find_if(q->begin(), q->end(), [&](const QueuedJob& j) { return j.record == r; });
      if (it != q->end()) {
        q->erase(it);  // the work goes now, an upload with it
        was_queued = true;
      }
    }
  }
  if (was_queued) Finish(r, Status::Cancelled("cancelled while queued"));
  spdlog::info("job {} cancel requested", job_id);
  return r->Snapshot();
}

Status JobManager::BeginDeletion(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  if (auto it = live_.find(job_id); it != live_.end() && !it->second->terminal()) {
    return Status::FailedPrecondition("job " + job_id + " is " + v1::JobState_Name(it->second->Snapshot().state()) +
                                      "; cancel it before deleting it");
  }
  for (const auto& [reader, scan] : scan_readers_) {
    if (scan == job_id) {
      return Status::FailedPrecondition("scan " + job_id + " is being reconstructed by job " + reader +
                                        "; delete it after that job ends");
    }
  }
  if (!deleting_.insert(job_id).second) return Status::Aborted("job " + job_id + " is being deleted already");
  return Status::Ok();
}

void JobManager::EndDeletion(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  deleting_.erase(job_id);
}

void JobManager::Forget(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  if (auto it = live_.find(job_id); it != live_.end() && it->second->terminal()) live_.erase(it);
}

int JobManager::queued_rig_jobs() const {
  std::lock_guard<std::mutex> lock(mu_);
  return int(rig_queue_.size());
}

std::string JobManager::running_rig_job() const {
  std::lock_guard<std::mutex> lock(mu_);
  return running_rig_ ? running_rig_->job_id() : std::string();
}

void JobManager::Emit(const RecordPtr& r, const EventFill& fill) {
  r->AppendEvent(fill, [&](const v1::JobEvent& e) {
    Status s = store_->AppendEvent(e);
    if (!s.ok()) spdlog::error("job {}: cannot persist event: {}", e.job_id(), s.ToString());
    if (options_.on_event) options_.on_event(e);
  });
}

void JobManager::Finish(const RecordPtr& r, const StatusOr<v1::JobResult>& outcome) {
  const ScopedLogJob log_job(r->job_id(), r->Snapshot().owner());
  const Status status = outcome.ok() ? Status::Ok() : outcome.status();
  v1::Job job;
  auto fill = [&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_DONE);
    e.set_progress(status.ok() ? 1.0 : 0.0);
    e.set_remaining_seconds(0);
    e.set_message(status.ok() ? "done" : status.ToString());
  };
  auto persist = [&](const v1::Job& ended, const v1::JobEvent& e) {
    job = ended;
    Status s = store_->PutJob(ended);
    if (!s.ok()) spdlog::error("job {}: cannot persist: {}", ended.job_id(), s.ToString());
    s = store_->AppendEvent(e);
    if (!s.ok()) spdlog::error("job {}: cannot persist event: {}", e.job_id(), s.ToString());
    if (options_.on_event) options_.on_event(e);
  };
  const bool ended = r->End(outcome, fill, persist);
  {
    std::lock_guard<std::mutex> lock(mu_);
    scan_readers_.erase(r->job_id());  // its reads are over, whichever way it ended
  }
  if (!ended) return;
  if (status.ok()) {
    spdlog::info("job {} succeeded", job.job_id());
  } else {
    spdlog::warn("job {} ended {}: {}", job.job_id(), v1::JobState_Name(job.state()), status.ToString());
  }
  std::lock_guard<std::mutex> lock(mu_);
  if (live_.size() > kMaxFinishedInMemory) {
    std::vector<std::pair<int64_t, std::string>> finished;
    for (const auto& [id, rec] : live_) {
      if (rec->terminal()) finished.push_back({rec->Snapshot().end_time().seconds(), id});
    }
    std::sort(finished.begin(), finished.end());
    for (size_t i = 0; i + kMaxFinishedInMemory / 2 < finished.size(); ++i) live_.erase(finished[i].second);
  }
}

std::optional<JobManager::QueuedJob> JobManager::WaitForWork(Queue& queue, bool rig) {
  std::unique_lock<std::mutex> lock(mu_);
  work_cv_.wait(lock, [&] { return stopping_ || !queue.empty(); });
  if (stopping_) return std::nullopt;
  QueuedJob job = std::move(queue.front());
  queue.pop_front();
  if (rig) running_rig_ = job.record;
  return job;
}

void JobManager::Worker(Queue* queue, bool rig) {
  for (;;) {
    RecordPtr r;
    std::optional<StatusOr<v1::JobResult>> outcome;
    {
      std::optional<QueuedJob> job = WaitForWork(*queue, rig);
      if (!job) return;
      r = job->record;
      if (r->cancel_requested) {
        outcome = Status::Cancelled("cancelled before it started");
      } else {
        Status s = store_->PutJob(r->MarkRunning());
        if (!s.ok()) spdlog::error("job {}: cannot persist: {}", r->job_id(), s.ToString());
        bool disk_full_seen = false;
        JobContext context;
        context.job_id = r->job_id();
        context.cancel = &r->cancel_requested;
        context.emit = [this, &r, &disk_full_seen](const EventFill& fill) {
          Emit(r, fill);
          if (options_.disk_full && !disk_full_seen) disk_full_seen = options_.disk_full();
        };
        const ScopedLogJob log_job(r->job_id(), r->Snapshot().owner());  // lines of the work name job and owner
        outcome = runner_->Run(job->work, context);
        if (!outcome->ok() && options_.disk_full) {
          disk_full_seen = disk_full_seen || options_.disk_full();
          outcome = StatusOr<v1::JobResult>(DiskFullOr(outcome->status(), disk_full_seen));
        }
      }
    }  // the work (an uploaded stack with it) is gone before the job ends
    if (rig) {
      // The runner has released the rig: a client that sees the job end can use the rig
      // (reset, calibrate, change specimen) at once.
      std::lock_guard<std::mutex> lock(mu_);
      running_rig_.reset();
    }
    Finish(r, *outcome);
  }
}

}  // namespace inspection
