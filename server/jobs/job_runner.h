// JobRunner: the one seam between scheduling and doing. The JobManager hands each job's work to
// a runner with a way to report progress and a cancel flag, and records what comes back. The
// server's runner (procedure_runner.h) drives the rig and the procedures; the JobManager tests
// use a fake.
#pragma once

#include <atomic>
#include <functional>
#include <string>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/jobs/job_work.h"

namespace inspection {

// Fills the job-specific fields of a progress event (phase, progress, frame, step, message).
// The manager has set job_id, sequence, time, state, elapsed_seconds and remaining_seconds = -1.
using EventFill = std::function<void(v1::JobEvent&)>;

// A running job as its runner sees it.
struct JobContext {
  std::string job_id;
  const std::atomic<bool>* cancel = nullptr;   // set by CancelJob or shutdown; check between frames
  std::function<void(const EventFill&)> emit;  // records and streams one progress event
};

class JobRunner {
 public:
  virtual ~JobRunner() = default;

  // Runs one job to its end: the result to record for SUCCEEDED, CANCELLED once the cancel flag
  // was seen, or the error the job FAILED with. Called on the manager's worker threads: rig jobs
  // (scan, calibrate) one at a time, reconstruct jobs beside them. Whatever the job leaves
  // behind (work folders, the rig's state) is settled before Run returns, because the terminal
  // event goes out right after.
  virtual StatusOr<v1::JobResult> Run(const JobWork& work, const JobContext& context) = 0;
};

}  // namespace inspection
