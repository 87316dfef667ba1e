// Upload reception and artifact sending (stack_transfer.h).
#include "server/api/stack_transfer.h"

#include <algorithm>
#include <cerrno>
#include <fstream>
#include <map>

#include "core/io/stack.h"
#include "server/storage/data_lifecycle.h"
#include "server/storage/stored_stack.h"

namespace inspection {
namespace fs = std::filesystem;

void UploadDecoding::FileComplete(const std::string& path) {
  if (options_.sequential) return;
  if (decoder_) {
    decoder_->SubmitFile(path);
    return;
  }
  if (path != kStackManifestName) {
    completed_.push_back(path);
    return;
  }
  std::ifstream in(dir_ / path, std::ios::binary);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto manifest = ParseStackManifest(text);
  if (!manifest.ok()) return;
  StackFrameDecoderOptions o;
  o.threads = options_.decode_threads;
  o.max_kept_bytes = options_.max_decoded_bytes;
  decoder_ = std::make_shared<StackFrameDecoder>(dir_, std::move(manifest).value(), o);
  for (const std::string& f : completed_) decoder_->SubmitFile(f);
  completed_.clear();
}

Status ReceiveUpload(grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>* stream,
                     const ReconstructSource& upload, const fs::path& dir, int64_t max_bytes,
                     UploadDecoding* decoding) {
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
    INSPECT_RETURN_IF_ERROR(CheckRequestTextLimits(msg));
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
    errno = 0;
    if (!out.write(c.data().data(), std::streamsize(c.data().size())) || !out.flush()) {
      // ENOSPC: RESOURCE_EXHAUSTED "data disk full"; the upload folder goes with the request.
      return WriteFailure(errno ? errno : EIO, "cannot write uploaded file '" + c.path() + "'");
    }
    out.close();  // on disk before a decode thread opens it
    sizes[c.path()] += int64_t(c.data().size());
    if (c.last()) {
      complete[c.path()] = true;
      decoding->FileComplete(c.path());
    }
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

Status CheckStackFrames(const fs::path& dir, const std::optional<StackManifest>& stored_manifest,
                        const ReconstructPipelineOptions& options, const StackFrameDecodeFn& decode_stored,
                        std::shared_ptr<StackFrameDecoder>* decoded) {
  auto manifest = stored_manifest ? StatusOr<StackManifest>(*stored_manifest) : ReadStackManifest(dir);
  if (!manifest.ok()) return manifest.status();
  if (options.sequential) {
    decoded->reset();
    return ValidateStackFrames(dir, *manifest);
  }
  if (!*decoded) {
    StackFrameDecoderOptions o;
    o.threads = options.decode_threads;
    o.max_kept_bytes = options.max_decoded_bytes;
    *decoded = std::make_shared<StackFrameDecoder>(dir, *manifest, o, decode_stored);
  }
  return (*decoded)->Finish();
}

StatusOr<JobWork> RestoreReconstructWork(DataStore& store, const ReconstructPipelineOptions& options,
                                         const QueuedWork& queued, const fs::path& stack_dir) {
  v1::ReconstructStart start;
  if (!start.ParseFromString(queued.input)) {
    return Status::DataLoss("the stored request of job " + queued.job_id + " is corrupt");
  }
  fs::path dir = stack_dir;
  std::shared_ptr<OwnedFolder> folder;
  std::optional<StackManifest> stored_manifest;
  StackFrameDecodeFn decode_stored;
  if (stack_dir.empty()) {
    if (start.scan_id().empty()) return Status::DataLoss("the stored request of job " + queued.job_id + " names no stack");
    INSPECT_ASSIGN_OR_RETURN(StoredStack stored,
                             OpenStoredStack(store, start.scan_id(),
                                             options.sequential ? StoredFrames::kExtracted : StoredFrames::kInMemory));
    dir = stored.dir;
    folder = std::move(stored.extraction);
    stored_manifest = std::move(stored.manifest);
    decode_stored = std::move(stored.decode);
  } else {
    std::error_code ec;
    if (!fs::is_regular_file(stack_dir / kStackManifestName, ec)) {
      return Status::DataLoss("the stored input of job " + queued.job_id + " (" + stack_dir.string() +
                              ") is gone from the shared data folder");
    }
    folder = std::make_shared<OwnedFolder>(stack_dir);
  }
  std::shared_ptr<StackFrameDecoder> decoded;
  INSPECT_RETURN_IF_ERROR(CheckStackFrames(dir, stored_manifest, options, decode_stored, &decoded));
  INSPECT_ASSIGN_OR_RETURN(ReconstructWork work, MapReconstructStart(start, dir, folder));
  work.decoded = std::move(decoded);
  work.pool_input = queued.input;
  return JobWork(std::move(work));
}

Status SendArtifactFile(const StoredArtifact& artifact, const ArtifactRange& range,
                        const std::function<bool(const v1::ArtifactChunk&)>& write) {
  const int64_t size = artifact.artifact.size_bytes();
  if (range.offset > size) {
    return Status::OutOfRange("offset " + std::to_string(range.offset) + " is beyond the artifact's size " +
                              std::to_string(size));
  }
  std::ifstream in(artifact.path, std::ios::binary);
  if (!in) return Status::DataLoss("artifact file of " + range.artifact_id + " is missing on the server");
  in.seekg(range.offset);
  const int64_t end = range.limit == 0 ? size : std::min(size, range.offset + range.limit);
  int64_t pos = range.offset;
  std::string buf;
  do {
    const int64_t n = std::min(kMaxChunkBytes, end - pos);
    buf.resize(size_t(n));
    if (n > 0 && !in.read(buf.data(), std::streamsize(n))) {
      return Status::DataLoss("artifact file of " + range.artifact_id + " is shorter than recorded");
    }
    v1::ArtifactChunk chunk;
    chunk.set_artifact_id(range.artifact_id);
    chunk.set_offset(pos);
    chunk.set_data(buf);
    chunk.set_total_size(size);
    chunk.set_sha256(artifact.artifact.sha256());
    if (!write(chunk)) return Status::Cancelled("client stopped reading");
    pos += n;
  } while (pos < end);
  return Status::Ok();
}

}  // namespace inspection
