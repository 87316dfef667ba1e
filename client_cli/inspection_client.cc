// InspectionClient: channel set-up (plaintext or TLS, bearer token), job-event following,
// chunked stack upload and resumable, sha256-verified artifact download for inspection.v1.
#include "client_cli/inspection_client.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <system_error>
#include <thread>

#include "client_cli/channel_credentials.h"
#include "client_cli/stack_files.h"
#include "common/sha256_file.h"

namespace inspection::client {
namespace {

namespace fs = std::filesystem;

// The proto's chunk limit for uploads and downloads.
constexpr size_t kChunkBytes = size_t{1} << 20;
// Unary calls are short; a deadline keeps a hung server from hanging the caller forever.
constexpr auto kUnaryTimeout = std::chrono::seconds(120);

bool IsTerminal(v1::JobState state) {
  return state == v1::JOB_STATE_SUCCEEDED || state == v1::JOB_STATE_FAILED || state == v1::JOB_STATE_CANCELLED;
}

std::string ToLower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

void SetUnaryDeadline(grpc::ClientContext* ctx) { ctx->set_deadline(std::chrono::system_clock::now() + kUnaryTimeout); }

}  // namespace

InspectionClient::InspectionClient(const ClientOptions& options) : options_(options) {
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  init_status_ = ChannelCredentialsFor(options_, &credentials);
  grpc::ChannelArguments args;
  // Chunks are at most 1 MiB; leave room for the envelope and a large terminal event.
  args.SetMaxReceiveMessageSize(16 << 20);
  channel_ = grpc::CreateCustomChannel(options_.target, credentials, args);
  stub_ = v1::InspectionService::NewStub(channel_);
  sim_stub_ = v1::SimulationService::NewStub(channel_);
}

void InspectionClient::Prepare(grpc::ClientContext* ctx) const {
  if (!options_.auth_token.empty()) ctx->AddMetadata("authorization", "Bearer " + options_.auth_token);
}

grpc::Status InspectionClient::WaitConnected() {
  if (!init_status_.ok()) return init_status_;
  const auto deadline = std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<int64_t>(options_.connect_timeout_seconds * 1000.0));
  if (!channel_->WaitForConnected(deadline)) {
    std::ostringstream msg;
    msg << "cannot connect to " << options_.target << " within " << options_.connect_timeout_seconds << " s";
    return {grpc::StatusCode::UNAVAILABLE, msg.str()};
  }
  return grpc::Status::OK;
}

grpc::Status InspectionClient::FollowStream(grpc::ClientReaderInterface<v1::JobEvent>* reader,
                                            const EventCallback& on_event, v1::Job* job) {
  v1::JobEvent event;
  while (reader->Read(&event)) {
    if (on_event) on_event(event);
    if (IsTerminal(event.state()) && event.has_job() && job != nullptr) *job = event.job();
  }
  return reader->Finish();
}

grpc::Status InspectionClient::GetRigStatus(v1::RigStatus* status) {
  return Unary(&v1::InspectionService::Stub::GetRigStatus, v1::GetRigStatusRequest(), status);
}

grpc::Status InspectionClient::ResetRig(v1::RigStatus* status) {
  return Unary(&v1::InspectionService::Stub::ResetRig, v1::ResetRigRequest(), status);
}

grpc::Status InspectionClient::Scan(const v1::ScanRequest& request, const EventCallback& on_event, v1::Job* job) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  Prepare(&ctx);
  auto reader = stub_->Scan(&ctx, request);
  return FollowStream(reader.get(), on_event, job);
}

grpc::Status InspectionClient::Calibrate(const v1::CalibrateRequest& request, const EventCallback& on_event,
                                         v1::Job* job) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  Prepare(&ctx);
  auto reader = stub_->Calibrate(&ctx, request);
  return FollowStream(reader.get(), on_event, job);
}

grpc::Status InspectionClient::ReconstructStored(const v1::ReconstructStart& start, const EventCallback& on_event,
                                                 v1::Job* job) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  Prepare(&ctx);
  auto stream = stub_->Reconstruct(&ctx);
  v1::ReconstructRequest first;
  *first.mutable_start() = start;
  // A failed write means the server already ended the call; Finish below reports why.
  if (stream->Write(first)) stream->WritesDone();
  v1::JobEvent event;
  while (stream->Read(&event)) {
    if (on_event) on_event(event);
    if (IsTerminal(event.state()) && event.has_job() && job != nullptr) *job = event.job();
  }
  return stream->Finish();
}

