#include "server/inspection_service.h"

#include <cctype>
#include <fstream>
#include <map>
#include <openssl/crypto.h>

#include <spdlog/spdlog.h>

#include "core/stack.h"
#include "server/grpc_status.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {

constexpr int64_t kChunkBytes = 1 << 20;  // 1 MiB: far below gRPC's 4 MiB message limit

grpc::Status Grpc(const Status& s) { return ToGrpcStatus(s); }

// The status a job's stream ends with, once its terminal event was sent.
grpc::Status FinalStatus(const v1::Job& job) {
  switch (job.state()) {
    case v1::JOB_STATE_SUCCEEDED: return grpc::Status::OK;
    case v1::JOB_STATE_CANCELLED: return grpc::Status(grpc::StatusCode::CANCELLED, job.error_message());
    default:
      return grpc::Status(static_cast<grpc::StatusCode>(job.error_code() ? job.error_code() : int(StatusCode::kUnknown)),
                          job.error_message());
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
  return FinalStatus(r->Snapshot());
}

// Ids become folder names: accept only what NewId produces.
bool SafeId(const std::string& id) {
  if (id.empty() || id.size() > 128) return false;
  for (char c : id) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_')) return false;
  }
  return true;
}

Status CheckUploadPath(const std::string& path) {
  if (path.empty()) return Status::InvalidArgument("file_chunk.path is empty");
  fs::path p(path);
  if (p.is_absolute()) return Status::InvalidArgument("file_chunk.path '" + path + "' must be relative");
  for (const auto& part : p) {
    if (part == ".." || part == ".") return Status::InvalidArgument("file_chunk.path '" + path + "' must not contain '.' or '..'");
  }
  return Status::Ok();
}

