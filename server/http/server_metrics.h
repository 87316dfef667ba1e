// ServerMetrics: what inspectd tells Prometheus. Job counts, durations and frame figures come
// from the JobManager's event stream (OnJobEvent), gRPC calls from the server interceptor
// (OnGrpcCall); rig state, queue and disk space are read at scrape time (ScrapeState).
// Metric names (all prefixed inspectd_) are listed in docs/operations.md. Thread-safe.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <string_view>

#include "inspection/v1/inspection.pb.h"
#include "server/http/metrics_registry.h"

namespace inspection {

// Values that are read when Prometheus scrapes, not counted from events.
struct ScrapeState {
  std::optional<v1::RigState> rig_state;  // nullopt: no rig (--no-rig)
  int queued_rig_jobs = 0;
  bool rig_job_running = false;
  std::optional<uint64_t> data_disk_free_bytes;  // nullopt when the data dir cannot be queried
  // Reconstruct pool: jobs waiting for a replica (the whole pool's on a shared store), for an
  // autoscaler (inspectd_queue_depth).
  int64_t reconstruct_queue_depth = 0;
  // Instrument verification under the active calibration (server/jobs/rig_verification.h):
  // nullopt without a rig or when the records could not be read.
  std::optional<v1::VerificationState> verification_state;
  // The last full verification's characteristics by name ("alpha_z", ...): value and U = 2u.
  std::map<std::string, std::pair<double, double>> verified_characteristics;
  std::optional<double> full_verification_age_days;
};

class ServerMetrics {
 public:
  // `now_s`: a monotonic clock in seconds (default: steady_clock). Job timestamps in the API
  // have whole seconds only, so queue waits are timed here as the events arrive; tests inject
  // a clock.
  explicit ServerMetrics(std::string server_version, std::function<double()> now_s = {});

  // Every job event as the JobManager records it; terminal events (with the ended job) count
  // the job. Must not block: called on job threads.
  void OnJobEvent(const v1::JobEvent& event);
  // One finished gRPC call: `method` as "/package.Service/Method", `code` a grpc::StatusCode.
  void OnGrpcCall(std::string_view method, int code);

  // The exposition text with `state` applied.
  std::string Render(const ScrapeState& state);

  MetricsRegistry& registry() { return registry_; }

 private:
  MetricsRegistry registry_;
  Counter jobs_;
  Histogram job_duration_;
  Histogram queue_wait_;
  Counter frames_acquired_;
  Gauge last_scan_mean_grey_;
  Gauge last_scan_saturated_;
  Gauge last_scan_frames_;
  Histogram engine_seconds_;
  Gauge rig_state_;
  Gauge rig_present_;
  Gauge queued_jobs_;
  Gauge running_jobs_;
  Counter artifact_bytes_;
  Gauge disk_free_;
  Counter grpc_calls_;
  Gauge build_info_;
  Gauge queue_depth_;  // inspectd_queue_depth
  Gauge verification_state_;
  Gauge verification_value_;
  Gauge verification_u_;
  Gauge verification_age_;

  // Per unfinished job: when it was queued and whether its wait is counted; for scans, sums
  // over the stack frames that become the last-scan gauges at its end.
  struct JobTrack {
    double queued_at_s = -1;  // now_s() at the QUEUED event; < 0 when not seen (e.g. a restart)
    bool wait_observed = false;
    double mean_grey = 0, saturated_percent = 0;
    int frames = 0;
  };
  // The wait of a job that has been running for `elapsed_s`, once. Caller holds mu_.
  void ObserveWaitLocked(JobTrack& t, v1::JobKind kind, double elapsed_s);

  std::function<double()> now_s_;
  std::mutex render_mu_;  // guards shown_characteristics_ (concurrent scrapes)
  // The characteristics whose series the last scrape showed: dropped when the active
  // calibration has no full verification any more (a recalibration), not left at old values.
  std::set<std::string> shown_characteristics_;
  std::mutex mu_;  // guards jobs_seen_
  std::map<std::string, JobTrack> jobs_seen_;
};

// "scan", "calibrate", "reconstruct" (the label values of kind); "succeeded", "failed",
// "cancelled" (state).
std::string JobKindLabel(v1::JobKind kind);
std::string JobStateLabel(v1::JobState state);
// "OK", "FAILED_PRECONDITION", ... for a grpc::StatusCode.
std::string GrpcCodeName(int code);

}  // namespace inspection
