// gRPC handlers: translate through the request mapping, delegate, stream job events back.
#include "server/api/inspection_service.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <optional>
#include <set>

#include "core/io/stack.h"
#include "server/api/grpc_status.h"
#include "server/api/recipe_scan.h"
#include "server/api/request_mapping.h"
#include "server/api/stack_transfer.h"
#include "server/jobs/rig_verification.h"
#include "server/security/audit_interceptor.h"
#include "server/security/call_authorization.h"
#include "server/storage/data_lifecycle.h"
#include "server/storage/stored_stack.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {

grpc::Status Grpc(const Status& s) { return ToGrpcStatus(s); }

// How a finished job ended, as the status its event stream closes with: OK for SUCCEEDED, the
// job's error otherwise (UNKNOWN when a stored job lacks its code).
Status JobOutcome(const v1::Job& job) {
  switch (job.state()) {
    case v1::JOB_STATE_SUCCEEDED:
      return Status::Ok();
    case v1::JOB_STATE_CANCELLED:
      return Status::Cancelled(job.error_message());
    default:
      return Status(job.error_code() ? StatusCode(job.error_code()) : StatusCode::kUnknown, job.error_message());
  }
}

// What a deletion freed, as DeleteJob and DeleteScan answer it.
grpc::Status Deleted(const StatusOr<DeleteOutcome>& deleted, v1::DeleteResponse* out) {
  if (!deleted.ok()) return Grpc(deleted.status());
  out->set_id(deleted->id);
  out->set_bytes_freed(deleted->bytes_freed);
  out->set_artifacts_deleted(deleted->artifacts_deleted);
  return grpc::Status::OK;
}

// Replays a job's events from the first and follows it to its terminal event. Returns when the
// job ended or the client went away; the job itself keeps running either way.
template <typename Writer>
grpc::Status StreamJob(grpc::ServerContext* ctx, const std::shared_ptr<JobRecord>& r, Writer* writer) {
  size_t sent = 0;
  for (;;) {
    std::vector<v1::JobEvent> events;
    const bool ended = r->EventsSince(sent, std::chrono::milliseconds(200), &events);
    for (const v1::JobEvent& e : events) {
      if (!writer->Write(e)) return grpc::Status(grpc::StatusCode::CANCELLED, "client stopped reading");
    }
    sent += events.size();
    if (ended) break;
    if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client went away");
  }
  return Grpc(JobOutcome(r->Snapshot()));
}

}  // namespace

void InspectionServiceImpl::FillRigStatus(v1::RigStatus* st) {
  rig_->FillStatus(st);
  st->set_active_calibration_id(calibrations_->active_id());
  if (StatusOr<RigVerification> v = ReadRigVerification(*store_, st->active_calibration_id(), CurrentTimestamp());
      v.ok()) {
    st->set_verification_state(v->state);
    st->set_verification_detail(v->detail);
  } else {
    st->set_verification_detail("verification records not read: " + v.status().message());
  }
  st->set_running_job_id(jobs_->running_rig_job());
  st->set_queued_jobs(jobs_->queued_rig_jobs());
  st->set_queue_capacity(jobs_->rig_queue_capacity());
  st->set_server_version(options_.server_version);
}

