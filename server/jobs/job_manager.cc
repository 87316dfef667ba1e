// JobManager: queues, records and events of every job; the work itself is the JobRunner's.
#include "server/jobs/job_manager.h"

#include <google/protobuf/util/time_util.h>
#include <spdlog/spdlog.h>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <optional>
#include <random>

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
    case v1::JOB_KIND_VERIFY:
      return "ver";
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

bool JobRecord::EventsSince(size_t from, std::chrono::milliseconds timeout, std::vector<v1::JobEvent>* out) {
  std::unique_lock<std::mutex> lock(mu_);
  if (follow_store_) {
    // Another replica writes this job's events: its store is the only place they appear.
    cv_.wait_for(lock, std::min(timeout, follow_poll_),
                 [&] { return events_.size() > from || IsTerminal(job_.state()) || poked_; });
    poked_ = false;
    if (events_.size() <= from && !IsTerminal(job_.state()) && follow_store_) {
      lock.unlock();
      Refresh();
      lock.lock();
    }
  } else {
    cv_.wait_for(lock, timeout, [&] { return events_.size() > from || IsTerminal(job_.state()); });
  }
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

void JobRecord::Follow(DataStore* store, std::chrono::milliseconds poll) {
  std::lock_guard<std::mutex> lock(mu_);
  follow_store_ = store;
  follow_poll_ = poll;
}

void JobRecord::Poke() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!follow_store_) return;
    poked_ = true;
  }
  cv_.notify_all();
}

void JobRecord::StopFollowing() {
  std::lock_guard<std::mutex> lock(mu_);
  follow_store_ = nullptr;
}

bool JobRecord::Refresh() {
  DataStore* store;
  {
    std::lock_guard<std::mutex> lock(mu_);
    store = follow_store_;
  }
  if (!store) return true;
  // Events first, then the job: a terminal job read after its events never lacks the last one.
  auto events = store->Events(job_id_);
  if (!events.ok()) return false;
  auto job = store->GetJob(job_id_);
  if (!job.ok()) return false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!follow_store_) return true;  // a worker here took it meanwhile: its record is newer
    for (size_t i = events_.size(); i < events->size(); ++i) events_.push_back((*events)[i]);
    const bool ended = IsTerminal(job->state());
    if (!ended || events_.size() == events->size()) job_ = std::move(*job);
  }
  cv_.notify_all();
  return true;
}

void JobRecord::Reload(v1::Job job, std::vector<v1::JobEvent> events) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    job_ = std::move(job);
    // Never fewer events than a watcher has been sent: the store's are a superset of what this
    // process recorded unless a write failed.
    if (events.size() >= events_.size()) events_ = std::move(events);
  }
  cv_.notify_all();
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
    : options_(options), store_(store), runner_(runner), worker_id_(options.pool.worker_id) {
  if (worker_id_.empty()) {
    char host[256] = {};
    gethostname(host, sizeof host - 1);
    std::random_device rd;
    char suffix[16];
    std::snprintf(suffix, sizeof suffix, "%06x", unsigned(rd()) & 0xffffff);
    worker_id_ = std::string(host) + "-" + std::to_string(getpid()) + "-" + suffix;
  }
}

JobManager::~JobManager() { Shutdown(); }

