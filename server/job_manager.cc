#include "server/job_manager.h"

#include <google/protobuf/util/time_util.h>
#include <spdlog/spdlog.h>

#include "core/depth_metrics.h"
#include "core/texture_pattern.h"
#include "server/artifact_files.h"
#include "server/procedures/reconstruct_procedure.h"

namespace inspection {
namespace fs = std::filesystem;
using google::protobuf::util::TimeUtil;
using Clock = std::chrono::steady_clock;

namespace {

constexpr size_t kMaxFinishedInMemory = 256;

bool IsTerminal(v1::JobState s) {
  return s == v1::JOB_STATE_SUCCEEDED || s == v1::JOB_STATE_FAILED || s == v1::JOB_STATE_CANCELLED;
}

StatusOr<FocusMeasure> ToFocusMeasure(v1::FocusMeasure m) {
  switch (m) {
    case v1::FOCUS_MEASURE_UNSPECIFIED:
    case v1::FOCUS_MEASURE_TENENGRAD: return FocusMeasure::kTenengrad;
    case v1::FOCUS_MEASURE_MODIFIED_LAPLACIAN: return FocusMeasure::kModifiedLaplacian;
    case v1::FOCUS_MEASURE_SUM_MODIFIED_LAPLACIAN: return FocusMeasure::kSumModifiedLaplacian;
    case v1::FOCUS_MEASURE_GREY_LEVEL_VARIANCE: return FocusMeasure::kGreyLevelVariance;
    case v1::FOCUS_MEASURE_HELMLI_MEAN: return FocusMeasure::kHelmliMean;
    case v1::FOCUS_MEASURE_CHEBYSHEV_MOMENTS: return FocusMeasure::kChebyshevMoments;
    case v1::FOCUS_MEASURE_GREY_LEVEL_LOCAL_VARIANCE: return FocusMeasure::kGreyLevelLocalVariance;
    default: return Status::InvalidArgument("focus_measure " + std::to_string(int(m)) + " is unknown");
  }
}

// Request options -> engine options, with errors naming the request field.
StatusOr<SffOptions> ToSffOptions(const v1::ReconstructionOptions& o, const std::string& field,
                                  std::vector<int>* extras) {
  SffOptions s;
  auto fm = ToFocusMeasure(o.focus_measure());
  if (!fm.ok()) return fm.status().WithContext(field);
  s.focus_measure = *fm;
  if (o.window_px() != 0) s.window_px = o.window_px();
  switch (o.interpolation()) {
    case v1::DEPTH_INTERPOLATION_UNSPECIFIED:
    case v1::DEPTH_INTERPOLATION_GAUSSIAN: s.interpolation = DepthInterpolation::kGaussian; break;
    case v1::DEPTH_INTERPOLATION_MAXIMUM: s.interpolation = DepthInterpolation::kMaximum; break;
    case v1::DEPTH_INTERPOLATION_LINE_FIT: s.interpolation = DepthInterpolation::kLineFit; break;
    default: return Status::InvalidArgument(field + ".interpolation " + std::to_string(int(o.interpolation())) + " is unknown");
  }
  if (o.has_min_confidence()) s.min_confidence = o.min_confidence();
  INSPECT_RETURN_IF_ERROR(s.Validate().WithContext(field));
  for (int i = 0; i < o.extra_exports_size(); ++i) {
    const int k = o.extra_exports(i);
    if (k != v1::ARTIFACT_KIND_DEPTH_PNG16 && k != v1::ARTIFACT_KIND_DEPTH_PLY && k != v1::ARTIFACT_KIND_DEPTH_X3P) {
      return Status::InvalidArgument(field + ".extra_exports[" + std::to_string(i) +
                                     "] must be ARTIFACT_KIND_DEPTH_PNG16, _PLY or _X3P");
    }
    extras->push_back(k);
  }
  return s;
}

v1::ArtifactKind ToArtifactKind(DepthExportKind k) {
  switch (k) {
    case DepthExportKind::kDepthTiff: return v1::ARTIFACT_KIND_DEPTH_TIFF;
    case DepthExportKind::kConfidenceTiff: return v1::ARTIFACT_KIND_CONFIDENCE_TIFF;
    case DepthExportKind::kAllInFocusPng: return v1::ARTIFACT_KIND_ALL_IN_FOCUS_PNG;
    case DepthExportKind::kDepthPreviewPng: return v1::ARTIFACT_KIND_DEPTH_PREVIEW_PNG;
    case DepthExportKind::kDepthPng16: return v1::ARTIFACT_KIND_DEPTH_PNG16;
    case DepthExportKind::kDepthPly: return v1::ARTIFACT_KIND_DEPTH_PLY;
    case DepthExportKind::kDepthX3p: return v1::ARTIFACT_KIND_DEPTH_X3P;
    case DepthExportKind::kGroundTruthTiff: return v1::ARTIFACT_KIND_GROUND_TRUTH_TIFF;
  }
  return v1::ARTIFACT_KIND_UNSPECIFIED;
}

std::vector<DepthExportKind> ToExportKinds(const std::vector<int>& extras) {
  std::vector<DepthExportKind> out;
  for (int k : extras) {
    if (k == v1::ARTIFACT_KIND_DEPTH_PNG16) out.push_back(DepthExportKind::kDepthPng16);
    if (k == v1::ARTIFACT_KIND_DEPTH_PLY) out.push_back(DepthExportKind::kDepthPly);
    if (k == v1::ARTIFACT_KIND_DEPTH_X3P) out.push_back(DepthExportKind::kDepthX3p);
  }
  return out;
}

const char* MediaType(v1::ArtifactKind k) {
  switch (k) {
    case v1::ARTIFACT_KIND_DEPTH_TIFF:
    case v1::ARTIFACT_KIND_CONFIDENCE_TIFF:
    case v1::ARTIFACT_KIND_GROUND_TRUTH_TIFF: return "image/tiff";
    case v1::ARTIFACT_KIND_ALL_IN_FOCUS_PNG:
    case v1::ARTIFACT_KIND_DEPTH_PREVIEW_PNG:
    case v1::ARTIFACT_KIND_DEPTH_PNG16: return "image/png";
    case v1::ARTIFACT_KIND_STACK_ZIP: return "application/zip";
    case v1::ARTIFACT_KIND_DEPTH_PLY: return "application/x-ply";
    case v1::ARTIFACT_KIND_DEPTH_X3P: return "application/x-iso25178-x3p";
    default: return "application/octet-stream";
  }
}

// Summary of a depth result; compares with ground truth when given. The focus window's half
// width at the image border is left out of the comparison (the window sees the border there).
v1::DepthSummary Summarise(const DepthResult& r, double pixel_size_um, const cv::Mat& truth, int window_px) {
  v1::DepthSummary d;
  d.set_width(r.depth_um.cols);
  d.set_height(r.depth_um.rows);
  d.set_pixel_size_um(pixel_size_um);
  d.set_valid_percent(100.0 * r.valid_fraction);
  auto [lo, hi] = FiniteRange(r.depth_um);
  d.set_z_min_um(lo);
  d.set_z_max_um(hi);
  d.set_frame_count(r.frame_count);
  if (!truth.empty() && truth.size() == r.depth_um.size()) {
    DepthErrorStats e = CompareDepth(r.depth_um, truth, 1e9, window_px / 2);
    d.set_has_ground_truth(true);
    d.set_rmse_um(e.rmse_um);
    d.set_mean_abs_error_um(e.mean_abs_error_um);
  }
  return d;
}

// A per-frame progress event: frame i of n with its statistics; the frames make up 90 % of a
// job, the remaining time is extrapolated from the frame rate so far.
void FillFrameEvent(v1::JobPhase phase, int index, int count, double z_um, double exposure_us,
                    const FrameStatistics& st, v1::JobEvent* e) {
  e->set_phase(phase);
  v1::FrameProgress* fp = e->mutable_frame();
  fp->set_frame_index(index);
  fp->set_frame_count(count);
  fp->set_z_um(z_um);
  fp->set_exposure_us(exposure_us);
  fp->set_acquisition_index(index);  // scans with extra captures overwrite both
  fp->set_stack_frame(true);
  fp->mutable_statistics()->set_mean_grey(st.mean_grey);
  fp->mutable_statistics()->set_stddev_grey(st.stddev_grey);
  fp->mutable_statistics()->set_saturated_percent(st.saturated_percent);
  fp->mutable_statistics()->set_underexposed_percent(st.underexposed_percent);
  const double done = index + 1;
  e->set_progress(0.9 * done / count);
  e->set_remaining_seconds(e->elapsed_seconds() / done * (count - done));
}

void RemoveAll(const fs::path& p) {
  std::error_code ec;
  if (!p.empty()) fs::remove_all(p, ec);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// JobRecord

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
  return IsTerminal(job_.state());
}

// ---------------------------------------------------------------------------------------------
// JobManager

JobManager::JobManager(const JobManagerOptions& options, DataStore* store, RigController* rig)
    : options_(options), store_(store), rig_(rig) {}

JobManager::~JobManager() { Shutdown(); }

Status JobManager::Start() {
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::Job> unfinished, store_->UnfinishedJobs());
  for (v1::Job& job : unfinished) {
    const bool was_running = job.state() == v1::JOB_STATE_RUNNING;
    auto events = store_->Events(job.job_id());
    job.set_state(v1::JOB_STATE_FAILED);
    job.set_error_code(int(StatusCode::kAborted));
    job.set_error_message(was_running ? "the server stopped while the job was running; its partial results were discarded"
                                      : "the server stopped before the job ran; submit it again");
    *job.mutable_end_time() = TimeUtil::GetCurrentTime();
    job.set_queue_position(0);
    INSPECT_RETURN_IF_ERROR(store_->PutJob(job));
    v1::JobEvent e;
    e.set_job_id(job.job_id());
    e.set_sequence(events.ok() ? events->size() + 1 : 1);
    *e.mutable_time() = job.end_time();
    e.set_state(job.state());
    e.set_phase(v1::JOB_PHASE_DONE);
    e.set_message(job.error_message());
    *e.mutable_job() = job;
    INSPECT_RETURN_IF_ERROR(store_->AppendEvent(e));
    spdlog::warn("job {} marked failed: {}", job.job_id(), job.error_message());
  }
  rig_thread_ = std::thread([this] { RigWorker(); });
  reconstruct_thread_ = std::thread([this] { ReconstructWorker(); });
  return Status::Ok();
}

void JobManager::Shutdown() {
  std::vector<RecordPtr> queued;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) return;
    stopping_ = true;
    for (auto& [id, r] : live_) r->cancel_requested = true;
    queued.assign(rig_queue_.begin(), rig_queue_.end());
    queued.insert(queued.end(), reconstruct_queue_.begin(), reconstruct_queue_.end());
    rig_queue_.clear();
    reconstruct_queue_.clear();
  }
  work_cv_.notify_all();
  for (const RecordPtr& r : queued) Finish(r, Status::Aborted("the server shut down before the job ran"));
  if (rig_thread_.joinable()) rig_thread_.join();
  if (reconstruct_thread_.joinable()) reconstruct_thread_.join();
}

