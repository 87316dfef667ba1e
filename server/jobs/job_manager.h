// JobManager: schedules, records and emits - every job of this server from submission to its
// terminal event, whatever the job does (that is the JobRunner's, see job_runner.h).
//  - Rig jobs (scan, calibrate) run one at a time from a bounded FIFO queue (RESOURCE_EXHAUSTED
//    when `rig_queue_capacity` jobs already wait). A calibration is refused with ABORTED while a
//    scan runs or waits, and the reverse, so the two never interleave.
//  - Reconstruct jobs do not need the rig and run on their own worker and queue.
//  - A request id makes a submission idempotent: the earlier job of that kind is returned, from
//    this run or an earlier one.
//  - Each job's events are persisted as they happen; a job that was queued or running when the
//    server stopped is marked FAILED (ABORTED) at the next start.
//  - Pool mode (options.pool.enabled: replicas sharing one PostgreSQL store and one data folder):
//    reconstruct jobs go through the store's work queue (DataStore::EnqueueWork) instead of this
//    process's queue. Any replica accepts an upload; any idle replica's worker takes the oldest
//    queued job under a lease its heartbeat renews, and ends it in the store only while it still
//    holds the lease (so a job's outcome is recorded once). A replica that dies (kill -9) stops
//    renewing: its lease runs out and another replica reruns the job from the stored input (the
//    upload's folder on the shared data folder and the stored ReconstructStart). Drain stops
//    taking work and waits for the running jobs; what is still running then is handed back
//    (queued again for another replica). Records of jobs running elsewhere follow the store.
//    A running pool job's progress events (and its RUNNING row) are written to the store by one
//    thread of their own, in order and in batches, so the engine never waits for a database round
//    trip; they are all written before the job's end (or its hand-back) is recorded, and its
//    queue row, record and first or last event are always written in one statement.
//    Uploads this replica is receiving are kept alive on the shared folder (touched every third
//    of the lease), and the heartbeat removes uploads/ folders of writers that died mid-upload
//    (server/storage/work_folders.h: no job refers to them, untouched for two leases).
// Thread-safe.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/storage/data_store.h"
#include "server/jobs/job_runner.h"
#include "server/jobs/job_work.h"

namespace inspection {

// One job's record (the Job message and its events) as seen by the workers and by any number
// of watchers. Thread-safe.
class JobRecord {
 public:
  JobRecord(v1::Job job, std::vector<v1::JobEvent> events = {});

  const std::string& job_id() const { return job_id_; }
  v1::JobKind kind() const { return kind_; }
  const std::string& request_id() const { return request_id_; }

  v1::Job Snapshot() const;
  bool terminal() const;
  // Copies events [from, ...) into *out. Waits up to `timeout` when there are none yet and the
  // job has not ended. Returns true when the job has ended and *out holds the last events.
  // A record that follows the store (a pool job running on another replica) looks there for new
  // events at least every poll interval while it waits.
  bool EventsSince(size_t from, std::chrono::milliseconds timeout, std::vector<v1::JobEvent>* out);

  std::atomic<bool> cancel_requested{false};

  // Record keeping, for the JobManager.
  void SetQueuePosition(int position);
  v1::Job MarkRunning();
  // Ends the job - SUCCEEDED with the result, CANCELLED or FAILED with the status's code and
  // message - and appends its terminal event (`fill`, then the ended job) in the same step, so a
  // watcher never sees the end without the last event. Hands both to `persist`, then wakes the
  // watchers. False (and nothing changes) when the job had ended already.
  using Persist = std::function<void(const v1::Job& ended, const v1::JobEvent& terminal_event)>;
  bool End(const StatusOr<v1::JobResult>& outcome, const EventFill& fill, const Persist& persist);
  // Appends the next event (id, sequence, time, state, elapsed time, then `fill`), hands it to
  // `persist`, then wakes the watchers; returns it.
  v1::JobEvent AppendEvent(const EventFill& fill, const std::function<void(const v1::JobEvent&)>& persist);

  // Pool mode. Follow: the job runs elsewhere; EventsSince and Refresh read `store` (every `poll`).
  void Follow(DataStore* store, std::chrono::milliseconds poll);
  void StopFollowing();
  // Reads the stored job and its events newer than this record's; false when the store does not
  // answer (the record stays as it was).
  bool Refresh();
  // The store says this job changed (another replica wrote its events): a waiting watcher reads
  // them now rather than at its next poll.
  void Poke();
  // Replaces the record with the stored one (a worker taking the job: others may have run it).
  void Reload(v1::Job job, std::vector<v1::JobEvent> events);

 private:
  const std::string job_id_;
  const v1::JobKind kind_;
  const std::string request_id_;

  v1::JobEvent NextEventLocked(const EventFill& fill) const;  // caller holds mu_