// Receives an uploaded stack folder into `dir`. Errors name the file and field at fault.
Status ReceiveUpload(grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>* stream,
                     const v1::StackUpload& upload, const fs::path& dir, int64_t max_bytes) {
  if (upload.total_bytes() < 0 || upload.total_bytes() > max_bytes) {
    return Status::InvalidArgument("start.upload.total_bytes must be between 0 and " + std::to_string(max_bytes));
  }
  if (upload.file_count() < 0) return Status::InvalidArgument("start.upload.file_count must be >= 0");
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
    INSPECT_RETURN_IF_ERROR(CheckUploadPath(c.path()));
    if (int64_t(c.data().size()) > kChunkBytes) {
      return Status::InvalidArgument("file_chunk.data of '" + c.path() + "' exceeds 1 MiB");
    }
    if (complete[c.path()]) return Status::InvalidArgument("file '" + c.path() + "' was already completed");
    if (c.offset() != sizes[c.path()]) {
      return Status::InvalidArgument("file_chunk.offset " + std::to_string(c.offset()) + " of '" + c.path() +
                                     "' does not continue the file at " + std::to_string(sizes[c.path()]));
    }
    total += int64_t(c.data().size());
    if (total > max_bytes || (upload.total_bytes() > 0 && total > upload.total_bytes())) {
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
  if (upload.file_count() > 0 && int(sizes.size()) != upload.file_count()) {
    return Status::InvalidArgument("received " + std::to_string(sizes.size()) + " files but start.upload.file_count is " +
                                   std::to_string(upload.file_count()));
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
  st->set_active_calibration_id(jobs_->active_calibration_id());
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
  auto r = jobs_->SubmitScan(*req);
  if (!r.ok()) return Grpc(r.status());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::Calibrate(grpc::ServerContext* ctx, const v1::CalibrateRequest* req,
                                              grpc::ServerWriter<v1::JobEvent>* writer) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto r = jobs_->SubmitCalibrate(*req);
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
  fs::path dir;
  bool owns = false;
  if (start.has_scan_id()) {
    if (!SafeId(start.scan_id())) return Grpc(Status::InvalidArgument("start.scan_id '" + start.scan_id() + "' is malformed"));
    dir = jobs_->ScanDir(start.scan_id());
    if (!fs::is_directory(dir)) return Grpc(Status::NotFound("scan_id '" + start.scan_id() + "' not found"));
  } else if (start.has_upload()) {
    dir = store_->uploads_dir() / NewId("upload");
    owns = true;
    Status s = ReceiveUpload(stream, start.upload(), dir, options_.max_upload_bytes);
    if (!s.ok()) {
      std::error_code ec;
      fs::remove_all(dir, ec);
      return Grpc(s);
    }
  } else {
    return Grpc(Status::InvalidArgument("start.source must be scan_id or upload"));
  }
  // Validate the whole stack before a job exists: bad input never becomes a failed job.
  auto manifest = ReadStackManifest(dir);
  Status valid = manifest.ok() ? ValidateStackFrames(dir, *manifest) : manifest.status();
  if (!valid.ok()) {
    if (owns) {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
    return Grpc(valid);
  }
  auto r = jobs_->SubmitReconstruct(start, dir, owns);
  if (!r.ok()) return Grpc(r.status());
  return StreamJob(ctx, *r, stream);
}

grpc::Status InspectionServiceImpl::WatchJob(grpc::ServerContext* ctx, const v1::WatchJobRequest* req,
                                             grpc::ServerWriter<v1::JobEvent>* writer) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto r = jobs_->Find(req->job_id());
  if (!r.ok()) return Grpc(r.status());
  return StreamJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::GetJob(grpc::ServerContext* ctx, const v1::GetJobRequest* req, v1::Job* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto r = jobs_->Find(req->job_id());
  if (!r.ok()) return Grpc(r.status());
  *out = (*r)->Snapshot();
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ListJobs(grpc::ServerContext* ctx, const v1::ListJobsRequest* req,
                                             v1::ListJobsResponse* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  if (req->page_size() < 0) return Grpc(Status::InvalidArgument("page_size must be >= 0"));
  const int limit = req->page_size() == 0 ? 50 : std::min(req->page_size(), 500);
  int64_t before = 0;
  if (!req->page_token().empty()) {
    try {
      before = std::stoll(req->page_token());
    } catch (...) {
      return Grpc(Status::InvalidArgument("page_token is malformed"));
    }
  }
  auto jobs = store_->ListJobs(req->kind(), req->state(), limit + 1, before);
  if (!jobs.ok()) return Grpc(jobs.status());
  for (int i = 0; i < int(jobs->size()) && i < limit; ++i) {
    // Live jobs carry fresher state than their last stored copy.
    auto live = jobs_->Find((*jobs)[i].job_id());
    *out->add_jobs() = live.ok() ? (*live)->Snapshot() : (*jobs)[i];
  }
  if (int(jobs->size()) > limit) {
    const auto& t = (*jobs)[limit - 1].create_time();
    out->set_next_page_token(std::to_string(t.seconds() * 1000000000LL + t.nanos()));
  }
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::CancelJob(grpc::ServerContext* ctx, const v1::CancelJobRequest* req, v1::Job* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto job = jobs_->Cancel(req->job_id());
  if (!job.ok()) return Grpc(job.status());
  *out = *job;
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::DownloadArtifact(grpc::ServerContext* ctx, const v1::DownloadArtifactRequest* req,
                                                     grpc::ServerWriter<v1::ArtifactChunk>* writer) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  if (req->artifact_id().empty()) return Grpc(Status::InvalidArgument("artifact_id is empty"));
  if (req->offset() < 0) return Grpc(Status::InvalidArgument("offset must be >= 0"));
  if (req->limit() < 0) return Grpc(Status::InvalidArgument("limit must be >= 0 (0 = to the end)"));
  auto a = store_->GetArtifact(req->artifact_id());
  if (!a.ok()) return Grpc(a.status());
  const int64_t size = a->artifact.size_bytes();
  if (req->offset() > size) {
    return Grpc(Status::OutOfRange("offset " + std::to_string(req->offset()) + " is beyond the artifact's size " +
                                   std::to_string(size)));
  }
  std::ifstream in(a->path, std::ios::binary);
  if (!in) return Grpc(Status::DataLoss("artifact file of " + req->artifact_id() + " is missing on the server"));
  in.seekg(req->offset());
  const int64_t end = req->limit() == 0 ? size : std::min(size, req->offset() + req->limit());
  int64_t pos = req->offset();
  std::string buf;
  do {
    const int64_t n = std::min(kChunkBytes, end - pos);
    buf.resize(size_t(n));
    if (n > 0 && !in.read(buf.data(), std::streamsize(n))) {
      return Grpc(Status::DataLoss("artifact file of " + req->artifact_id() + " is shorter than recorded"));
    }
    v1::ArtifactChunk chunk;
    chunk.set_artifact_id(req->artifact_id());
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
  std::string id = req->calibration_id();
  const std::string active = jobs_->active_calibration_id();
  if (id.empty()) {
    if (active.empty()) return Grpc(Status::NotFound("no calibration is active; run Calibrate"));
    id = active;
  }
  auto c = store_->GetCalibration(id);
  if (!c.ok()) return Grpc(c.status());
  *out = *c;
  out->set_active(id == active);
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ListCalibrations(grpc::ServerContext* ctx, const v1::ListCalibrationsRequest*,
                                                     v1::ListCalibrationsResponse* out) {
  if (auto a = CheckAuth(ctx); !a.ok()) return a;
  auto list = store_->ListCalibrations();
  if (!list.ok()) return Grpc(list.status());
  const std::string active = jobs_->active_calibration_id();
  for (auto& c : *list) {
    c.set_active(c.calibration_id() == active);
    *out->add_calibrations() = c;
  }
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
  if (req->specimen().empty()) return Grpc(Status::InvalidArgument("specimen is empty"));
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
