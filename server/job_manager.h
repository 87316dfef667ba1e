// JobManager: every job of this server, from submission to its terminal event.
//  - Rig jobs (scan, calibrate) run one at a time on the rig worker, from a bounded FIFO queue
//    (RESOURCE_EXHAUSTED when `rig_queue_capacity` jobs already wait). A calibration is refused
//    with ABORTED while a scan runs or waits, and the reverse, so the two never interleave.
//  - Reconstruct jobs do not need the rig and run on their own worker.
//  - Each job's events are persisted as they happen; a job that was queued or running when the
//    server stopped is marked FAILED (ABORTED) at the next start.
// Thread-safe.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/data_store.h"
#include "server/procedures/scan_procedure.h"
#include "server/rig_controller.h"

namespace inspection {

// One job as seen by the workers and by any number of watchers.
class JobRecord {
 public:
  explicit JobRecord(v1::Job job) : job_(std::move(job)) {}

  v1::Job Snapshot() const;
  bool terminal() const;
  // Copies events [from, ...) into *out. Waits up to `timeout` when there are none yet and the
  // job has not ended. Returns true when the job has ended and *out holds the last events.
  bool EventsSince(size_t from, std::chrono::milliseconds timeout, std::vector<v1::JobEvent>* out) const;

  std::atomic<bool> cancel_requested{false};

 private:
  friend class JobManager;
  mutable std::mutex mu_;
  mutable std::condition_variable cv_;
  v1::Job job_;
  std::vector<v1::JobEvent> events_;
  std::chrono::steady_clock::time_point started_;
  // What to run.
  ScanPlan scan_plan_;
  std::vector<int> extra_exports_;
  v1::CalibrateRequest calibrate_;
  std::filesystem::path stack_dir_;   // reconstruct input
  bool owns_stack_dir_ = false;        // an upload, removed when the job ends
  SffOptions sff_;
};

struct JobManagerOptions {
  int rig_queue_capacity = 4;          // jobs waiting behind the running rig job
  int reconstruct_queue_capacity = 8;
};

// Hook for calibration jobs (implemented with server/procedures/calibration_procedure).
// Given the rig (held exclusively), the request, a progress reporter and the cancel flag, it
// returns the new calibration's record (already stored) or an error.
struct CalibrationContext {
  Rig* rig;
  const v1::CalibrateRequest* request;
  std::function<void(const std::string& step, double progress, const std::string& message)> progress;
  const std::atomic<bool>* cancel;
  std::string job_id;
};
using CalibrationRunner = std::function<StatusOr<v1::Calibration>(const CalibrationContext&)>;

class JobManager {
 public:
  JobManager(const JobManagerOptions& options, DataStore* store, RigController* rig);
  ~JobManager();

  // Marks jobs left unfinished by a previous run, then starts the workers.
  Status Start();
  // Cancels queued and running jobs and joins the workers.
  void Shutdown();

  void SetCalibrationRunner(CalibrationRunner runner) { calibration_runner_ = std::move(runner); }
  // Source of the active calibration bundle for scans in calibrated illumination modes (null
  // or returning null = no calibration: only STD scans).
  void SetActiveCalibrationProvider(std::function<std::shared_ptr<const CalibrationBundle>()> provider) {
    active_calibration_ = std::move(provider);
  }

  StatusOr<std::shared_ptr<JobRecord>> SubmitScan(const v1::ScanRequest& request);
  StatusOr<std::shared_ptr<JobRecord>> SubmitCalibrate(const v1::CalibrateRequest& request);
  // stack_dir must hold a stack already validated by the caller. With owns_stack_dir the folder
  // (an upload) is removed when the job ends.
  StatusOr<std::shared_ptr<JobRecord>> SubmitReconstruct(const v1::ReconstructStart& start,
                                                         const std::filesystem::path& stack_dir, bool owns_stack_dir);

  // A live record, or one rebuilt from the store (events included) for a job of an earlier run.
  StatusOr<std::shared_ptr<JobRecord>> Find(const std::string& job_id);
  StatusOr<v1::Job> Cancel(const std::string& job_id);

  int queued_rig_jobs() const;
  int rig_queue_capacity() const { return options_.rig_queue_capacity; }
  std::string running_rig_job() const;
  std::string active_calibration_id() const;

  // For reconstruct requests naming a stored scan.
  std::filesystem::path ScanDir(const std::string& scan_id) const;

 private:
  using RecordPtr = std::shared_ptr<JobRecord>;

  StatusOr<RecordPtr> Dedupe(v1::JobKind kind, const std::string& request_id);
  RecordPtr NewRecord(v1::JobKind kind, const std::string& request_id, const std::string& label);
  void Emit(const RecordPtr& r, const std::function<void(v1::JobEvent&)>& fill);
  void Finish(const RecordPtr& r, const Status& status);
  // Blocks until `queue` has a job (returned, removed from the queue) or the manager stops (nullptr).
  RecordPtr WaitForWork(std::deque<RecordPtr>& queue, bool mark_running_rig);
  void RigWorker();
  void ReconstructWorker();
  // Rig jobs return their final status; the rig worker finishes the job after releasing the rig.
  Status RunScan(const RecordPtr& r);
  Status RunCalibrate(const RecordPtr& r);
  void RunReconstruct(const RecordPtr& r);

  JobManagerOptions options_;
  DataStore* store_;
  RigController* rig_;
  CalibrationRunner calibration_runner_;
  std::function<std::shared_ptr<const CalibrationBundle>()> active_calibration_;

  mutable std::mutex mu_;
  std::condition_variable work_cv_;
  bool stopping_ = false;
  std::map<std::string, RecordPtr> live_;  // jobs of this run
  std::deque<RecordPtr> rig_queue_;
  std::deque<RecordPtr> reconstruct_queue_;
  RecordPtr running_rig_;
  std::thread rig_thread_, reconstruct_thread_;
};

}  // namespace inspection