  mutable std::mutex mu_;               // guards the members below
  mutable std::condition_variable cv_;  // signalled on every event
  v1::Job job_;
  std::vector<v1::JobEvent> events_;
  std::chrono::steady_clock::time_point started_;
  DataStore* follow_store_ = nullptr;  // set: the job runs elsewhere
  std::chrono::milliseconds follow_poll_{250};
  bool poked_ = false;  // Poke() since the last read of the store
};

// A reconstruct pool's settings (JobManager pool mode, above).
struct PoolOptions {
  bool enabled = false;   // the server sets it when its store is shared (PostgreSQL)
  std::string worker_id;  // this replica's name on its leases; empty = host name, pid and a random suffix
  // A worker that has not renewed its lease for this long is taken for dead; renewed every third.
  std::chrono::milliseconds lease{30000};
  std::chrono::milliseconds poll{250};  // idle workers look for work, followers for events, this often
  int workers = 1;                      // reconstructions run at once by this replica
  int64_t queue_capacity = 1000;        // queued jobs of the whole pool; beyond: RESOURCE_EXHAUSTED
  // Rebuilds a job's work from its stored input (server/api: the stored ReconstructStart and the
  // stack folder `stack_dir`, empty for a stored scan) when this replica did not accept the job.
  std::function<StatusOr<JobWork>(const QueuedWork& work, const std::filesystem::path& stack_dir)> restore;
};

struct JobManagerOptions {
  int rig_queue_capacity = 4;  // jobs waiting behind the running rig job
  int reconstruct_queue_capacity = 8;
  // Sees every event once it is persisted (metrics, dashboard). Called on the emitting thread,
  // sometimes under the manager's lock: it must be quick and must not call the manager.
  std::function<void(const v1::JobEvent&)> on_event;
  // True when the data disk is (nearly) full now. Sampled at every event of a running job and
  // when it ends: a job that failed writing (INTERNAL, UNKNOWN, DATA_LOSS, or "cannot write")
  // while the disk was full ends RESOURCE_EXHAUSTED "data disk full" instead. The work folders
  // it wrote are gone by then (the runner removes them before returning), so the free space
  // seen after the failure alone would not tell. Empty = never.
  std::function<bool()> disk_full;
  PoolOptions pool;
};

class JobManager {
 public:
  // `runner` does the work of every job; it must outlive the manager's Shutdown.
  JobManager(const JobManagerOptions& options, DataStore* store, JobRunner* runner);
  ~JobManager();

  // Marks jobs left unfinished by a previous run, then starts the workers.
  Status Start();
  // Ends queued jobs (FAILED, ABORTED), asks running ones to cancel and joins the workers. Pool
  // mode: queued jobs stay queued in the store and running ones are handed back.
  void Shutdown();
  // Pool mode: takes no more work (new uploads get UNAVAILABLE), waits up to `timeout` for the
  // jobs running here to end, then hands back the rest. Shutdown follows. Returns the number of
  // jobs handed back.
  int Drain(std::chrono::milliseconds timeout);
  bool pool() const { return options_.pool.enabled; }
  const std::string& worker_id() const { return worker_id_; }
  // Reconstruct jobs waiting to run: the pool's (sampled by the heartbeat), or this process's queue.
  int64_t reconstruct_queue_depth() const;

  // Builds the work of a new job (`prepare`: request mapping and rig checks, called without the
  // manager's lock) and queues it. With a request id that an earlier job of this kind carries,
  // returns that job and does not call `prepare`. Errors of `prepare` come back unchanged; then,
  // and for UNAVAILABLE (shutting down), ABORTED and RESOURCE_EXHAUSTED (see above), no job is
  // created. `owner` is the identity that started the job (recorded in Job.owner).
  using Prepare = std::function<StatusOr<JobWork>()>;
  StatusOr<std::shared_ptr<JobRecord>> Submit(v1::JobKind kind, const std::string& request_id, const std::string& label,
                                              const Prepare& prepare, const std::string& owner = "");

  // A live record, or one rebuilt from the store (events included) for a job of an earlier run.
  StatusOr<std::shared_ptr<JobRecord>> Find(const std::string& job_id);
  // The record of a job of this run still held in memory; null otherwise.
  std::shared_ptr<JobRecord> FindLive(const std::string& job_id);
  // Cancels a queued job at once; a running job is asked to stop (its runner sees the flag).
  StatusOr<v1::Job> Cancel(const std::string& job_id);

  // Data lifecycle. Marks a finished job as being deleted: FAILED_PRECONDITION while it is
  // queued or running or while a queued or running reconstruction reads its scan; meanwhile a
  // reconstruction of that scan is refused (NOT_FOUND). EndDeletion lifts the mark.
  Status BeginDeletion(const std::string& job_id);
  void EndDeletion(const std::string& job_id);
  // Drops a finished job's record from memory so the store's copy is served (after it changed).
  void Forget(const std::string& job_id);