Status JobManager::Start() {
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::Job> unfinished, store_->UnfinishedJobs());
  // The pool's queued and running jobs are the pool's, not this process's: a dead worker's lease
  // runs out and the job runs again.
  std::set<std::string> pooled;
  if (pool()) {
    INSPECT_ASSIGN_OR_RETURN(std::vector<std::string> ids, store_->QueuedWorkIds());
    pooled.insert(ids.begin(), ids.end());
  }
  for (v1::Job& job : unfinished) {
    if (pooled.count(job.job_id())) continue;
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
  if (pool()) {
    if (options_.pool.workers < 1) return Status::InvalidArgument("pool workers must be >= 1");
    if (options_.pool.lease < std::chrono::milliseconds(300)) return Status::InvalidArgument("pool lease must be >= 300 ms");
    writer_thread_ = std::thread([this] { PoolWriter(); });
    // Another replica's upload wakes an idle worker here, and its events a watcher here, at once;
    // the poll stays for notifications lost while the listening connection was down.
    store_->ListenForChanges([this](DataStore::Change change, const std::string& job_id) {
      RecordPtr follower;
      {
        std::lock_guard<std::mutex> lock(mu_);
        if (change == DataStore::Change::kWorkQueued) {
          ++pool_submissions_;
        } else if (auto it = pool_followers_.find(job_id); it != pool_followers_.end()) {
          follower = it->second.lock();
        }
      }
      if (change == DataStore::Change::kWorkQueued) work_cv_.notify_all();
      if (follower) follower->Poke();
    });
    for (int i = 0; i < options_.pool.workers; ++i) pool_threads_.emplace_back([this] { PoolWorker(); });
    // Two leases, and never under 2 s: a folder's time may have a coarse grain on a shared volume.
    upload_sweeper_ = std::make_unique<OrphanUploadSweeper>(
        store_, std::max(std::chrono::milliseconds(2000), 2 * options_.pool.lease));
    heartbeat_thread_ = std::thread([this] { PoolHeartbeat(); });
    upload_keeper_thread_ = std::thread([this] { KeepUploadsAlive(); });
    spdlog::info("reconstruct pool: worker {} ({} at once, lease {} ms)", worker_id_, options_.pool.workers,
                 options_.pool.lease.count());
  } else {
    reconstruct_thread_ = std::thread([this] { Worker(&reconstruct_queue_, /*rig=*/false); });
  }
  return Status::Ok();
}

