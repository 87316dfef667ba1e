// gRPC handlers: translate through the request mapping, delegate, stream job events back.
#include "server/inspection_service.h"

#include <openssl/crypto.h>
#include <spdlog/spdlog.h>

#include <fstream>
#include <map>

#include "core/stack.h"
#include "server/grpc_status.h"
#include "server/request_mapping.h"

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

// Receives an uploaded stack folder into `dir`. Errors name the file and field at fault.
Status ReceiveUpload(grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>* stream,
                     const ReconstructSource& upload, const fs::path& dir, int64_t max_bytes) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::Internal("cannot create upload folder: " + ec.message());
  std::map<std::string, int64_t> sizes;
  std::map<std::string, bool> complete;
  int64_t total = 0;
  v1::ReconstructRequest msg;
  while (stream->Read(&msg)) {
    if (!msg.has_file_chunk()) return Status::InvalidArgument("after start, only file_chunk messages may follow");
    const v1::StackFileChunk& c = msg.file_chunk();
    INSPECT_RETURN_IF_ERROR(CheckUploadChunk(c));
    if (complete[c.path()]) return Status::InvalidArgument("file '" + c.path() + "' was already completed");
    if (c.offset() != sizes[c.path()]) {
      return Status::InvalidArgument("file_chunk.offset " + std::to_string(c.offset()) + " of '" + c.path() +
                                     "' does not continue the file at " + std::to_string(sizes[c.path()]));
    }
    total += int64_t(c.data().size());
    if (total > max_bytes || (upload.upload_total_bytes > 0 && total > upload.upload_total_bytes)) {
      return Status::InvalidArgument("upload exceeds start.upload.total_bytes");
    }
    const fs::path target = dir / c.path();
    fs::create_directories(target.parent_path(), ec);
    std::ofstream out(target, std::ios::binary | (c.offset() == 0 ? std::ios::trunc : std::ios::app));
    if (!out.write(c.data().data(), std::streamsize(c.data().size()))) {
      return Status::Internal("cannot write uploaded file '" + c.path() + "'");
    }
    sizes[c.path()] += int64_t(c.data().size());
    if (c.last()) complete[c.path()] = true;
  }
  for (const auto& [path, size] : sizes) {
    if (!complete[path]) return Status::InvalidArgument("file '" + path + "' ended without a chunk marked last");
  }
  if (upload.upload_file_count > 0 && int(sizes.size()) != upload.upload_file_count) {
    return Status::InvalidArgument("received " + std::to_string(sizes.size()) +
                                   " files but start.upload.file_count is " + std::to_string(upload.upload_file_count));
  }
  return Status::Ok();
}

}  // namespace

grpc::Status CheckBearerToken(grpc::ServerContext* ctx, const std::string& token) {
  if (token.empty()) return grpc::Status::OK;
  const auto& md = ctx->client_metadata();
  auto it = md.find("authorization");
  const std::string expected = "Bearer " + token;
  if (it == md.end() || it->second.size() != expected.size() ||
      CRYPTO_memcmp(it->second.data(), expected.data(), expected.size()) != 0) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "missing or wrong bearer token");
  }
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::CheckAuth(grpc::ServerContext* ctx) const {
  return CheckBearerToken(ctx, options_.auth_token);
}

void InspectionServiceImpl::FillRigStatus(v1::RigStatus* st) {
  rig_->FillStatus(st);
  st->set_active_calibration_id(calibrations_->active_id());
  st->set_running_job_id(jobs_->running_rig_job());
  st->set_queued_jobs(jobs_->queued_rig_jobs());
  st->set_queue_capacity(jobs_->rig_queue_capacity());
  st->set_server_version(options_.server_version);
}