grpc::Status InspectionClient::ReconstructUpload(const std::filesystem::path& stack_dir, v1::ReconstructStart start,
                                                 const EventCallback& on_event, v1::Job* job,
                                                 const ByteProgress& on_upload) {
  if (!init_status_.ok()) return init_status_;
  std::vector<UploadFile> files;
  if (grpc::Status listed = ListStackFiles(stack_dir, &files); !listed.ok()) return listed;
  int64_t total_bytes = 0;
  for (const auto& f : files) total_bytes += f.size_bytes;
  start.mutable_upload()->set_file_count(static_cast<int32_t>(files.size()));
  start.mutable_upload()->set_total_bytes(total_bytes);

  grpc::ClientContext ctx;
  Prepare(&ctx);
  auto stream = stub_->Reconstruct(&ctx);

  // Events are read on their own thread: the server may answer (or reject) while the upload is
  // still being written, and neither side should wait on the other's flow-control window.
  v1::Job terminal_job;
  bool have_terminal = false;
  std::thread reader([&] {
    v1::JobEvent event;
    while (stream->Read(&event)) {
      if (on_event) on_event(event);
      if (IsTerminal(event.state()) && event.has_job()) {
        terminal_job = event.job();
        have_terminal = true;
      }
    }
  });

  grpc::Status local_error = grpc::Status::OK;
  bool stream_open = true;
  {
    v1::ReconstructRequest first;
    *first.mutable_start() = start;
    stream_open = stream->Write(first);
  }
  int64_t sent_bytes = 0;
  // One message for every chunk, the file read straight into its data field: the buffer keeps
  // its capacity from chunk to chunk (no copy into the message, no fresh megabyte per chunk).
  v1::ReconstructRequest msg;
  v1::StackFileChunk* chunk = msg.mutable_file_chunk();
  std::string* data = chunk->mutable_data();
  for (size_t i = 0; stream_open && local_error.ok() && i < files.size(); ++i) {
    const UploadFile& file = files[i];
    std::ifstream in(file.path, std::ios::binary);
    if (!in) {
      local_error =
          grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, file.relative + ": cannot open " + file.path.string());
      break;
    }
    int64_t offset = 0;
    // Empty files still send one (empty, last) chunk so the server sees every listed file.
    do {
      data->resize(kChunkBytes);
      in.read(data->data(), static_cast<std::streamsize>(kChunkBytes));
      const std::streamsize n = in.gcount();
      if (in.bad()) {
        local_error = grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, file.relative + ": read error");
        break;
      }
      data->resize(static_cast<size_t>(n));
      chunk->set_path(file.relative);
      chunk->set_offset(offset);
      offset += n;
      chunk->set_last(offset >= file.size_bytes || in.eof());
      const bool last = chunk->last();
      if (!stream->Write(msg)) {
        stream_open = false;
        break;
      }
      sent_bytes += n;
      if (on_upload) on_upload(sent_bytes, total_bytes);
      if (last) break;
    } while (true);
  }
  if (!local_error.ok()) {
    // Tell the server the upload is abandoned; its stream ends CANCELLED and the reader stops.
    ctx.TryCancel();
  } else if (stream_open) {
    stream->WritesDone();
  }
  reader.join();
  grpc::Status status = stream->Finish();
  if (have_terminal && job != nullptr) *job = terminal_job;
  if (!local_error.ok()) return local_error;
  return status;
}

grpc::Status InspectionClient::Watch(const std::string& job_id, const EventCallback& on_event, v1::Job* job) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  Prepare(&ctx);
  v1::WatchJobRequest request;
  request.set_job_id(job_id);
  auto reader = stub_->WatchJob(&ctx, request);
  return FollowStream(reader.get(), on_event, job);
}

grpc::Status InspectionClient::GetJob(const std::string& job_id, v1::Job* job) {
  v1::GetJobRequest request;
  request.set_job_id(job_id);
  return Unary(&v1::InspectionService::Stub::GetJob, request, job);
}

grpc::Status InspectionClient::ListJobs(const v1::ListJobsRequest& request, v1::ListJobsResponse* response) {
  return Unary(&v1::InspectionService::Stub::ListJobs, request, response);
}

grpc::Status InspectionClient::CancelJob(const std::string& job_id, v1::Job* job) {
  v1::CancelJobRequest request;
  request.set_job_id(job_id);
  return Unary(&v1::InspectionService::Stub::CancelJob, request, job);
}