void JobManager::Shutdown() {
  std::vector<RecordPtr> queued;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return;
    stopping_ = true;
    for (auto& [id, r] : live_) r->cancel_requested = true;
    for (auto& [id, r] : pool_held_) pool_hand_back_.insert(id);  // queued again, for another replica
    pool_hints_.clear();  // their input stays on the shared folder: the queue still has them
    for (Queue* q : {&rig_queue_, &reconstruct_queue_}) {
      for (const QueuedJob& j : *q) queued.push_back(j.record);
      q->clear();  // the work goes now, uploads with it
    }
  }
  if (pool()) store_->ListenForChanges(nullptr);  // no call into this manager after it
  work_cv_.notify_all();
  pool_cv_.notify_all();
  for (const RecordPtr& r : queued) Finish(r, Status::Aborted("the server shut down before the job ran"));
  if (rig_thread_.joinable()) rig_thread_.join();
  if (reconstruct_thread_.joinable()) reconstruct_thread_.join();
  for (std::thread& t : pool_threads_) t.join();
  pool_threads_.clear();
  if (heartbeat_thread_.joinable()) heartbeat_thread_.join();
  if (upload_keeper_thread_.joinable()) upload_keeper_thread_.join();
  if (writer_thread_.joinable()) {
    {
      std::lock_guard<std::mutex> lock(write_mu_);
      writer_stop_ = true;  // after the workers: what they queued is written first
    }
    write_cv_.notify_all();
    writer_thread_.join();
  }
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
  if (pool() && kind == v1::JOB_KIND_RECONSTRUCT) {
    if (draining_) return Status::Unavailable("this replica is draining (shutting down); another replica takes the job");
    INSPECT_ASSIGN_OR_RETURN(int64_t depth, store_->QueueDepth());
    if (depth >= options_.pool.queue_capacity) {
      return Status::ResourceExhausted("the pool's reconstruct queue is full (" + std::to_string(depth) +
                                       " jobs waiting); retry later");
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
    const std::string description = DescribeWork(work);
    return SubmitToPool(std::move(job), std::move(work), description);
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
  if (pool() && job.kind() == v1::JOB_KIND_RECONSTRUCT && !IsTerminal(job.state())) {
    return FollowerFor(std::move(job), std::move(events));  // it runs wherever the pool runs it
  }
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
    // A verification measures the instrument with whatever bundle is active when it runs, and
    // changes none: it queues behind either.
    const bool ordered = kind != v1::JOB_KIND_VERIFY;
    if (ordered && (is_other(running_rig_) ||
        std::any_of(rig_queue_.begin(), rig_queue_.end(), [&](const QueuedJob& j) { return is_other(j.record); }))) {
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
  if (pool() && job.kind() == v1::JOB_KIND_RECONSTRUCT && !IsTerminal(job.state())) {
    std::lock_guard<std::mutex> lock(mu_);
    return FollowerFor(std::move(job), std::move(events));
  }
  return std::make_shared<JobRecord>(std::move(job), std::move(events));
}

StatusOr<v1::Job> JobManager::Cancel(const std::string& job_id) {
  INSPECT_ASSIGN_OR_RETURN(RecordPtr r, Find(job_id));
  if (r->terminal()) return r->Snapshot();
  if (pool() && r->kind() == v1::JOB_KIND_RECONSTRUCT) return CancelPoolJob(r);
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

int64_t JobManager::reconstruct_queue_depth() const {
  if (pool()) return pool_queue_depth_.load();
  std::lock_guard<std::mutex> lock(mu_);
  return int64_t(reconstruct_queue_.size());
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

// ---------------------------------------------------------------------------------------------
// Pool mode

namespace {

namespace fs = std::filesystem;

// Best effort: what cannot be removed now is a stale folder of a job that ended.
void RemoveFolder(const fs::path& p) {
  std::error_code ec;
  fs::remove_all(p, ec);
}

v1::JobEvent PoolEvent(const v1::Job& job, size_t sequence, v1::JobPhase phase, const std::string& message) {
  v1::JobEvent e;
  e.set_job_id(job.job_id());
  e.set_sequence(sequence);
  *e.mutable_time() = TimeUtil::GetCurrentTime();
  e.set_state(job.state());
  e.set_phase(phase);
  e.set_remaining_seconds(-1);
  e.set_message(message);
  return e;
}

}  // namespace

JobManager::RecordPtr JobManager::FollowerFor(v1::Job job, std::vector<v1::JobEvent> events) {
  const std::string id = job.job_id();
  if (auto it = pool_followers_.find(id); it != pool_followers_.end()) {
    if (RecordPtr r = it->second.lock()) return r;
  }
  auto r = std::make_shared<JobRecord>(std::move(job), std::move(events));
  r->Follow(store_, options_.pool.poll);
  pool_followers_[id] = r;
  // Expired entries go as new ones come.
  for (auto it = pool_followers_.begin(); it != pool_followers_.end();) {
    it = it->second.expired() ? pool_followers_.erase(it) : std::next(it);
  }
  return r;
}

StatusOr<JobManager::RecordPtr> JobManager::SubmitToPool(v1::Job job, JobWork work, const std::string& description) {
  auto* reconstruct = std::get_if<ReconstructWork>(&work);
  if (!reconstruct) return Status::Internal("only reconstructions go to the pool");
  QueuedWork queued;
  queued.job_id = job.job_id();
  queued.input = reconstruct->pool_input;
  if (reconstruct->source_scan_id.empty()) {
    // The upload's folder is the stored input from now on: the worker that ends the job removes it.
    std::error_code ec;
    const fs::path rel = fs::relative(reconstruct->stack_dir, store_->data_dir(), ec);
    if (ec || rel.empty() || *rel.begin() == "..") {
      return Status::Internal("the upload folder " + reconstruct->stack_dir.string() + " is not in the data directory");
    }
    queued.stack_dir = rel.string();
  }
  v1::JobEvent e = PoolEvent(job, 1, v1::JOB_PHASE_QUEUED, "queued in the pool by " + worker_id_);
  INSPECT_RETURN_IF_ERROR(store_->EnqueueWork(job, e, queued));
  if (reconstruct->upload && reconstruct->source_scan_id.empty()) reconstruct->upload->Release();
  if (options_.on_event) options_.on_event(e);
  RecordPtr r = FollowerFor(std::move(job), {e});
  pool_hints_.emplace(r->job_id(), std::move(work));
  ++pool_submissions_;
  work_cv_.notify_all();
  spdlog::info("job {} queued in the pool: {}", r->job_id(), description);
  return r;
}

StatusOr<v1::Job> JobManager::CancelPoolJob(const RecordPtr& r) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = pool_held_.find(r->job_id()); it != pool_held_.end()) {
      it->second->cancel_requested = true;
      spdlog::info("job {} cancel requested", r->job_id());
      return it->second->Snapshot();
    }
  }
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::JobEvent> events, store_->Events(r->job_id()));
  v1::Job job = r->Snapshot();
  job.set_state(v1::JOB_STATE_CANCELLED);
  job.clear_result();
  job.set_error_code(int(StatusCode::kCancelled));
  job.set_error_message("cancelled while queued");
  job.set_queue_position(0);
  *job.mutable_end_time() = TimeUtil::GetCurrentTime();
  v1::JobEvent e = PoolEvent(job, events.size() + 1, v1::JOB_PHASE_DONE, "cancelled while queued");
  e.set_remaining_seconds(0);
  *e.mutable_job() = job;
  INSPECT_ASSIGN_OR_RETURN(bool removed, store_->CancelQueuedWork(job, e));
  if (removed) {
    std::lock_guard<std::mutex> lock(mu_);
    pool_hints_.erase(job.job_id());
    if (options_.on_event) options_.on_event(e);
    spdlog::info("job {} cancelled while queued", job.job_id());
  } else {
    spdlog::info("job {} cancel requested (running on another replica)", job.job_id());
  }
  r->Refresh();
  return r->Snapshot();
}

