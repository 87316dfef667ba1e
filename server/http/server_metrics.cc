// inspectd's Prometheus metrics from job events, gRPC calls and scrape-time state (server_metrics.h).
#include "server/http/server_metrics.h"

#include <algorithm>
#include <cctype>
#include <chrono>

namespace inspection {

namespace {

bool IsSet(const google::protobuf::Timestamp& t) { return t.seconds() != 0 || t.nanos() != 0; }

// The lower-case enum name without its prefix: JOB_KIND_SCAN -> scan.
std::string EnumLabel(const std::string& name, std::string_view prefix) {
  std::string s = name.compare(0, prefix.size(), prefix) == 0 ? name.substr(prefix.size()) : name;
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// Buckets in seconds. Jobs: a scan takes seconds to minutes, a calibration up to half an hour.
const std::vector<double> kJobDurationBuckets_s = {0.5, 1, 2, 5, 10, 20, 30, 60, 120, 300, 600, 1800, 3600};
// Queue wait: zero when the rig is idle, a job length per job ahead otherwise.
const std::vector<double> kQueueWaitBuckets_s = {0.01, 0.1, 0.5, 1, 5, 10, 30, 60, 120, 300, 900, 1800};
// SFF engine: tens of ms for a streaming finish, seconds for a replayed stack.
const std::vector<double> kEngineBuckets_s = {0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120};

const v1::RigState kRigStates[] = {v1::RIG_STATE_INITIALIZING, v1::RIG_STATE_READY, v1::RIG_STATE_BUSY,
                                   v1::RIG_STATE_ERROR};
const v1::VerificationState kVerificationStates[] = {v1::VERIFICATION_STATE_VERIFIED, v1::VERIFICATION_STATE_DUE,
                                                     v1::VERIFICATION_STATE_FAILED};

}  // namespace

std::string JobKindLabel(v1::JobKind kind) { return EnumLabel(v1::JobKind_Name(kind), "JOB_KIND_"); }
std::string JobStateLabel(v1::JobState state) { return EnumLabel(v1::JobState_Name(state), "JOB_STATE_"); }

std::string GrpcCodeName(int code) {
  static const char* kNames[] = {
      "OK",        "CANCELLED",      "UNKNOWN",           "INVALID_ARGUMENT",   "DEADLINE_EXCEEDED",
      "NOT_FOUND", "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
      "ABORTED",   "OUT_OF_RANGE",   "UNIMPLEMENTED",     "INTERNAL",           "UNAVAILABLE",
      "DATA_LOSS", "UNAUTHENTICATED"};
  if (code >= 0 && code < int(std::size(kNames))) return kNames[code];
  return "CODE_" + std::to_string(code);
}

ServerMetrics::ServerMetrics(std::string server_version, std::function<double()> now_s)
    : jobs_(
          registry_.AddCounter("inspectd_jobs_total", "Jobs that ended, by kind and final state.", {"kind", "state"})),
      job_duration_(registry_.AddHistogram("inspectd_job_duration_seconds",
                                           "Running time of jobs that ran (start to end), by kind.",
                                           kJobDurationBuckets_s, {"kind"})),
      queue_wait_(registry_.AddHistogram(
          "inspectd_job_queue_wait_seconds",
          "Time jobs waited in their queue before they started, by kind (observed at their end).", kQueueWaitBuckets_s,
          {"kind"})),
      frames_acquired_(
          registry_.AddCounter("inspectd_frames_acquired_total",
                               "Camera captures of scans (stack frames, HDR exposures, ADAPT iterations).")),
      last_scan_mean_grey_(registry_.AddGauge(
          "inspectd_last_scan_mean_grey", "Mean grey value (0..255) over the stack frames of the last finished scan.")),
      last_scan_saturated_(
          registry_.AddGauge("inspectd_last_scan_saturated_percent",
                             "Saturated pixels in percent, averaged over the stack frames of the last finished scan.")),
      last_scan_frames_(registry_.AddGauge("inspectd_last_scan_frames", "Stack frames of the last finished scan.")),
      engine_seconds_(registry_.AddHistogram(
          "inspectd_reconstruct_engine_seconds",
          "SFF engine time of succeeded jobs: scan = last frame to depth map, reconstruct = the whole job.",
          kEngineBuckets_s, {"kind"})),
      rig_state_(
          registry_.AddGauge("inspectd_rig_state", "1 for the rig's current state, 0 for the others.", {"state"})),
      rig_present_(registry_.AddGauge("inspectd_rig_present", "1 with a rig, 0 for inspectd --no-rig.")),
      queued_jobs_(registry_.AddGauge("inspectd_rig_queue_jobs", "Rig jobs waiting behind the running one.")),
      running_jobs_(registry_.AddGauge("inspectd_rig_job_running", "1 while a rig job (scan, calibration) runs.")),
      artifact_bytes_(registry_.AddCounter("inspectd_artifact_bytes_total",
                                           "Bytes of result artifacts published, by kind of job.", {"kind"})),
      disk_free_(registry_.AddGauge("inspectd_data_disk_free_bytes",
                                    "Bytes available to inspectd on the data directory's file system.")),
      grpc_calls_(registry_.AddCounter("inspectd_grpc_calls_total", "Finished gRPC calls by method and status code.",
                                       {"method", "code"})),
      build_info_(registry_.AddGauge("inspectd_build_info", "Always 1; the server version as a label.", {"version"})),
      // The reconstruct pool's backlog: replicas to add while it grows.
      queue_depth_(registry_.AddGauge("inspectd_queue_depth",
                                      "Reconstruct jobs waiting for a replica (the whole pool's on a shared database).")),
      verification_state_(registry_.AddGauge(
          "inspectd_verification_state",
          "1 for the rig's instrument verification state under the active calibration (verified, due, failed), "
          "0 for the others.",
          {"state"})),
      verification_value_(registry_.AddGauge(
          "inspectd_verification_characteristic",
          "ISO 25178-600 characteristic of the last full verification (N_M, z_FLT, l_z, W_R in um; alpha_z, "
          "alpha_x, alpha_y dimensionless).",
          {"characteristic"})),
      verification_u_(registry_.AddGauge("inspectd_verification_characteristic_expanded_uncertainty",
                                         "Expanded uncertainty U = 2u of inspectd_verification_characteristic.",
                                         {"characteristic"})),
      verification_age_(registry_.AddGauge("inspectd_verification_full_age_days",
                                           "Days since the last full verification under the active calibration.")) {
  build_info_.Set({std::move(server_version)}, 1);
  now_s_ = now_s ? std::move(now_s) : [] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  };
}

void ServerMetrics::ObserveWaitLocked(JobTrack& t, v1::JobKind kind, double elapsed_s) {
  if (t.wait_observed || t.queued_at_s < 0) return;
  t.wait_observed = true;
  // The job started elapsed_s ago (the event's elapsed time counts from its start).
  queue_wait_.Observe({JobKindLabel(kind)}, std::max(0.0, now_s_() - elapsed_s - t.queued_at_s));
}

void ServerMetrics::OnJobEvent(const v1::JobEvent& e) {
  if (e.has_frame() && e.phase() == v1::JOB_PHASE_ACQUIRING) frames_acquired_.Add({});
  if (!e.has_job()) {  // progress: only terminal events carry the ended job
    std::lock_guard<std::mutex> lock(mu_);
    JobTrack& t = jobs_seen_[e.job_id()];
    if (e.state() == v1::JOB_STATE_QUEUED && t.queued_at_s < 0) t.queued_at_s = now_s_();
    if (e.has_frame() && e.phase() == v1::JOB_PHASE_ACQUIRING && e.frame().stack_frame()) {
      t.mean_grey += e.frame().statistics().mean_grey();
      t.saturated_percent += e.frame().statistics().saturated_percent();
      ++t.frames;
    }
    return;
  }
  const v1::Job& job = e.job();
  const std::string kind = JobKindLabel(job.kind());
  jobs_.Add({kind, JobStateLabel(job.state())});
  const bool ran = IsSet(job.start_time());
  // elapsed_seconds of the terminal event is the steady-clock running time (start to end).
  const double duration_s = ran ? std::max(0.0, e.elapsed_seconds()) : 0.0;
  if (ran) job_duration_.Observe({kind}, duration_s);
  JobTrack t;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = jobs_seen_.find(job.job_id()); it != jobs_seen_.end()) {
      if (ran) ObserveWaitLocked(it->second, job.kind(), duration_s);
      t = it->second;
      jobs_seen_.erase(it);
    }
  }
  if (job.state() != v1::JOB_STATE_SUCCEEDED) return;
  if (job.kind() == v1::JOB_KIND_SCAN && t.frames > 0) {
    last_scan_mean_grey_.Set({}, t.mean_grey / t.frames);
    last_scan_saturated_.Set({}, t.saturated_percent / t.frames);
    last_scan_frames_.Set({}, t.frames);
  }
  if (job.result().has_depth()) {
    const double engine_s = job.kind() == v1::JOB_KIND_SCAN ? job.result().depth().engine_seconds() : duration_s;
    engine_seconds_.Observe({kind}, engine_s);
  }
  double bytes = 0;
  for (const v1::Artifact& a : job.result().artifacts()) bytes += double(a.size_bytes());
  artifact_bytes_.Add({kind}, bytes);
}