JobManager::RecordPtr JobManager::NewRecord(v1::JobKind kind, const std::string& request_id, const std::string& label) {
  static const std::map<v1::JobKind, std::string> prefix = {
      {v1::JOB_KIND_SCAN, "scan"}, {v1::JOB_KIND_CALIBRATE, "cal"}, {v1::JOB_KIND_RECONSTRUCT, "rec"}};
  v1::Job job;
  job.set_job_id(NewId(prefix.at(kind)));
  job.set_kind(kind);
  job.set_state(v1::JOB_STATE_QUEUED);
  job.set_request_id(request_id);
  job.set_label(label);
  *job.mutable_create_time() = TimeUtil::GetCurrentTime();
  return std::make_shared<JobRecord>(std::move(job));
}

StatusOr<JobManager::RecordPtr> JobManager::Dedupe(v1::JobKind kind, const std::string& request_id) {
  // Caller holds mu_. Live jobs first (they may not be terminal yet), then earlier runs.
  for (const auto& [id, r] : live_) {
    if (r->job_.kind() == kind && r->job_.request_id() == request_id) return r;
  }
  if (auto id = store_->FindJobByRequestId(kind, request_id)) {
    auto job = store_->GetJob(*id);
    if (!job.ok()) return job.status();
    auto r = std::make_shared<JobRecord>(*job);
    auto events = store_->Events(*id);
    if (events.ok()) r->events_ = std::move(*events);
    return r;
  }
  return Status::NotFound("");
}