int JobManager::Drain(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mu_);
  if (!pool()) return 0;
  draining_ = true;
  work_cv_.notify_all();
  spdlog::info("draining: taking no more work; {} job(s) running here", pool_held_.size());
  pool_cv_.wait_for(lock, timeout, [&] { return pool_held_.empty(); });
  int handed_back = 0;
  for (auto& [id, r] : pool_held_) {
    pool_hand_back_.insert(id);
    r->cancel_requested = true;
    ++handed_back;
  }
  if (handed_back) spdlog::warn("drain: {} job(s) still running after {} ms: handing them back", handed_back, timeout.count());
  pool_cv_.wait(lock, [&] { return pool_held_.empty(); });
  return handed_back;
}

void JobManager::PoolWorker() {
  const int64_t lease_ms = options_.pool.lease.count();
  bool reported_error = false;
  std::chrono::milliseconds backoff{500};
  for (;;) {
    std::vector<std::string> preferred;
    uint64_t seen;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stopping_ || draining_) return;
      for (const auto& [id, w] : pool_hints_) preferred.push_back(id);
      seen = pool_submissions_;
    }
    auto claimed = store_->ClaimWork(worker_id_, lease_ms, preferred);
    if (!claimed.ok()) {
      if (!reported_error) spdlog::error("pool: cannot take work: {} (retrying)", claimed.status().ToString());
      reported_error = true;
      std::unique_lock<std::mutex> lock(mu_);
      work_cv_.wait_for(lock, backoff, [&] { return stopping_ || draining_; });
      backoff = std::min(backoff * 2, std::chrono::milliseconds(10000));
      continue;
    }
    if (reported_error) spdlog::info("pool: the work queue answers again");
    reported_error = false;
    backoff = std::chrono::milliseconds(500);
    if (!*claimed) {
      std::unique_lock<std::mutex> lock(mu_);
      work_cv_.wait_for(lock, options_.pool.poll,
                        [&] { return stopping_ || draining_ || pool_submissions_ != seen; });
      continue;
    }
    RunPoolJob(**claimed);
  }
}