void ServerMetrics::OnGrpcCall(std::string_view method, int code) {
  if (!method.empty() && method.front() == '/') method.remove_prefix(1);
  grpc_calls_.Add({std::string(method), GrpcCodeName(code)});
}

std::string ServerMetrics::Render(const ScrapeState& state) {
  rig_present_.Set({}, state.rig_state ? 1 : 0);
  for (v1::RigState s : kRigStates) {
    // Without a rig no state series is shown at all, rather than four zeros that look like a
    // rig in no state.
    if (state.rig_state) rig_state_.Set({EnumLabel(v1::RigState_Name(s), "RIG_STATE_")}, *state.rig_state == s);
  }
  queued_jobs_.Set({}, state.queued_rig_jobs);
  running_jobs_.Set({}, state.rig_job_running ? 1 : 0);
  if (state.data_disk_free_bytes) disk_free_.Set({}, double(*state.data_disk_free_bytes));
  queue_depth_.Set({}, double(state.reconstruct_queue_depth));
  if (state.verification_state) {
    for (v1::VerificationState s : kVerificationStates) {
      verification_state_.Set({EnumLabel(v1::VerificationState_Name(s), "VERIFICATION_STATE_")},
                              *state.verification_state == s);
    }
  }
  {
    std::lock_guard<std::mutex> lock(render_mu_);
    for (const std::string& name : shown_characteristics_) {
      if (state.verified_characteristics.count(name) == 0) {
        verification_value_.Remove({name});
        verification_u_.Remove({name});
      }
    }
    shown_characteristics_.clear();
    for (const auto& [name, value_u] : state.verified_characteristics) {
      verification_value_.Set({name}, value_u.first);
      verification_u_.Set({name}, value_u.second);
      shown_characteristics_.insert(name);
    }
    if (state.full_verification_age_days) {
      verification_age_.Set({}, *state.full_verification_age_days);
    } else {
      verification_age_.Remove({});  // no full verification under the active calibration: no age
    }
  }
  return registry_.Render();
}

}  // namespace inspection