StatusOr<std::shared_ptr<JobRecord>> JobManager::SubmitScan(const v1::ScanRequest& req) {
  if (!req.request_id().empty()) {
    std::lock_guard<std::mutex> lock(mu_);
    auto existing = Dedupe(v1::JOB_KIND_SCAN, req.request_id());
    if (existing.ok()) return *existing;
  }
  if (!rig_->usable()) {
    return Status::FailedPrecondition("rig is not ready (state " + v1::RigState_Name(rig_->state()) + ": " +
                                      rig_->state_detail() + "); fix the cause and call ResetRig");
  }
  std::shared_ptr<const CalibrationBundle> bundle = active_calibration_ ? active_calibration_() : nullptr;
  IlluminationMode mode = IlluminationMode::kStd;
  switch (req.illumination()) {
    case v1::ILLUMINATION_MODE_UNSPECIFIED:
      // Default for an unknown specimen: HF+ADAPT handles both high dynamic range and missing
      // texture (thesis 5.3, 6.2.3); chosen below when its models are calibrated and the
      // window fits the checkerboard (eq. 5.15), else ADAPT, else STD.
      mode = IlluminationMode::kHfAdapt;
      break;
    case v1::ILLUMINATION_MODE_STD: mode = IlluminationMode::kStd; break;
    case v1::ILLUMINATION_MODE_HDR: mode = IlluminationMode::kHdr; break;
    case v1::ILLUMINATION_MODE_ADAPT_IT: mode = IlluminationMode::kAdaptIterative; break;
    case v1::ILLUMINATION_MODE_ADAPT: mode = IlluminationMode::kAdapt; break;
    case v1::ILLUMINATION_MODE_TEXTURE: mode = IlluminationMode::kTexture; break;
    case v1::ILLUMINATION_MODE_HF_ADAPT: mode = IlluminationMode::kHfAdapt; break;
    case v1::ILLUMINATION_MODE_ADAPTED_HF: mode = IlluminationMode::kAdaptedHf; break;
    default: return Status::InvalidArgument("illumination " + std::to_string(int(req.illumination())) + " is unknown");
  }
  IlluminationParams params;
  const v1::IlluminationParameters& ip = req.illumination_parameters();
  if (ip.has_hdr_exposures()) params.hdr_exposures = ip.hdr_exposures();
  if (ip.has_lambda()) params.lambda = ip.lambda();
  if (ip.has_gamma()) params.gamma = ip.gamma();
  if (ip.has_psi()) params.psi = ip.psi();
  if (ip.has_max_iterations()) params.max_iterations = ip.max_iterations();
  if (ip.has_target_grey()) params.target_grey = ip.target_grey();
  {
    Status v = params.Validate();
    if (!v.ok()) return Status::InvalidArgument("illumination_parameters." + v.message());
  }
  if (req.illumination() != v1::ILLUMINATION_MODE_UNSPECIFIED) {
    INSPECT_RETURN_IF_ERROR(CheckCalibrationFor(mode, bundle.get()));
  }
  const ScanDefaults defaults = rig_->rig().scan_defaults();
  // Range unset (both ends zero) = the rig's default range; step zero = the rig's default step.
  const bool default_range = req.z_start_um() == 0.0 && req.z_end_um() == 0.0;
  const double z0 = default_range ? defaults.z_start_um : req.z_start_um();
  const double z1 = default_range ? defaults.z_end_um : req.z_end_um();
  const double dz = req.z_step_um() == 0.0 ? defaults.z_step_um : req.z_step_um();
  if (req.exposure_us() < 0) return Status::InvalidArgument("exposure_us must be >= 0 (0 = rig default)");
  const double exposure = req.exposure_us() > 0 ? req.exposure_us() : defaults.exposure_us;
  INSPECT_ASSIGN_OR_RETURN(ScanPlan plan, MakeScanPlan(z0, z1, dz, exposure, rig_->rig().stage()));
  std::vector<int> extras;
  INSPECT_ASSIGN_OR_RETURN(plan.sff, ToSffOptions(req.reconstruction(), "reconstruction", &extras));
  auto texture_fits = [&] {
    return bundle && bundle->psf && bundle->geometry &&
           ChooseTexturePeriod(bundle->psf->influence_radius_px, bundle->geometry->camera_px_per_projector_px,
                               plan.sff.window_px)
               .ok();
  };
  if (req.illumination() == v1::ILLUMINATION_MODE_UNSPECIFIED) {
    if (!CheckCalibrationFor(IlluminationMode::kHfAdapt, bundle.get()).ok() || !texture_fits()) {
      mode = CheckCalibrationFor(IlluminationMode::kAdapt, bundle.get()).ok() ? IlluminationMode::kAdapt
                                                                              : IlluminationMode::kStd;
    }
  } else if (mode == IlluminationMode::kTexture || mode == IlluminationMode::kHfAdapt ||
             mode == IlluminationMode::kAdaptedHf) {
    auto period = ChooseTexturePeriod(bundle->psf->influence_radius_px, bundle->geometry->camera_px_per_projector_px,
                                      plan.sff.window_px);
    if (!period.ok()) return period.status().WithContext("reconstruction.window_px " + std::to_string(plan.sff.window_px));
  }
  plan.mode = mode;
  plan.params = params;

  std::lock_guard<std::mutex> lock(mu_);
  if (stopping_) return Status::Unavailable("server is shutting down");
  if (!req.request_id().empty()) {  // again under the lock: a concurrent duplicate may have won
    auto existing = Dedupe(v1::JOB_KIND_SCAN, req.request_id());
    if (existing.ok()) return *existing;
  }
  auto is_cal = [](const RecordPtr& r) { return r->job_.kind() == v1::JOB_KIND_CALIBRATE; };
  if ((running_rig_ && is_cal(running_rig_)) || std::any_of(rig_queue_.begin(), rig_queue_.end(), is_cal)) {
    return Status::Aborted("a calibration is running or queued; scans and calibrations never interleave, retry after it");
  }
  if (int(rig_queue_.size()) >= options_.rig_queue_capacity) {
    return Status::ResourceExhausted("rig queue is full (" + std::to_string(options_.rig_queue_capacity) +
                                     " jobs waiting); retry later");
  }
  RecordPtr r = NewRecord(v1::JOB_KIND_SCAN, req.request_id(), req.label());
  r->scan_plan_ = std::move(plan);
  r->extra_exports_ = std::move(extras);
  INSPECT_RETURN_IF_ERROR(store_->PutJob(r->job_));
  live_[r->job_.job_id()] = r;
  rig_queue_.push_back(r);
  Emit(r, [&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_QUEUED);
    e.set_message("queued at position " + std::to_string(rig_queue_.size()));
  });
  work_cv_.notify_all();
  spdlog::info("job {} queued: scan {} frames z {}..{} um", r->job_.job_id(), r->scan_plan_.z_um.size(), z0, z1);
  return r;
}