void JobManager::RunPoolJob(const QueuedWork& claimed) {
  const std::string& id = claimed.job_id;
  RecordPtr r;
  std::optional<JobWork> work;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = pool_followers_.find(id); it != pool_followers_.end()) r = it->second.lock();
  }
  // A first attempt at a job accepted here: the record streamed to its client is the store's
  // (nobody else writes a queued job; a cancel comes with the claim), so it is not read again.
  const bool fresh = r && claimed.attempts == 1 && r->Snapshot().state() == v1::JOB_STATE_QUEUED;
  StatusOr<v1::Job> job = fresh ? StatusOr<v1::Job>(v1::Job()) : store_->GetJob(id);
  auto events = job.ok() ? (fresh ? StatusOr<std::vector<v1::JobEvent>>(std::vector<v1::JobEvent>()) : store_->Events(id))
                         : StatusOr<std::vector<v1::JobEvent>>(job.status());
  if (!events.ok()) {
    // Its lease runs out and a worker takes it again once the store answers.
    spdlog::error("pool: job {} taken but not readable: {}", id, events.status().ToString());
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = pool_hints_.find(id); it != pool_hints_.end()) {
      work = std::move(it->second);
      pool_hints_.erase(it);
    }
    if (r) {
      r->StopFollowing();
      if (!fresh) r->Reload(*job, *events);
    } else {
      r = std::make_shared<JobRecord>(*job, *events);
    }
    if (claimed.cancel_requested) r->cancel_requested = true;
    live_[id] = r;
    pool_held_[id] = r;
  }
  const ScopedLogJob log_job(id, r->Snapshot().owner());
  if (claimed.attempts > 1) {
    // What the earlier attempt left: its artifact rows went with the claim, its files go now.
    RemoveFolder(store_->artifacts_dir() / id);
    RemoveFolder(store_->tmp_dir() / (id + ".artifacts"));
    RemoveFolder(store_->tmp_dir() / (id + ".stack"));
    spdlog::warn("job {} taken over by {} (attempt {}): the replica that ran it stopped renewing its lease", id,
                 worker_id_, claimed.attempts);
  }
  const fs::path input = claimed.stack_dir.empty() ? fs::path() : store_->data_dir() / claimed.stack_dir;
  std::optional<StatusOr<v1::JobResult>> outcome;
  if (!work) {
    auto restored = options_.pool.restore
                        ? options_.pool.restore(claimed, input)
                        : StatusOr<JobWork>(Status::Internal("this server cannot rebuild a pool job's work"));
    if (restored.ok()) {
      work = std::move(*restored);
    } else {
      outcome = StatusOr<v1::JobResult>(restored.status().WithContext("the job's stored input"));
    }
  }
  if (work) {
    if (auto* w = std::get_if<ReconstructWork>(&*work); w && w->upload && w->source_scan_id.empty()) {
      w->upload->Release();  // the stored input: removed below once the job's end is recorded
    }
    QueueWrite({r->MarkRunning(), {}});
    EmitPool(r, [&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_PREPARING);
      e.set_message("running on " + worker_id_ + (claimed.attempts > 1 ? ", attempt " + std::to_string(claimed.attempts) : ""));
    });
    if (r->cancel_requested) {
      outcome = StatusOr<v1::JobResult>(Status::Cancelled("cancelled before it started"));
    } else {
      bool disk_full_seen = false;
      JobContext context;
      context.job_id = id;
      context.cancel = &r->cancel_requested;
      context.emit = [this, &r, &disk_full_seen](const EventFill& fill) {
        EmitPool(r, fill);
        if (options_.disk_full && !disk_full_seen) disk_full_seen = options_.disk_full();
      };
      outcome = runner_->Run(*work, context);
      if (!outcome->ok() && options_.disk_full) {
        disk_full_seen = disk_full_seen || options_.disk_full();
        outcome = StatusOr<v1::JobResult>(DiskFullOr(outcome->status(), disk_full_seen));
      }
    }
    work.reset();  // decoded frames and private folders go before the job ends
  }
  // The attempt's progress is in the store before its end or hand-back, which number their
  // event after the stored ones.
  FlushWrites();
  bool lost, hand_back;
  // The database went away during the run (a write of the job's events or artifacts failed
  // UNAVAILABLE): the job is not the failure, so it is queued again once the database answers.
  const bool store_lost = !outcome->ok() && outcome->status().code() == StatusCode::kUnavailable;
  {
    std::lock_guard<std::mutex> lock(mu_);
    lost = pool_lost_.count(id) > 0;
    hand_back = (pool_hand_back_.count(id) > 0 && !outcome->ok() && outcome->status().code() == StatusCode::kCancelled) ||
                store_lost;
  }
  bool recorded = false;
  if (lost) {
    spdlog::warn("job {}: another worker took its lease over; this attempt's outcome is discarded", id);
  } else if (hand_back) {
    const std::string why = store_lost ? "the database was lost during the run (" + outcome->status().message() + ")"
                                       : "handed back by " + worker_id_ + " (shutting down)";
    std::chrono::milliseconds wait{250};
    for (bool logged = false;;) {
      v1::Job queued = r->Snapshot();
      queued.set_state(v1::JOB_STATE_QUEUED);
      queued.clear_start_time();
      auto stored = store_->Events(id);
      StatusOr<bool> released = stored.status();
      if (stored.ok()) {
        v1::JobEvent e = PoolEvent(queued, stored->size() + 1, v1::JOB_PHASE_QUEUED, why + ": queued again");
        released = store_->ReleaseWork(worker_id_, queued, e);
      }
      if (released.ok()) {
        if (*released) {
          spdlog::warn("job {} queued again: {}", id, why);
        } else {
          spdlog::warn("job {}: lease lost before it was handed back", id);
        }
        break;
      }
      if (!logged) spdlog::error("job {}: cannot hand it back yet: {} (retrying)", id, released.status().ToString());
      logged = true;
      std::unique_lock<std::mutex> lock(mu_);
      if (stopping_ || pool_lost_.count(id)) break;  // the lease's expiry queues it again
      pool_cv_.wait_for(lock, wait, [&] { return stopping_ || pool_lost_.count(id) > 0; });
      wait = std::min(wait * 2, std::chrono::milliseconds(5000));
    }
  } else {
    const Status status = outcome->ok() ? Status::Ok() : outcome->status();
    auto fill = [&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_DONE);
      e.set_progress(status.ok() ? 1.0 : 0.0);
      e.set_remaining_seconds(0);
      e.set_message(status.ok() ? "done" : status.ToString());
    };
    auto persist = [&](const v1::Job& ended, const v1::JobEvent& e) {
      // The database may be away for a while: the job is done, so its end is kept trying while
      // the lease holds (the heartbeat renews it once the database is back); a replica stopping
      // meanwhile leaves it to the lease's expiry and a rerun.
      std::chrono::milliseconds wait{250};
      for (bool logged = false;;) {
        auto held = store_->CompleteWork(worker_id_, ended, e);
        if (held.ok()) {
          recorded = *held;
          if (!recorded) spdlog::warn("job {}: lease lost before its end was recorded; discarded", id);
          break;
        }
        if (!logged) spdlog::error("job {}: cannot record its end: {} (retrying)", id, held.status().ToString());
        logged = true;
        std::unique_lock<std::mutex> lock(mu_);
        if (stopping_ || pool_lost_.count(id)) break;
        pool_cv_.wait_for(lock, wait, [&] { return stopping_ || pool_lost_.count(id) > 0; });
        wait = std::min(wait * 2, std::chrono::milliseconds(5000));
      }
      if (recorded && options_.on_event) options_.on_event(e);
    };
    r->End(*outcome, fill, persist);
    if (recorded) {
      if (!input.empty()) RemoveFolder(input);
      Status forgotten = store_->ForgetWork(id);  // else the next sweep does it
      if (!forgotten.ok()) spdlog::debug("job {}: queue row left for the sweep: {}", id, forgotten.ToString());
      if (status.ok()) {
        spdlog::info("job {} succeeded", id);
      } else {
        spdlog::warn("job {} ended {}: {}", id, v1::JobState_Name(r->Snapshot().state()), status.ToString());
      }
    }
  }
  std::lock_guard<std::mutex> lock(mu_);
  pool_held_.erase(id);
  pool_lost_.erase(id);
  pool_hand_back_.erase(id);
  if (!recorded) {
    // This record is not the job's any more: serve the store's.
    live_.erase(id);
    r->Follow(store_, options_.pool.poll);
    pool_followers_[id] = r;
  } else if (live_.size() > kMaxFinishedInMemory) {
    std::vector<std::pair<int64_t, std::string>> finished;
    for (const auto& [jid, rec] : live_) {
      if (rec->terminal()) finished.push_back({rec->Snapshot().end_time().seconds(), jid});
    }
    std::sort(finished.begin(), finished.end());
    for (size_t i = 0; i + kMaxFinishedInMemory / 2 < finished.size(); ++i) live_.erase(finished[i].second);
  }
  pool_cv_.notify_all();
}