grpc::Status InspectionClient::DeleteJob(const std::string& job_id, v1::DeleteResponse* response) {
  v1::DeleteJobRequest request;
  request.set_job_id(job_id);
  return Unary(&v1::InspectionService::Stub::DeleteJob, request, response);
}

grpc::Status InspectionClient::DeleteScan(const std::string& scan_id, v1::DeleteResponse* response) {
  v1::DeleteScanRequest request;
  request.set_scan_id(scan_id);
  return Unary(&v1::InspectionService::Stub::DeleteScan, request, response);
}

grpc::Status InspectionClient::PinJob(const std::string& job_id, bool pinned, v1::PinJobResponse* response) {
  v1::PinJobRequest request;
  request.set_job_id(job_id);
  request.set_pinned(pinned);
  return Unary(&v1::InspectionService::Stub::PinJob, request, response);
}

grpc::Status InspectionClient::DownloadRange(const std::string& artifact_id, int64_t offset, int64_t limit,
                                             std::string* data, std::string* sha256_hex, int64_t* total_size) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  Prepare(&ctx);
  v1::DownloadArtifactRequest request;
  request.set_artifact_id(artifact_id);
  request.set_offset(offset);
  request.set_limit(limit);
  auto reader = stub_->DownloadArtifact(&ctx, request);
  v1::ArtifactChunk chunk;
  if (data != nullptr) data->clear();
  int64_t expected_offset = offset;
  bool out_of_order = false;
  while (reader->Read(&chunk)) {
    if (chunk.offset() != expected_offset) {
      out_of_order = true;
      ctx.TryCancel();
      break;
    }
    expected_offset += static_cast<int64_t>(chunk.data().size());
    if (data != nullptr) data->append(chunk.data());
    if (sha256_hex != nullptr && !chunk.sha256().empty()) *sha256_hex = chunk.sha256();
    if (total_size != nullptr) *total_size = chunk.total_size();
  }
  grpc::Status status = reader->Finish();
  if (out_of_order) {
    return {grpc::StatusCode::DATA_LOSS, "artifact " + artifact_id + ": chunk at offset " +
                                             std::to_string(chunk.offset()) + ", expected " +
                                             std::to_string(expected_offset)};
  }
  return status;
}

grpc::Status InspectionClient::DownloadArtifact(const std::string& artifact_id, const std::filesystem::path& dest,
                                                bool resume, const ByteProgress& on_progress) {
  if (!init_status_.ok()) return init_status_;
  const fs::path part = fs::path(dest.string() + ".part");
  std::error_code ec;
  if (dest.has_parent_path()) fs::create_directories(dest.parent_path(), ec);

  int64_t offset = 0;
  if (resume && fs::is_regular_file(part, ec)) offset = static_cast<int64_t>(fs::file_size(part, ec));
  if (ec) offset = 0;

  std::string sha256_expected;
  int64_t total_size = -1;
  for (int attempt = 0; attempt < 2; ++attempt) {
    std::ofstream out(part, std::ios::binary | (offset > 0 ? std::ios::app : std::ios::trunc));
    if (!out) return {grpc::StatusCode::INTERNAL, "cannot write " + part.string()};

    grpc::ClientContext ctx;
    Prepare(&ctx);
    v1::DownloadArtifactRequest request;
    request.set_artifact_id(artifact_id);
    request.set_offset(offset);
    auto reader = stub_->DownloadArtifact(&ctx, request);
    v1::ArtifactChunk chunk;
    int64_t written = offset;
    grpc::Status local_error = grpc::Status::OK;
    while (reader->Read(&chunk)) {
      if (chunk.offset() != written) {
        local_error = grpc::Status(grpc::StatusCode::DATA_LOSS, "artifact " + artifact_id + ": chunk at offset " +
                                                                    std::to_string(chunk.offset()) + ", expected " +
                                                                    std::to_string(written));
        ctx.TryCancel();
        break;
      }
      out.write(chunk.data().data(), static_cast<std::streamsize>(chunk.data().size()));
      if (!out) {
        local_error = grpc::Status(grpc::StatusCode::INTERNAL, "write error on " + part.string());
        ctx.TryCancel();
        break;
      }
      written += static_cast<int64_t>(chunk.data().size());
      if (!chunk.sha256().empty()) sha256_expected = chunk.sha256();
      total_size = chunk.total_size();
      if (on_progress) on_progress(written, total_size);
    }
    grpc::Status status = reader->Finish();
    out.close();
    if (!local_error.ok()) return local_error;
    // A stale .part longer than the artifact: start over once from byte 0.
    if (status.error_code() == grpc::StatusCode::OUT_OF_RANGE && offset > 0 && attempt == 0) {
      offset = 0;
      continue;
    }
    // Keep the .part on RPC errors so a later --resume continues it, unless nothing was ever
    // received (e.g. NOT_FOUND): an empty .part would only be litter.
    if (!status.ok()) {
      if (written == 0) fs::remove(part, ec);
      return status;
    }
    break;
  }

  if (sha256_expected.empty()) {
    // Resumed a .part that was already complete: the server sent no chunk, so ask for the
    // artifact's metadata with a one-byte range.
    grpc::Status meta = DownloadRange(artifact_id, 0, 1, nullptr, &sha256_expected, &total_size);
    if (!meta.ok()) return meta;
    if (sha256_expected.empty()) {
      return {grpc::StatusCode::DATA_LOSS, "artifact " + artifact_id + ": server sent no sha256"};
    }
  }
  const int64_t part_size = static_cast<int64_t>(fs::file_size(part, ec));
  std::string hash_error;
  const std::optional<std::string> hashed = Sha256FileHex(part, &hash_error);
  const std::string actual = hashed ? *hashed : "unknown (" + hash_error + ")";
  if (ec || !hashed || (total_size >= 0 && part_size != total_size) || actual != ToLower(sha256_expected)) {
    fs::remove(part, ec);
    std::ostringstream msg;
    msg << "artifact " << artifact_id << ": integrity check failed (" << part_size << " of " << total_size
        << " bytes, sha256 " << actual << ", expected " << ToLower(sha256_expected) << "); partial file removed";
    return {grpc::StatusCode::DATA_LOSS, msg.str()};
  }
  fs::rename(part, dest, ec);
  if (ec)
    return {grpc::StatusCode::INTERNAL,
            "cannot rename " + part.string() + " to " + dest.string() + ": " + ec.message()};
  return grpc::Status::OK;
}