StatusOr<std::shared_ptr<JobRecord>> JobManager::SubmitCalibrate(const v1::CalibrateRequest& req) {
  for (int i = 0; i < req.steps_size(); ++i) {
    if (req.steps(i) == v1::CALIBRATION_STEP_UNSPECIFIED || !v1::CalibrationStep_IsValid(req.steps(i))) {
      return Status::InvalidArgument("steps[" + std::to_string(i) + "] is not a calibration step");
    }
  }
  std::lock_guard<std::mutex> lock(mu_);
  if (!req.request_id().empty()) {
    auto existing = Dedupe(v1::JOB_KIND_CALIBRATE, req.request_id());
    if (existing.ok()) return *existing;
  }
  if (!calibration_runner_) return Status::Unimplemented("calibration is not available in this server build");
  if (!rig_->usable()) {
    return Status::FailedPrecondition("rig is not ready (state " + v1::RigState_Name(rig_->state()) + ": " +
                                      rig_->state_detail() + "); fix the cause and call ResetRig");
  }
  auto is_scan = [](const RecordPtr& r) { return r->job_.kind() == v1::JOB_KIND_SCAN; };
  if ((running_rig_ && is_scan(running_rig_)) || std::any_of(rig_queue_.begin(), rig_queue_.end(), is_scan)) {
    return Status::Aborted("a scan is running or queued; scans and calibrations never interleave, retry after it");
  }
  if (int(rig_queue_.size()) >= options_.rig_queue_capacity) {
    return Status::ResourceExhausted("rig queue is full; retry later");
  }
  RecordPtr r = NewRecord(v1::JOB_KIND_CALIBRATE, req.request_id(), req.label());
  r->calibrate_ = req;
  INSPECT_RETURN_IF_ERROR(store_->PutJob(r->job_));
  live_[r->job_.job_id()] = r;
  rig_queue_.push_back(r);
  Emit(r, [&](v1::JobEvent& e) { e.set_phase(v1::JOB_PHASE_QUEUED); });
  work_cv_.notify_all();
  return r;
}