void JobManager::PoolHeartbeat() {
  const int64_t lease_ms = options_.pool.lease.count();
  const auto period = std::max(std::chrono::milliseconds(100), options_.pool.lease / 3);
  bool reported_error = false;
  for (;;) {
    std::set<std::string> held_before;
    {
      std::unique_lock<std::mutex> lock(mu_);
      pool_cv_.wait_for(lock, period, [&] { return stopping_ && pool_held_.empty(); });
      if (stopping_ && pool_held_.empty()) return;
      // Only jobs taken before the renewal are judged by it.
      for (const auto& [id, r] : pool_held_) held_before.insert(id);
    }
    // Only the jobs running here: a lease this replica holds on anything else (a claim whose
    // answer was lost, a job taken but not readable) runs out and the job is taken again.
    auto renewal = store_->RenewLeases(worker_id_, lease_ms, {held_before.begin(), held_before.end()});
    if (!renewal.ok()) {
      if (!reported_error) spdlog::error("pool: cannot renew leases: {} (retrying)", renewal.status().ToString());
      reported_error = true;
      continue;
    }
    reported_error = false;
    auto depth = store_->QueueDepth();
    if (depth.ok()) pool_queue_depth_ = *depth;
    auto queued = store_->QueuedWorkIds();
    // Inputs of ended jobs that their replica did not remove (it died right after the end).
    if (auto ended = store_->EndedWork(); ended.ok()) {
      for (const QueuedWork& w : *ended) {
        if (!w.stack_dir.empty()) RemoveFolder(store_->data_dir() / w.stack_dir);
        (void)store_->ForgetWork(w.job_id);
      }
    }
    // Partial uploads of replicas that died while receiving them (no job was created for them).
    if (auto swept = upload_sweeper_->Sweep(); !swept.ok()) {
      spdlog::debug("pool: uploads/ not swept: {}", swept.status().ToString());
    }
    std::lock_guard<std::mutex> lock(mu_);
    const std::set<std::string> held(renewal->held.begin(), renewal->held.end());
    for (const std::string& id : held_before) {
      auto it = pool_held_.find(id);
      if (it == pool_held_.end()) continue;  // ended meanwhile
      if (!held.count(id)) {
        // Our lease ran out (the database was away longer than it) and another worker took the
        // job: stop, and leave its outcome to that worker.
        pool_lost_.insert(id);
        it->second->cancel_requested = true;
        spdlog::warn("job {}: lease lost to another worker; stopping this attempt", id);
      }
    }
    for (const std::string& id : renewal->cancel_requested) {
      if (auto it = pool_held_.find(id); it != pool_held_.end()) it->second->cancel_requested = true;
    }
    if (queued.ok()) {
      // Hints of jobs another replica ended (or cancelled) go; their input is not ours to remove.
      const std::set<std::string> ids(queued->begin(), queued->end());
      for (auto it = pool_hints_.begin(); it != pool_hints_.end();) {
        it = ids.count(it->first) ? std::next(it) : pool_hints_.erase(it);
      }
    }
    pool_cv_.notify_all();
  }
}

