// Stack and artifact transfer of the gRPC API: an uploaded stack folder received chunk by chunk
// (its frames decoding while the rest arrives, once stack.json parses) and an artifact's file
// sent in chunks. The handlers (inspection_service.cc) only map, submit and stream.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/io/stack.h"
#include "core/io/stack_frame_decoder.h"
#include "core/util/status.h"
#include "inspection/v1/inspection.grpc.pb.h"
#include "server/api/request_mapping.h"
#include "server/jobs/job_work.h"
#include "server/storage/data_store.h"

namespace inspection {

// Starts decoding an upload's frames as their files complete (core/io/stack_frame_decoder.h). The
// decoder exists once stack.json is complete and parses; files completed before that are
// submitted then. A stack.json that does not parse leaves the decoder null: the manifest check
// after the upload names the fault, as before.
class UploadDecoding {
 public:
  UploadDecoding(const std::filesystem::path& dir, const ReconstructPipelineOptions& options)
      : dir_(dir), options_(options) {}

  void FileComplete(const std::string& path);
  std::shared_ptr<StackFrameDecoder> Take() { return std::move(decoder_); }

 private:
  std::filesystem::path dir_;
  ReconstructPipelineOptions options_;
  std::vector<std::string> completed_;  // before stack.json
  std::shared_ptr<StackFrameDecoder> decoder_;
};

// Receives an uploaded stack folder into `dir`, handing each complete file to `decoding`. Errors
// name the file and field at fault.
Status ReceiveUpload(grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>* stream,
                     const ReconstructSource& upload, const std::filesystem::path& dir, int64_t max_bytes,
                     UploadDecoding* decoding);

// Reads and checks the stack in `dir` before a job exists: its manifest (`stored_manifest` when
// the stack is a stored scan's, else dir's stack.json) and every frame. The frames were decoding
// while they arrived (*decoded, from UploadDecoding); the rest decode now, in parallel (a stored
// scan's all of them, through `decode_stored`), and the job's engine takes them from memory in z
// order. Sequential options: decoded here only to check them (*decoded null; the job decodes
// them again). Errors name the file and the field at fault.
Status CheckStackFrames(const std::filesystem::path& dir, const std::optional<StackManifest>& stored_manifest,
                        const ReconstructPipelineOptions& options, const StackFrameDecodeFn& decode_stored,
                        std::shared_ptr<StackFrameDecoder>* decoded);

// A reconstruct pool job's work rebuilt from its stored input (server/jobs/job_manager.h pool
// mode) on a replica that did not receive the request: the stored ReconstructStart and the
// uploaded stack in `stack_dir` on the shared data folder (empty: the request named a stored
// scan, opened again). The frames are checked and decoded as at the upload. DATA_LOSS naming the
// folder when the stored input is gone; the request's own errors as at the upload.
StatusOr<JobWork> RestoreReconstructWork(DataStore& store, const ReconstructPipelineOptions& options,
                                         const QueuedWork& queued, const std::filesystem::path& stack_dir);

// Sends the byte range `range` of a stored artifact's file in chunks of at most kMaxChunkBytes
// through `write` (false: the client stopped reading, CANCELLED). OUT_OF_RANGE for an offset
// beyond the file, DATA_LOSS when the file is missing or shorter than recorded.
Status SendArtifactFile(const StoredArtifact& artifact, const ArtifactRange& range,
                        const std::function<bool(const v1::ArtifactChunk&)>& write);

}  // namespace inspection