StatusOr<std::shared_ptr<JobRecord>> JobManager::SubmitReconstruct(const v1::ReconstructStart& start,
                                                                   const fs::path& stack_dir, bool owns_stack_dir) {
  std::vector<int> extras;
  auto sff = ToSffOptions(start.options(), "options", &extras);
  std::lock_guard<std::mutex> lock(mu_);
  if (!start.request_id().empty()) {
    auto existing = Dedupe(v1::JOB_KIND_RECONSTRUCT, start.request_id());
    if (existing.ok()) {
      if (owns_stack_dir) RemoveAll(stack_dir);
      return *existing;
    }
  }
  if (!sff.ok() || stopping_ || int(reconstruct_queue_.size()) >= options_.reconstruct_queue_capacity) {
    if (owns_stack_dir) RemoveAll(stack_dir);
    if (!sff.ok()) return sff.status();
    if (stopping_) return Status::Unavailable("server is shutting down");
    return Status::ResourceExhausted("reconstruct queue is full; retry later");
  }
  RecordPtr r = NewRecord(v1::JOB_KIND_RECONSTRUCT, start.request_id(), start.label());
  r->sff_ = *sff;
  r->extra_exports_ = std::move(extras);
  r->stack_dir_ = stack_dir;
  r->owns_stack_dir_ = owns_stack_dir;
  if (start.has_scan_id()) r->job_.mutable_result()->set_scan_id(start.scan_id());
  INSPECT_RETURN_IF_ERROR(store_->PutJob(r->job_));
  live_[r->job_.job_id()] = r;
  reconstruct_queue_.push_back(r);
  Emit(r, [&](v1::JobEvent& e) { e.set_phase(v1::JOB_PHASE_QUEUED); });
  work_cv_.notify_all();
  return r;
}

StatusOr<std::shared_ptr<JobRecord>> JobManager::Find(const std::string& job_id) {
  if (job_id.empty()) return Status::InvalidArgument("job_id is empty");
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = live_.find(job_id);
    if (it != live_.end()) {
      // Queue position is derived, not stored: compute it when asked.
      int pos = 0;
      for (size_t i = 0; i < rig_queue_.size(); ++i) {
        if (rig_queue_[i] == it->second) pos = int(i) + 1;
      }
      for (size_t i = 0; i < reconstruct_queue_.size(); ++i) {
        if (reconstruct_queue_[i] == it->second) pos = int(i) + 1;
      }
      std::lock_guard<std::mutex> rl(it->second->mu_);
      it->second->job_.set_queue_position(pos);
      return it->second;
    }
  }
  INSPECT_ASSIGN_OR_RETURN(v1::Job job, store_->GetJob(job_id));
  auto r = std::make_shared<JobRecord>(std::move(job));
  INSPECT_ASSIGN_OR_RETURN(r->events_, store_->Events(job_id));
  return r;
}

StatusOr<v1::Job> JobManager::Cancel(const std::string& job_id) {
  INSPECT_ASSIGN_OR_RETURN(RecordPtr r, Find(job_id));
  if (r->terminal()) return r->Snapshot();
  r->cancel_requested = true;
  bool was_queued = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto* q : {&rig_queue_, &reconstruct_queue_}) {
      auto it = std::find(q->begin(), q->end(), r);
      if (it != q->end()) {
        q->erase(it);
        was_queued = true;
      }
    }
  }
  if (was_queued) {
    if (r->owns_stack_dir_) RemoveAll(r->stack_dir_);
    Finish(r, Status::Cancelled("cancelled while queued"));
  }
  spdlog::info("job {} cancel requested", job_id);
  return r->Snapshot();
}

int JobManager::queued_rig_jobs() const {
  std::lock_guard<std::mutex> lock(mu_);
  return int(rig_queue_.size());
}

std::string JobManager::running_rig_job() const {
  std::lock_guard<std::mutex> lock(mu_);
  return running_rig_ ? running_rig_->job_.job_id() : std::string();
}