grpc::Status InspectionServiceImpl::GetRigStatus(grpc::ServerContext* ctx, const v1::GetRigStatusRequest*,
                                                 v1::RigStatus* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  FillRigStatus(out);
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ResetRig(grpc::ServerContext* ctx, const v1::ResetRigRequest*, v1::RigStatus* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  auto lock = rig_->TryAcquire();
  if (!lock.owns_lock()) {
    return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "a rig job is running; cancel it before a reset");
  }
  Status s = rig_->Reset();
  lock.unlock();
  FillRigStatus(out);
  if (!s.ok()) return Grpc(Status::Unavailable("reset failed: " + s.message()));
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::Scan(grpc::ServerContext* ctx, const v1::ScanRequest* req,
                                         grpc::ServerWriter<v1::JobEvent>* writer) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  // Refused before the rig moves: a scan that cannot be stored is not worth taking.
  if (Status s = CheckFreeSpaceReserve(store_->data_dir(), options_.min_free_bytes); !s.ok()) return Grpc(s);
  auto r = jobs_->Submit(
      v1::JOB_KIND_SCAN, req->request_id(), req->label(),
      [&]() -> StatusOr<JobWork> {
        INSPECT_RETURN_IF_ERROR(rig_->CheckUsable());
        const std::shared_ptr<const CalibrationBundle> calibration = calibrations_->active();
        ScanContext context;
        context.defaults = rig_->rig().scan_defaults();
        context.stage = &rig_->rig().stage();
        context.calibration = calibration.get();
        Rig& rig = rig_->rig();
        INSPECT_ASSIGN_OR_RETURN(
            ScanWork work,
            MapScanRequestWithRecipe(*req, context, *store_, rig.camera().frame_size(), rig.pixel_size_um()));
        return JobWork(std::move(work));
      },
      who->name);
  if (!r.ok()) return Grpc(r.status());
  SetAuditTarget(ctx, (*r)->job_id());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::Calibrate(grpc::ServerContext* ctx, const v1::CalibrateRequest* req,
                                              grpc::ServerWriter<v1::JobEvent>* writer) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  auto r = jobs_->Submit(
      v1::JOB_KIND_CALIBRATE, req->request_id(), req->label(),
      [&]() -> StatusOr<JobWork> {
        INSPECT_ASSIGN_OR_RETURN(CalibrateWork work, MapCalibrateRequest(*req));
        INSPECT_RETURN_IF_ERROR(rig_->CheckUsable());
        return JobWork(std::move(work));
      },
      who->name);
  if (!r.ok()) return Grpc(r.status());
  SetAuditTarget(ctx, (*r)->job_id());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::Verify(grpc::ServerContext* ctx, const v1::VerifyRequest* req,
                                           grpc::ServerWriter<v1::JobEvent>* writer) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  auto r = jobs_->Submit(
      v1::JOB_KIND_VERIFY, req->request_id(), req->label(),
      [&]() -> StatusOr<JobWork> {
        INSPECT_ASSIGN_OR_RETURN(VerifyWork work, MapVerifyRequest(*req));
        work.interval_days = options_.verification_interval_days;
        INSPECT_RETURN_IF_ERROR(rig_->CheckUsable());
        // Refused before it queues; RunVerification checks the mode's measures in full.
        SimulationControl* sim = rig_->rig().simulation();
        if (sim == nullptr || sim->material_measures().empty()) {
          return Status::FailedPrecondition(
              "material_measures: the rig offers no ISO 25178-70 material measures (AFL, PGR, ASG, ACG) to verify with");
        }
        return JobWork(std::move(work));
      },
      who->name);
  if (!r.ok()) return Grpc(r.status());
  SetAuditTarget(ctx, (*r)->job_id());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::Reconstruct(
    grpc::ServerContext* ctx, grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>* stream) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  v1::ReconstructRequest first;
  if (!stream->Read(&first) || !first.has_start()) {
    return Grpc(Status::InvalidArgument("the first message must be start"));
  }
  if (Status s = CheckRequestTextLimits(first); !s.ok()) return Grpc(s);
  const v1::ReconstructStart& start = first.start();
  auto source = MapReconstructSource(start, options_.max_upload_bytes);
  if (!source.ok()) return Grpc(source.status());
  fs::path dir;
  std::shared_ptr<OwnedFolder> upload;  // removed on every early return
  // Declared after `upload`: its decode threads are joined before the folder goes.
  std::shared_ptr<StackFrameDecoder> decoded;
  std::optional<StackManifest> stored_manifest;  // a stored scan's, checked against its archive
  StackFrameDecodeFn decode_stored;              // empty: the frames decode from `dir`
  if (Status s = CheckFreeSpaceReserve(store_->data_dir(), options_.min_free_bytes); !s.ok()) return Grpc(s);
  if (source->upload) {
    upload = store_->NewUploadFolder("upload");  // held: other replicas' sweeps leave it
    dir = upload->path();
    UploadDecoding decoding(dir, options_.reconstruct);
    Status received = ReceiveUpload(stream, *source, dir, options_.max_upload_bytes, &decoding);
    decoded = decoding.Take();
    if (!received.ok()) return Grpc(received);
  } else {
    // The stack is stored once, as the scan's stack.zip: its frames are read from the archive and
    // decoded in memory, in parallel; only stack.json and the ground truth go to the job's folder.
    auto stored = OpenStoredStack(*store_, source->scan_id,
                                  options_.reconstruct.sequential ? StoredFrames::kExtracted : StoredFrames::kInMemory);
    if (!stored.ok()) return Grpc(stored.status());
    dir = stored->dir;
    upload = std::move(stored->extraction);
    stored_manifest = std::move(stored->manifest);
    decode_stored = std::move(stored->decode);
  }
  // Validate the whole stack before a job exists: bad input never becomes a failed job.
  if (Status s = CheckStackFrames(dir, stored_manifest, options_.reconstruct, decode_stored, &decoded); !s.ok()) {
    return Grpc(s);
  }
  // The upload moves into the job's work: it goes when the job ends, or with the request when
  // no job is queued (invalid options, a duplicate request id, a full queue).
  auto r = jobs_->Submit(
      v1::JOB_KIND_RECONSTRUCT, start.request_id(), start.label(),
      [&, upload = std::move(upload)]() -> StatusOr<JobWork> {
        INSPECT_ASSIGN_OR_RETURN(ReconstructWork work, MapReconstructStart(start, dir, upload));
        work.decoded = std::move(decoded);
        work.pool_input = start.SerializeAsString();  // a pool replica rebuilds the work from it
        return JobWork(std::move(work));
      },
      who->name);
  if (!r.ok()) return Grpc(r.status());
  SetAuditTarget(ctx, (*r)->job_id());
  return StreamJob(ctx, *r, stream);
}