void JobManager::EmitPool(const RecordPtr& r, const EventFill& fill) {
  r->AppendEvent(fill, [&](const v1::JobEvent& e) {
    // Watchers here are woken at once; the store (watchers elsewhere) follows within a batch. A
    // replica that dies meanwhile loses progress events only: its job runs again from the start.
    QueueWrite({std::nullopt, e});
    if (options_.on_event) options_.on_event(e);
  });
}

void JobManager::QueueWrite(PendingWrite w) {
  {
    std::lock_guard<std::mutex> lock(write_mu_);
    pending_writes_.push_back(std::move(w));
    ++writes_queued_;
  }
  write_cv_.notify_all();
}

void JobManager::FlushWrites() {
  std::unique_lock<std::mutex> lock(write_mu_);
  const uint64_t ticket = writes_queued_;
  write_cv_.wait(lock, [&] { return writes_done_ >= ticket; });
}

void JobManager::PoolWriter() {
  for (;;) {
    std::vector<PendingWrite> batch;
    {
      std::unique_lock<std::mutex> lock(write_mu_);
      write_cv_.wait(lock, [&] { return writer_stop_ || !pending_writes_.empty(); });
      if (pending_writes_.empty()) return;  // stopping, and everything is written
      batch.assign(std::make_move_iterator(pending_writes_.begin()), std::make_move_iterator(pending_writes_.end()));
      pending_writes_.clear();
    }
    // In the order queued: a run of events goes as one statement, a job row on its own.
    std::vector<v1::JobEvent> events;
    auto write_events = [&] {
      if (events.empty()) return;
      Status s = store_->AppendEvents(events);
      if (!s.ok()) spdlog::error("job {}: cannot persist {} event(s): {}", events.front().job_id(), events.size(), s.ToString());
      events.clear();
    };
    for (PendingWrite& w : batch) {
      if (!w.job) {
        events.push_back(std::move(w.event));
        continue;
      }
      write_events();
      Status s = store_->PutJob(*w.job);
      if (!s.ok()) spdlog::error("job {}: cannot persist: {}", w.job->job_id(), s.ToString());
    }
    write_events();
    {
      std::lock_guard<std::mutex> lock(write_mu_);
      writes_done_ += batch.size();
    }
    write_cv_.notify_all();
  }
}

void JobManager::KeepUploadsAlive() {
  // Not on the heartbeat's thread: that one waits for the database, and an upload in progress
  // must stay visibly alive also while the database is slow or away.
  const auto period = std::max(std::chrono::milliseconds(100), options_.pool.lease / 3);
  for (;;) {
    store_->live_work_folders().TouchAll();
    std::unique_lock<std::mutex> lock(mu_);
    pool_cv_.wait_for(lock, period, [&] { return stopping_ && pool_held_.empty(); });
    if (stopping_ && pool_held_.empty()) return;
  }
}

}  // namespace inspection