grpc::Status InspectionClient::DownloadResults(const v1::Job& job, const std::filesystem::path& dir, bool include_stack,
                                               std::vector<std::filesystem::path>* written, bool resume,
                                               const FileProgress& on_progress) {
  if (!init_status_.ok()) return init_status_;
  if (job.state() != v1::JOB_STATE_SUCCEEDED) {
    return {grpc::StatusCode::FAILED_PRECONDITION,
            "job " + job.job_id() + " is " + v1::JobState_Name(job.state()) + "; only a succeeded job has results"};
  }
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return {grpc::StatusCode::INTERNAL, "cannot create " + dir.string() + ": " + ec.message()};
  for (const v1::Artifact& artifact : job.result().artifacts()) {
    if (artifact.kind() == v1::ARTIFACT_KIND_STACK_ZIP && !include_stack) continue;
    // Only the last component of the server's suggested name: never write outside dir.
    std::string name = fs::path(artifact.file_name()).filename().string();
    if (name.empty() || name == "." || name == "..") name = artifact.artifact_id();
    const fs::path dest = dir / name;
    ByteProgress progress;
    if (on_progress) progress = [&](int64_t done, int64_t total) { on_progress(name, done, total); };
    grpc::Status status = DownloadArtifact(artifact.artifact_id(), dest, resume, progress);
    if (!status.ok()) return status;
    if (written != nullptr) written->push_back(dest);
  }
  return grpc::Status::OK;
}

grpc::Status InspectionClient::GetCalibration(const std::string& calibration_id, v1::Calibration* calibration) {
  v1::GetCalibrationRequest request;
  request.set_calibration_id(calibration_id);
  return Unary(&v1::InspectionService::Stub::GetCalibration, request, calibration);
}

grpc::Status InspectionClient::ListCalibrations(v1::ListCalibrationsResponse* response) {
  return Unary(&v1::InspectionService::Stub::ListCalibrations, v1::ListCalibrationsRequest(), response);
}

grpc::Status InspectionClient::ListSpecimens(v1::ListSpecimensResponse* response) {
  return Unary(&v1::SimulationService::Stub::ListSpecimens, v1::ListSpecimensRequest(), response);
}

grpc::Status InspectionClient::SetSpecimen(const std::string& specimen, v1::ListSpecimensResponse* response) {
  v1::SetSpecimenRequest request;
  request.set_specimen(specimen);
  return Unary(&v1::SimulationService::Stub::SetSpecimen, request, response);
}

void InspectionClient::PrepareUnary(grpc::ClientContext* ctx) const {
  Prepare(ctx);
  SetUnaryDeadline(ctx);
}

}  // namespace inspection::client