  int queued_rig_jobs() const;
  int rig_queue_capacity() const { return options_.rig_queue_capacity; }
  std::string running_rig_job() const;

 private:
  using RecordPtr = std::shared_ptr<JobRecord>;
  struct QueuedJob {
    RecordPtr record;
    JobWork work;
  };
  using Queue = std::deque<QueuedJob>;

  static bool IsRigJob(v1::JobKind kind) { return kind != v1::JOB_KIND_RECONSTRUCT; }
  Queue& QueueFor(v1::JobKind kind) { return IsRigJob(kind) ? rig_queue_ : reconstruct_queue_; }
  // The earlier job with this request id: live ones first (they may not have ended), then the
  // store. Null when there is none. Caller holds mu_.
  StatusOr<RecordPtr> FindDuplicate(v1::JobKind kind, const std::string& request_id);
  // ABORTED (scan/calibration interleave) or RESOURCE_EXHAUSTED (queue full). Caller holds mu_.
  Status Admit(v1::JobKind kind) const;
  void Emit(const RecordPtr& r, const EventFill& fill);
  void Finish(const RecordPtr& r, const StatusOr<v1::JobResult>& outcome);
  // Blocks until `queue` has a job (returned, removed from the queue) or the manager stops
  // (nullopt). With `rig`, the job becomes the running rig job.
  std::optional<QueuedJob> WaitForWork(Queue& queue, bool rig);
  // Runs the jobs of one queue, one at a time, until the manager stops.
  void Worker(Queue* queue, bool rig);

  // Pool mode (see the top of this file).
  StatusOr<RecordPtr> SubmitToPool(v1::Job job, JobWork work, const std::string& description);
  void PoolWorker();
  void RunPoolJob(const QueuedWork& claimed);
  void PoolHeartbeat();
  void KeepUploadsAlive();  // touches this process's upload folders until the manager stops
  // The pool's store writer (see the top of this file): QueueWrite hands it a record, Flush waits
  // until everything handed to it so far is written (or failed, logged).
  struct PendingWrite {
    std::optional<v1::Job> job;  // set: PutJob; else AppendEvent(event)
    v1::JobEvent event;
  };
  void QueueWrite(PendingWrite w);
  void FlushWrites();
  void PoolWriter();
  void EmitPool(const RecordPtr& r, const EventFill& fill);
  StatusOr<v1::Job> CancelPoolJob(const RecordPtr& r);
  RecordPtr FollowerFor(v1::Job job, std::vector<v1::JobEvent> events);

  const JobManagerOptions options_;
  DataStore* const store_;
  JobRunner* const runner_;

  mutable std::mutex mu_;            // guards the members below
  std::condition_variable work_cv_;  // a job was queued, or the manager stops
  bool stopping_ = false;
  std::map<std::string, RecordPtr> live_;  // jobs of this run (finished ones trimmed)
  Queue rig_queue_;
  Queue reconstruct_queue_;
  RecordPtr running_rig_;
  std::map<std::string, std::string> scan_readers_;  // unfinished reconstruct job -> scan it reads
  std::set<std::string> deleting_;                   // jobs (and so scans) being deleted

  std::thread rig_thread_, reconstruct_thread_;

  // Pool mode; guarded by mu_ unless atomic.
  std::string worker_id_;
  bool draining_ = false;
  uint64_t pool_submissions_ = 0;  // wakes idle workers at a local upload or another replica's (Change::kWorkQueued)
  std::map<std::string, JobWork> pool_hints_;              // accepted here, frames decoded, not yet taken here
  std::map<std::string, std::weak_ptr<JobRecord>> pool_followers_;  // records streamed to clients here
  std::map<std::string, RecordPtr> pool_held_;             // running here under our lease
  std::set<std::string> pool_lost_;                        // held, but another worker took the lease over
  std::set<std::string> pool_hand_back_;                   // held, to be handed back when they stop
  std::condition_variable pool_cv_;                        // a held job ended, or the manager stops
  std::atomic<int64_t> pool_queue_depth_{0};
  std::vector<std::thread> pool_threads_;
  std::thread heartbeat_thread_;
  std::thread upload_keeper_thread_;
  std::mutex write_mu_;                // guards the members below (never held with mu_)
  std::condition_variable write_cv_;  // a write was queued or done, or the writer stops
  std::deque<PendingWrite> pending_writes_;
  uint64_t writes_queued_ = 0, writes_done_ = 0;
  bool writer_stop_ = false;
  std::thread writer_thread_;
  std::unique_ptr<OrphanUploadSweeper> upload_sweeper_;  // used by the heartbeat thread only
};

}  // namespace inspection