grpc::Status InspectionServiceImpl::WatchJob(grpc::ServerContext* ctx, const v1::WatchJobRequest* req,
                                             grpc::ServerWriter<v1::JobEvent>* writer) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  if (Status s = CheckJobId(req->job_id()); !s.ok()) return Grpc(s);
  auto r = jobs_->Find(req->job_id());
  if (!r.ok()) return Grpc(r.status());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::GetJob(grpc::ServerContext* ctx, const v1::GetJobRequest* req, v1::Job* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  if (Status s = CheckJobId(req->job_id()); !s.ok()) return Grpc(s);
  auto r = jobs_->Find(req->job_id());
  if (!r.ok()) return Grpc(r.status());
  *out = (*r)->Snapshot();
  auto pinned = store_->PinnedJobs();
  if (!pinned.ok()) return Grpc(pinned.status());
  out->set_pinned(std::find(pinned->begin(), pinned->end(), out->job_id()) != pinned->end());
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ListJobs(grpc::ServerContext* ctx, const v1::ListJobsRequest* req,
                                             v1::ListJobsResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  auto query = MapListJobsRequest(*req);
  if (!query.ok()) return Grpc(query.status());
  const int limit = query->limit;
  auto jobs = store_->ListJobs(query->kind, query->state, limit + 1, query->before_create_ns);
  if (!jobs.ok()) return Grpc(jobs.status());
  auto pinned_ids = store_->PinnedJobs();
  if (!pinned_ids.ok()) return Grpc(pinned_ids.status());
  const std::set<std::string> pinned(pinned_ids->begin(), pinned_ids->end());
  for (int i = 0; i < int(jobs->size()) && i < limit; ++i) {
    // Live jobs carry fresher state than their last stored copy.
    const std::shared_ptr<JobRecord> live = jobs_->FindLive((*jobs)[i].job_id());
    v1::Job* job = out->add_jobs();
    *job = live ? live->Snapshot() : (*jobs)[i];
    job->set_pinned(pinned.count(job->job_id()) > 0);
  }
  if (int(jobs->size()) > limit) out->set_next_page_token(NextPageToken((*jobs)[limit - 1].create_time()));
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::CancelJob(grpc::ServerContext* ctx, const v1::CancelJobRequest* req, v1::Job* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  if (Status s = CheckJobId(req->job_id()); !s.ok()) return Grpc(s);
  // Operators cancel their own jobs; another identity's job needs an admin.
  auto found = jobs_->Find(req->job_id());
  if (!found.ok()) return Grpc(found.status());
  const std::string owner = (*found)->Snapshot().owner();
  if (owner != who->name) {
    if (Status s = CheckRole(*who, Role::kAdmin, "CancelJob of another identity's job ('" + owner + "')"); !s.ok()) {
      return Grpc(s);
    }
  }
  auto job = jobs_->Cancel(req->job_id());
  if (!job.ok()) return Grpc(job.status());
  *out = *job;
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::DownloadArtifact(grpc::ServerContext* ctx, const v1::DownloadArtifactRequest* req,
                                                     grpc::ServerWriter<v1::ArtifactChunk>* writer) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  auto range = MapDownloadRequest(*req);
  if (!range.ok()) return Grpc(range.status());
  auto a = store_->GetArtifact(range->artifact_id);
  if (!a.ok()) return Grpc(a.status());
  return Grpc(SendArtifactFile(*a, *range, [writer](const v1::ArtifactChunk& chunk) { return writer->Write(chunk); }));
}

grpc::Status InspectionServiceImpl::GetCalibration(grpc::ServerContext* ctx, const v1::GetCalibrationRequest* req,
                                                   v1::Calibration* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  auto c = calibrations_->Get(req->calibration_id());
  if (!c.ok()) return Grpc(c.status());
  *out = *c;
  for (v1::VerificationMode mode : {v1::VERIFICATION_MODE_FULL, v1::VERIFICATION_MODE_INTERIM}) {
    auto latest = store_->ListVerifications(out->calibration_id(), mode, 1);
    if (!latest.ok()) return Grpc(latest.status());
    if (latest->empty()) continue;
    *(mode == v1::VERIFICATION_MODE_FULL ? out->mutable_latest_full_verification()
                                         : out->mutable_latest_interim_verification()) = std::move(latest->front());
  }
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ListCalibrations(grpc::ServerContext* ctx, const v1::ListCalibrationsRequest*,
                                                     v1::ListCalibrationsResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  auto list = calibrations_->List();
  if (!list.ok()) return Grpc(list.status());
  for (const v1::Calibration& c : *list) *out->add_calibrations() = c;
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::DeleteJob(grpc::ServerContext* ctx, const v1::DeleteJobRequest* req,
                                              v1::DeleteResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  if (Status s = CheckJobId(req->job_id()); !s.ok()) return Grpc(s);
  return Deleted(options_.janitor->DeleteJob(req->job_id()), out);
}

grpc::Status InspectionServiceImpl::DeleteScan(grpc::ServerContext* ctx, const v1::DeleteScanRequest* req,
                                               v1::DeleteResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  if (req->scan_id().empty()) return Grpc(Status::InvalidArgument("scan_id is empty"));
  return Deleted(options_.janitor->DeleteScan(req->scan_id()), out);
}

grpc::Status InspectionServiceImpl::PinJob(grpc::ServerContext* ctx, const v1::PinJobRequest* req,
                                           v1::PinJobResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  if (Status s = CheckJobId(req->job_id()); !s.ok()) return Grpc(s);
  if (Status s = options_.janitor->Pin(req->job_id(), req->pinned()); !s.ok()) return Grpc(s);
  out->set_job_id(req->job_id());
  out->set_pinned(req->pinned());
  return grpc::Status::OK;
}

namespace {

// A user scene's name: letters, digits, '_', '-' and '.', not starting with '.'; never a path.
bool IsSceneName(const std::string& name) {
  if (name.empty() || name.front() == '.' || name.find("..") != std::string::npos) return false;
  return std::all_of(name.begin(), name.end(),
                     [](unsigned char c) { return std::isalnum(c) || c == '_' || c == '-' || c == '.'; });
}

fs::path ScenePath(const fs::path& scene_dir, const std::string& name) { return scene_dir / (name + ".json"); }

// The user scenes of the scene directory, by name (<name>.json).
std::vector<std::string> SceneNames(const fs::path& scene_dir) {
  std::vector<std::string> names;
  if (scene_dir.empty()) return names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(scene_dir, ec)) {
    const std::string stem = e.path().stem().string();
    if (e.path().extension() == ".json" && e.is_regular_file(ec) && IsSceneName(stem)) names.push_back(stem);
  }
  std::sort(names.begin(), names.end());
  return names;
}

// What the simulation calls the specimen, as the API shows it: a user scene by its name.
std::string ShownSpecimen(const std::string& current, const fs::path& scene_dir) {
  if (scene_dir.empty() || current.rfind("file:", 0) != 0) return current;
  const fs::path p(current.substr(5));
  if (p.parent_path() == scene_dir && p.extension() == ".json") return p.stem().string();
  return current;
}

// A built-in specimen name as it is, a scene name as the "file:" path the simulation loads.
// Paths from the caller are refused: the server must not open files a caller names.
StatusOr<std::string> ResolveSpecimen(const std::string& name, const std::vector<std::string>& builtins,
                                      const fs::path& scene_dir) {
  INSPECT_RETURN_IF_ERROR(CheckSpecimenName(name));
  if (std::find(builtins.begin(), builtins.end(), name) != builtins.end()) return name;
  if (name.rfind("file:", 0) == 0 || !IsSceneName(name)) {
    return Status::InvalidArgument("specimen '" + name +
                                   "' is not a specimen name: give a built-in specimen or the name of a scene in "
                                   "the server's scene directory (--scene-dir), not a path");
  }
  std::string known;
  for (const auto& n : builtins) known += (known.empty() ? "" : ", ") + n;
  for (const auto& n : SceneNames(scene_dir)) known += ", " + n;
  std::error_code ec;
  if (scene_dir.empty() || !fs::is_regular_file(ScenePath(scene_dir, name), ec)) {
    return Status::InvalidArgument("unknown specimen '" + name + "'; known: " + known);
  }
  return "file:" + ScenePath(scene_dir, name).string();
}

void FillSpecimens(SimulationControl* sim, const fs::path& scene_dir, v1::ListSpecimensResponse* out) {
  for (const std::string& n : sim->specimen_names()) out->add_specimens(n);
  for (const std::string& n : SceneNames(scene_dir)) out->add_specimens(n);
  out->set_current(ShownSpecimen(sim->specimen(), scene_dir));
}

}  // namespace

grpc::Status SimulationServiceImpl::ListSpecimens(grpc::ServerContext* ctx, const v1::ListSpecimensRequest*,
                                                  v1::ListSpecimensResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  SimulationControl* sim = rig_->rig().simulation();
  if (!sim) return Grpc(Status::FailedPrecondition("the rig is not simulated"));
  FillSpecimens(sim, options_.scene_dir, out);
  return grpc::Status::OK;
}

grpc::Status SimulationServiceImpl::SetSpecimen(grpc::ServerContext* ctx, const v1::SetSpecimenRequest* req,
                                                v1::ListSpecimensResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  SimulationControl* sim = rig_->rig().simulation();
  if (!sim) return Grpc(Status::FailedPrecondition("the rig is not simulated"));
  auto specimen = ResolveSpecimen(req->specimen(), sim->specimen_names(), options_.scene_dir);
  if (!specimen.ok()) return Grpc(specimen.status());
  auto lock = rig_->TryAcquire();
  if (!lock.owns_lock()) return Grpc(Status::Aborted("a rig job is running; change the specimen after it"));
  Status s = sim->SetSpecimen(*specimen);
  if (!s.ok()) return Grpc(s.code() == StatusCode::kNotFound ? Status::InvalidArgument(s.message()) : s);
  spdlog::info("simulated specimen set to {}", req->specimen());
  FillSpecimens(sim, options_.scene_dir, out);
  return grpc::Status::OK;
}

}  // namespace inspection