std::string JobManager::active_calibration_id() const { return store_->GetSetting("active_calibration_id"); }

fs::path JobManager::ScanDir(const std::string& scan_id) const { return store_->scans_dir() / scan_id; }

void JobManager::Emit(const RecordPtr& r, const std::function<void(v1::JobEvent&)>& fill) {
  v1::JobEvent e;
  {
    std::lock_guard<std::mutex> lock(r->mu_);
    e.set_job_id(r->job_.job_id());
    e.set_sequence(r->events_.size() + 1);
    *e.mutable_time() = TimeUtil::GetCurrentTime();
    e.set_state(r->job_.state());
    e.set_remaining_seconds(-1);
    if (r->started_ != Clock::time_point()) {
      e.set_elapsed_seconds(std::chrono::duration<double>(Clock::now() - r->started_).count());
    }
    fill(e);
    r->events_.push_back(e);
  }
  Status s = store_->AppendEvent(e);
  if (!s.ok()) spdlog::error("job {}: cannot persist event: {}", e.job_id(), s.ToString());
  r->cv_.notify_all();
}

void JobManager::Finish(const RecordPtr& r, const Status& status) {
  v1::Job job;
  {
    std::lock_guard<std::mutex> lock(r->mu_);
    if (IsTerminal(r->job_.state())) return;
    if (status.ok()) {
      r->job_.set_state(v1::JOB_STATE_SUCCEEDED);
    } else if (status.code() == StatusCode::kCancelled) {
      r->job_.set_state(v1::JOB_STATE_CANCELLED);
      r->job_.clear_result();
      r->job_.set_error_code(int(status.code()));
      r->job_.set_error_message(status.message());
    } else {
      r->job_.set_state(v1::JOB_STATE_FAILED);
      r->job_.clear_result();
      r->job_.set_error_code(int(status.code()));
      r->job_.set_error_message(status.message());
    }
    r->job_.set_queue_position(0);
    *r->job_.mutable_end_time() = TimeUtil::GetCurrentTime();
    job = r->job_;
  }
  Status s = store_->PutJob(job);
  if (!s.ok()) spdlog::error("job {}: cannot persist: {}", job.job_id(), s.ToString());
  Emit(r, [&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_DONE);
    e.set_progress(job.state() == v1::JOB_STATE_SUCCEEDED ? 1.0 : e.progress());
    e.set_remaining_seconds(0);
    e.set_message(status.ok() ? "done" : status.ToString());
    *e.mutable_job() = job;
  });
  if (status.ok()) {
    spdlog::info("job {} succeeded", job.job_id());
  } else {
    spdlog::warn("job {} ended {}: {}", job.job_id(), v1::JobState_Name(job.state()), status.ToString());
  }
  std::lock_guard<std::mutex> lock(mu_);
  // Keep memory bounded: finished jobs beyond the newest few are served from the store.
  if (live_.size() > kMaxFinishedInMemory) {
    std::vector<std::pair<int64_t, std::string>> finished;
    for (const auto& [id, rec] : live_) {
      if (rec->terminal()) finished.push_back({rec->Snapshot().end_time().seconds(), id});
    }
    std::sort(finished.begin(), finished.end());
    for (size_t i = 0; i + kMaxFinishedInMemory / 2 < finished.size(); ++i) live_.erase(finished[i].second);
  }
}

JobManager::RecordPtr JobManager::WaitForWork(std::deque<RecordPtr>& queue, bool mark_running_rig) {
  std::unique_lock<std::mutex> lock(mu_);
  work_cv_.wait(lock, [&] { return stopping_ || !queue.empty(); });
  if (stopping_) return nullptr;
  RecordPtr r = queue.front();
  queue.pop_front();
  if (mark_running_rig) running_rig_ = r;
  return r;
}

void JobManager::RigWorker() {
  while (RecordPtr r = WaitForWork(rig_queue_, /*mark_running_rig=*/true)) {
    Status status;
    {
      auto rig_lock = rig_->Acquire();
      status = r->job_.kind() == v1::JOB_KIND_SCAN ? RunScan(r) : RunCalibrate(r);
    }
    // The rig is free before the terminal event goes out: a client that sees the job end can
    // use the rig (reset, calibrate, change specimen) at once.
    {
      std::lock_guard<std::mutex> lock(mu_);
      running_rig_.reset();
    }
    Finish(r, status);
  }
}

void JobManager::ReconstructWorker() {
  while (RecordPtr r = WaitForWork(reconstruct_queue_, /*mark_running_rig=*/false)) RunReconstruct(r);
}