grpc::Status InspectionServiceImpl::GetRigStatus(grpc::ServerContext* ctx, const v1::GetRigStatusRequest*,
                                                 v1::RigStatus* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  FillRigStatus(out);
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ResetRig(grpc::ServerContext* ctx, const v1::ResetRigRequest*, v1::RigStatus* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
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
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto r = jobs_->Submit(v1::JOB_KIND_SCAN, req->request_id(), req->label(), [&]() -> StatusOr<JobWork> {
    INSPECT_RETURN_IF_ERROR(rig_->CheckUsable());
    const std::shared_ptr<const CalibrationBundle> calibration = calibrations_->active();
    ScanContext context;
    context.defaults = rig_->rig().scan_defaults();
    context.stage = &rig_->rig().stage();
    context.calibration = calibration.get();
    INSPECT_ASSIGN_OR_RETURN(ScanWork work, MapScanRequest(*req, context));
    return JobWork(std::move(work));
  });
  if (!r.ok()) return Grpc(r.status());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::Calibrate(grpc::ServerContext* ctx, const v1::CalibrateRequest* req,
                                              grpc::ServerWriter<v1::JobEvent>* writer) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto r = jobs_->Submit(v1::JOB_KIND_CALIBRATE, req->request_id(), req->label(), [&]() -> StatusOr<JobWork> {
    INSPECT_ASSIGN_OR_RETURN(CalibrateWork work, MapCalibrateRequest(*req));
    INSPECT_RETURN_IF_ERROR(rig_->CheckUsable());
    return JobWork(std::move(work));
  });
  if (!r.ok()) return Grpc(r.status());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::Reconstruct(
    grpc::ServerContext* ctx, grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>* stream) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  v1::ReconstructRequest first;
  if (!stream->Read(&first) || !first.has_start()) {
    return Grpc(Status::InvalidArgument("the first message must be start"));
  }
  const v1::ReconstructStart& start = first.start();
  auto source = MapReconstructSource(start, options_.max_upload_bytes);
  if (!source.ok()) return Grpc(source.status());
  fs::path dir;
  std::shared_ptr<const OwnedFolder> upload;  // removed on every early return
  if (source->upload) {
    upload = std::make_shared<const OwnedFolder>(store_->uploads_dir() / NewId("upload"));
    dir = upload->path();
    if (Status s = ReceiveUpload(stream, *source, dir, options_.max_upload_bytes); !s.ok()) return Grpc(s);
  } else {
    dir = store_->scans_dir() / source->scan_id;
    if (!fs::is_directory(dir)) return Grpc(Status::NotFound("scan_id '" + source->scan_id + "' not found"));
  }
  // Validate the whole stack before a job exists: bad input never becomes a failed job.
  auto manifest = ReadStackManifest(dir);
  Status valid = manifest.ok() ? ValidateStackFrames(dir, *manifest) : manifest.status();
  if (!valid.ok()) return Grpc(valid);
  // The upload moves into the job's work: it goes when the job ends, or with the request when
  // no job is queued (invalid options, a duplicate request id, a full queue).
  auto r = jobs_->Submit(v1::JOB_KIND_RECONSTRUCT, start.request_id(), start.label(),
                         [&, upload = std::move(upload)]() -> StatusOr<JobWork> {
                           INSPECT_ASSIGN_OR_RETURN(ReconstructWork work, MapReconstructStart(start, dir, upload));
                           return JobWork(std::move(work));
                         });
  if (!r.ok()) return Grpc(r.status());
  return StreamJob(ctx, *r, stream);
}

grpc::Status InspectionServiceImpl::WatchJob(grpc::ServerContext* ctx, const v1::WatchJobRequest* req,
                                             grpc::ServerWriter<v1::JobEvent>* writer) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  if (Status s = CheckJobId(req->job_id()); !s.ok()) return Grpc(s);
  auto r = jobs_->Find(req->job_id());
  if (!r.ok()) return Grpc(r.status());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::GetJob(grpc::ServerContext* ctx, const v1::GetJobRequest* req, v1::Job* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  if (Status s = CheckJobId(req->job_id()); !s.ok()) return Grpc(s);
  auto r = jobs_->Find(req->job_id());
  if (!r.ok()) return Grpc(r.status());
  *out = (*r)->Snapshot();
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ListJobs(grpc::ServerContext* ctx, const v1::ListJobsRequest* req,
                                             v1::ListJobsResponse* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto query = MapListJobsRequest(*req);
  if (!query.ok()) return Grpc(query.status());
  const int limit = query->limit;
  auto jobs = store_->ListJobs(query->kind, query->state, limit + 1, query->before_create_ns);
  if (!jobs.ok()) return Grpc(jobs.status());
  for (int i = 0; i < int(jobs->size()) && i < limit; ++i) {
    // Live jobs carry fresher state than their last stored copy.
    const std::shared_ptr<JobRecord> live = jobs_->FindLive((*jobs)[i].job_id());
    *out->add_jobs() = live ? live->Snapshot() : (*jobs)[i];
  }
  if (int(jobs->size()) > limit) out->set_next_page_token(NextPageToken((*jobs)[limit - 1].create_time()));
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::CancelJob(grpc::ServerContext* ctx, const v1::CancelJobRequest* req, v1::Job* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  if (Status s = CheckJobId(req->job_id()); !s.ok()) return Grpc(s);
  auto job = jobs_->Cancel(req->job_id());
  if (!job.ok()) return Grpc(job.status());
  *out = *job;
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::DownloadArtifact(grpc::ServerContext* ctx, const v1::DownloadArtifactRequest* req,
                                                     grpc::ServerWriter<v1::ArtifactChunk>* writer) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto range = MapDownloadRequest(*req);
  if (!range.ok()) return Grpc(range.status());
  auto a = store_->GetArtifact(range->artifact_id);
  if (!a.ok()) return Grpc(a.status());
  const int64_t size = a->artifact.size_bytes();
  if (range->offset > size) {
    return Grpc(Status::OutOfRange("offset " + std::to_string(range->offset) + " is beyond the artifact's size " +
                                   std::to_string(size)));
  }
  std::ifstream in(a->path, std::ios::binary);
  if (!in) return Grpc(Status::DataLoss("artifact file of " + range->artifact_id + " is missing on the server"));
  in.seekg(range->offset);
  const int64_t end = range->limit == 0 ? size : std::min(size, range->offset + range->limit);
  int64_t pos = range->offset;
  std::string buf;
  do {
    const int64_t n = std::min(kMaxChunkBytes, end - pos);
    buf.resize(size_t(n));
    if (n > 0 && !in.read(buf.data(), std::streamsize(n))) {
      return Grpc(Status::DataLoss("artifact file of " + range->artifact_id + " is shorter than recorded"));
    }
    v1::ArtifactChunk chunk;
    chunk.set_artifact_id(range->artifact_id);
    chunk.set_offset(pos);
    chunk.set_data(buf);
    chunk.set_total_size(size);
    chunk.set_sha256(a->artifact.sha256());
    if (!writer->Write(chunk)) return grpc::Status(grpc::StatusCode::CANCELLED, "client stopped reading");
    pos += n;
  } while (pos < end);
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::GetCalibration(grpc::ServerContext* ctx, const v1::GetCalibrationRequest* req,
                                                   v1::Calibration* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto c = calibrations_->Get(req->calibration_id());
  if (!c.ok()) return Grpc(c.status());
  *out = *c;
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ListCalibrations(grpc::ServerContext* ctx, const v1::ListCalibrationsRequest*,
                                                     v1::ListCalibrationsResponse* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto list = calibrations_->List();
  if (!list.ok()) return Grpc(list.status());
  for (const v1::Calibration& c : *list) *out->add_calibrations() = c;
  return grpc::Status::OK;
}

grpc::Status SimulationServiceImpl::ListSpecimens(grpc::ServerContext* ctx, const v1::ListSpecimensRequest*,
                                                  v1::ListSpecimensResponse* out) {
  if (auto a = CheckBearerToken(ctx, options_.auth_token); !a.ok()) return a;
  SimulationControl* sim = rig_->rig().simulation();
  if (!sim) return Grpc(Status::FailedPrecondition("the rig is not simulated"));
  for (const std::string& s : sim->specimen_names()) out->add_specimens(s);
  out->set_current(sim->specimen());
  return grpc::Status::OK;
}

grpc::Status SimulationServiceImpl::SetSpecimen(grpc::ServerContext* ctx, const v1::SetSpecimenRequest* req,
                                                v1::ListSpecimensResponse* out) {
  if (auto a = CheckBearerToken(ctx, options_.auth_token); !a.ok()) return a;
  SimulationControl* sim = rig_->rig().simulation();
  if (!sim) return Grpc(Status::FailedPrecondition("the rig is not simulated"));
  if (Status s = CheckSpecimenName(req->specimen()); !s.ok()) return Grpc(s);
  auto lock = rig_->TryAcquire();
  if (!lock.owns_lock()) return Grpc(Status::Aborted("a rig job is running; change the specimen after it"));
  Status s = sim->SetSpecimen(req->specimen());
  if (!s.ok()) return Grpc(s.code() == StatusCode::kNotFound ? Status::InvalidArgument(s.message()) : s);
  spdlog::info("simulated specimen set to {}", req->specimen());
  for (const std::string& n : sim->specimen_names()) out->add_specimens(n);
  out->set_current(sim->specimen());
  return grpc::Status::OK;
}

}  // namespace inspection