Status JobManager::PublishArtifacts(const RecordPtr& r, const fs::path& tmp_dir,
                                    const std::vector<std::pair<v1::ArtifactKind, fs::path>>& files,
                                    v1::JobResult* result) {
  const std::string job_id = r->Snapshot().job_id();
  const fs::path final_dir = store_->artifacts_dir() / job_id;
  std::vector<StoredArtifact> stored;
  for (const auto& [kind, path] : files) {
    StoredArtifact a;
    a.job_id = job_id;
    a.path = final_dir / path.filename();
    a.artifact.set_artifact_id(NewId("art"));
    a.artifact.set_kind(kind);
    a.artifact.set_file_name(path.filename().string());
    std::error_code ec;
    a.artifact.set_size_bytes(int64_t(fs::file_size(path, ec)));
    if (ec) return Status::Internal("artifact " + path.string() + ": " + ec.message());
    INSPECT_ASSIGN_OR_RETURN(std::string sha, Sha256File(path));
    a.artifact.set_sha256(sha);
    a.artifact.set_media_type(MediaType(kind));
    stored.push_back(std::move(a));
  }
  std::error_code ec;
  fs::rename(tmp_dir, final_dir, ec);
  if (ec) return Status::Internal("cannot move artifacts into place: " + ec.message());
  for (const StoredArtifact& a : stored) {
    INSPECT_RETURN_IF_ERROR(store_->PutArtifact(a));
    *result->add_artifacts() = a.artifact;
  }
  return Status::Ok();
}

Status JobManager::RunScan(const RecordPtr& r) {
  if (r->cancel_requested) {
    return Status::Cancelled("cancelled before it started");
  }
  const std::string job_id = r->Snapshot().job_id();
  {
    std::lock_guard<std::mutex> lock(r->mu_);
    r->job_.set_state(v1::JOB_STATE_RUNNING);
    *r->job_.mutable_start_time() = TimeUtil::GetCurrentTime();
    r->started_ = Clock::now();
  }
  (void)store_->PutJob(r->Snapshot());
  rig_->SetBusy(true);
  const ScanPlan plan = [&] {
    ScanPlan p = r->scan_plan_;
    p.calibration_id = active_calibration_id();
    return p;
  }();
  const int count = int(plan.z_um.size());
  Emit(r, [&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_PREPARING);
    e.set_message("scan of " + std::to_string(count) + " frames");
  });

  const fs::path tmp_stack = store_->tmp_dir() / (job_id + ".stack");
  const fs::path tmp_artifacts = store_->tmp_dir() / (job_id + ".artifacts");
  auto fail = [&](const Status& s) {
    RemoveAll(tmp_stack);
    RemoveAll(tmp_artifacts);
    rig_->ReportJobStatus(s);
    return s;
  };

  auto on_frame = [&](const ScanFrameEvent& f) {
    Emit(r, [&](v1::JobEvent& e) {
      FillFrameEvent(v1::JOB_PHASE_ACQUIRING, f.index, f.count, f.z_um, f.exposure_us, f.statistics, &e);
      e.mutable_frame()->set_acquisition_index(f.acquisition);
      e.mutable_frame()->set_stack_frame(f.stack_frame);
    });
  };
  // The bundle is taken again at run time (a calibration may have finished since submission);
  // RunScan re-checks that it holds the mode's models.
  std::shared_ptr<const CalibrationBundle> bundle = active_calibration_ ? active_calibration_() : nullptr;
  auto outcome = inspection::RunScan(rig_->rig(), plan, tmp_stack, on_frame, r->cancel_requested, bundle.get());
  if (!outcome.ok()) {
    return fail(outcome.status());
  }
  Emit(r, [&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_STORING);
    e.set_progress(0.92);
  });

  std::error_code ec;
  fs::create_directories(tmp_artifacts, ec);
  DepthExportMeta meta;
  meta.pixel_size_um = outcome->manifest.pixel_size_um;
  meta.description = "depth (um) of scan " + job_id;
  auto files = WriteDepthArtifacts(outcome->depth, tmp_artifacts, meta, ToExportKinds(r->extra_exports_));
  if (!files.ok()) {
    return fail(files.status());
  }
  std::vector<std::pair<v1::ArtifactKind, fs::path>> published;
  for (const auto& f : *files) published.push_back({ToArtifactKind(f.kind), f.path});
  if (!outcome->ground_truth_um.empty()) {
    fs::copy_file(tmp_stack / kGroundTruthDepthName, tmp_artifacts / kGroundTruthDepthName, ec);
    if (ec) {
      return fail(Status::Internal("cannot copy ground truth: " + ec.message()));
    }
    published.push_back({v1::ARTIFACT_KIND_GROUND_TRUTH_TIFF, tmp_artifacts / kGroundTruthDepthName});
  }
  Status zs = ZipFolder(tmp_stack, tmp_artifacts / "stack.zip");
  if (!zs.ok()) {
    return fail(zs);
  }
  published.push_back({v1::ARTIFACT_KIND_STACK_ZIP, tmp_artifacts / "stack.zip"});
  if (r->cancel_requested) {  // last point at which a cancel still wins
    return fail(Status::Cancelled("scan cancelled while storing"));
  }

  v1::JobResult result;
  result.set_scan_id(job_id);
  result.set_calibration_id(plan.calibration_id);
  *result.mutable_depth() =
      Summarise(outcome->depth, outcome->manifest.pixel_size_um, outcome->ground_truth_um, plan.sff.window_px);
  result.mutable_depth()->set_engine_seconds(outcome->engine_finish_seconds);
  fs::rename(tmp_stack, ScanDir(job_id), ec);
  if (ec) {
    return fail(Status::Internal("cannot store the scan: " + ec.message()));
  }
  Status ps = PublishArtifacts(r, tmp_artifacts, published, &result);
  if (!ps.ok()) {
    RemoveAll(ScanDir(job_id));
    return fail(ps);
  }
  {
    std::lock_guard<std::mutex> lock(r->mu_);
    *r->job_.mutable_result() = result;
  }
  rig_->ReportJobStatus(Status::Ok());
  return Status::Ok();
}

void JobManager::RunReconstruct(const RecordPtr& r) {
  const std::string job_id = r->Snapshot().job_id();
  const fs::path tmp_artifacts = store_->tmp_dir() / (job_id + ".artifacts");
  auto cleanup = [&] {
    RemoveAll(tmp_artifacts);
    if (r->owns_stack_dir_) RemoveAll(r->stack_dir_);
  };
  if (r->cancel_requested) {
    cleanup();
    Finish(r, Status::Cancelled("cancelled before it started"));
    return;
  }
  {
    std::lock_guard<std::mutex> lock(r->mu_);
    r->job_.set_state(v1::JOB_STATE_RUNNING);
    *r->job_.mutable_start_time() = TimeUtil::GetCurrentTime();
    r->started_ = Clock::now();
  }
  (void)store_->PutJob(r->Snapshot());
  Emit(r, [&](v1::JobEvent& e) { e.set_phase(v1::JOB_PHASE_PREPARING); });

  auto run = [&]() -> StatusOr<v1::JobResult> {
    INSPECT_ASSIGN_OR_RETURN(StackManifest m, ReadStackManifest(r->stack_dir_));
    auto on_frame = [&](int i, int n, double z, const FrameStatistics& st) {
      Emit(r, [&](v1::JobEvent& e) {
        FillFrameEvent(v1::JOB_PHASE_RECONSTRUCTING, i, n, z, m.frames[i].exposure_us, st, &e);
      });
    };
    INSPECT_ASSIGN_OR_RETURN(DepthResult depth,
                             ReconstructStackFolder(r->stack_dir_, m, r->sff_, on_frame, r->cancel_requested));
    Emit(r, [&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_STORING);
      e.set_progress(0.92);
    });
    std::error_code ec;
    fs::create_directories(tmp_artifacts, ec);
    DepthExportMeta meta;
    meta.pixel_size_um = m.pixel_size_um;
    meta.description = "depth (um) from reconstruct job " + job_id;
    INSPECT_ASSIGN_OR_RETURN(auto files, WriteDepthArtifacts(depth, tmp_artifacts, meta, ToExportKinds(r->extra_exports_)));
    std::vector<std::pair<v1::ArtifactKind, fs::path>> published;
    for (const auto& f : files) published.push_back({ToArtifactKind(f.kind), f.path});
    cv::Mat truth;
    if (fs::exists(r->stack_dir_ / kGroundTruthDepthName)) {
      auto t = ReadDepthTiff(r->stack_dir_ / kGroundTruthDepthName);
      if (t.ok()) truth = *t;
    }
    if (r->cancel_requested) return Status::Cancelled("reconstruction cancelled while storing");
    v1::JobResult result = r->Snapshot().result();  // carries scan_id when the source was a scan
    *result.mutable_depth() = Summarise(depth, m.pixel_size_um, truth, r->sff_.window_px);
    INSPECT_RETURN_IF_ERROR(PublishArtifacts(r, tmp_artifacts, published, &result));
    return result;
  };
  auto result = run();
  cleanup();
  if (result.ok()) {
    std::lock_guard<std::mutex> lock(r->mu_);
    *r->job_.mutable_result() = *result;
  }
  Finish(r, result.ok() ? Status::Ok() : result.status());
}

Status JobManager::RunCalibrate(const RecordPtr& r) {
  if (r->cancel_requested) {
    return Status::Cancelled("cancelled before it started");
  }
  {
    std::lock_guard<std::mutex> lock(r->mu_);
    r->job_.set_state(v1::JOB_STATE_RUNNING);
    *r->job_.mutable_start_time() = TimeUtil::GetCurrentTime();
    r->started_ = Clock::now();
  }
  (void)store_->PutJob(r->Snapshot());
  rig_->SetBusy(true);
  CalibrationContext ctx;
  ctx.rig = &rig_->rig();
  ctx.request = &r->calibrate_;
  ctx.cancel = &r->cancel_requested;
  ctx.job_id = r->Snapshot().job_id();
  ctx.progress = [&](const std::string& step, double progress, const std::string& message) {
    Emit(r, [&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_CALIBRATING);
      e.set_step(step);
      e.set_progress(progress);
      e.set_message(message);
    });
  };
  auto cal = calibration_runner_(ctx);
  rig_->ReportJobStatus(cal.ok() ? Status::Ok() : cal.status());
  if (cal.ok()) {
    std::lock_guard<std::mutex> lock(r->mu_);
    r->job_.mutable_result()->set_calibration_id(cal->calibration_id());
    *r->job_.mutable_result()->mutable_calibration() = cal->summary();
  }
  return cal.ok() ? Status::Ok() : cal.status();
}

}  // namespace inspection
