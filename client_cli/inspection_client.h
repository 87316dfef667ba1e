// InspectionClient: the C++ client of the inspection.v1 API, used by inspectctl and by the
// end-to-end tests. Speaks only the proto API (no core/ or devices/ code). Every call returns a
// grpc::Status; long operations follow the job's event stream to its terminal event.
// Thread-compatible: one instance per thread, or external locking.
#pragma once

#include <grpcpp/grpcpp.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "inspection/v1/inspection.grpc.pb.h"

namespace inspection::client {

namespace v1 = ::inspection::v1;

struct ClientOptions {
  std::string target = "127.0.0.1:50051";  // host:port
  std::string tls_ca_file;                 // PEM; empty = plaintext
  std::string tls_client_cert_file;        // PEM; with tls_client_key_file: mTLS client identity
  std::string tls_client_key_file;
  std::string auth_token;  // sent as "authorization: Bearer <token>" when set
  double connect_timeout_seconds = 10.0;
};

using EventCallback = std::function<void(const v1::JobEvent&)>;
// (bytes done, bytes total)
using ByteProgress = std::function<void(int64_t, int64_t)>;
// (file name, bytes done, bytes total)
using FileProgress = std::function<void(const std::string&, int64_t, int64_t)>;

class InspectionClient {
 public:
  explicit InspectionClient(const ClientOptions& options);

  // Waits until the channel is connected or the connect timeout passes (UNAVAILABLE).
  grpc::Status WaitConnected();

  grpc::Status GetRigStatus(v1::RigStatus* status);
  grpc::Status ResetRig(v1::RigStatus* status);

  // Start a job and follow its events until the terminal one. *job receives the final job
  // (also when it failed or was cancelled, if a terminal event arrived). The returned status is
  // the stream's: OK when the job succeeded, else the job's error or the RPC error.
  grpc::Status Scan(const v1::ScanRequest& request, const EventCallback& on_event, v1::Job* job);
  grpc::Status Calibrate(const v1::CalibrateRequest& request, const EventCallback& on_event, v1::Job* job);
  grpc::Status ReconstructStored(const v1::ReconstructStart& start, const EventCallback& on_event, v1::Job* job);
  // Uploads every file of the stack folder (stack.json first, then the frames it lists, then
  // ground_truth_depth.tiff when present) in chunks of at most 1 MiB and follows the
  // reconstruction. start.source is replaced by the upload. A missing or unreadable stack.json
  // or frame file is INVALID_ARGUMENT naming it, before any RPC.
  grpc::Status ReconstructUpload(const std::filesystem::path& stack_dir, v1::ReconstructStart start,
                                 const EventCallback& on_event, v1::Job* job, const ByteProgress& on_upload = {});
  // Re-attach: replays the job's events from the first and follows it to the end.
  grpc::Status Watch(const std::string& job_id, const EventCallback& on_event, v1::Job* job);

  grpc::Status GetJob(const std::string& job_id, v1::Job* job);
  grpc::Status ListJobs(const v1::ListJobsRequest& request, v1::ListJobsResponse* response);
  grpc::Status CancelJob(const std::string& job_id, v1::Job* job);
  // Data lifecycle (role admin): delete a finished job or only a scan's raw stack; pin a job
  // so retention keeps it.
  grpc::Status DeleteJob(const std::string& job_id, v1::DeleteResponse* response);
  grpc::Status DeleteScan(const std::string& scan_id, v1::DeleteResponse* response);
  grpc::Status PinJob(const std::string& job_id, bool pinned, v1::PinJobResponse* response);

  // Downloads an artifact to `dest`. With resume, an existing partial `dest` is continued from
  // its size. The whole file's sha256 is verified against the server's (DATA_LOSS on mismatch,
  // and the file is removed). Writes to dest + ".part" and renames when complete.
  grpc::Status DownloadArtifact(const std::string& artifact_id, const std::filesystem::path& dest, bool resume,
                                const ByteProgress& on_progress = {});
  // Raw chunk stream for callers that manage bytes themselves (tests, partial reads).
  grpc::Status DownloadRange(const std::string& artifact_id, int64_t offset, int64_t limit, std::string* data,
                             std::string* sha256_hex, int64_t* total_size);

  // Downloads the result artifacts of a succeeded job into dir under their file names
  // (depth.tiff, confidence.tiff, all_in_focus.png, depth_preview.png and any extras; the
  // stack zip only when include_stack). Returns the written paths. With resume, partial
  // downloads (".part") continue; on_progress is called per file as bytes arrive.
  grpc::Status DownloadResults(const v1::Job& job, const std::filesystem::path& dir, bool include_stack,
                               std::vector<std::filesystem::path>* written, bool resume = false,
                               const FileProgress& on_progress = {});

  grpc::Status GetCalibration(const std::string& calibration_id, v1::Calibration* calibration);
  grpc::Status ListCalibrations(v1::ListCalibrationsResponse* response);

  grpc::Status ListSpecimens(v1::ListSpecimensResponse* response);
  grpc::Status SetSpecimen(const std::string& specimen, v1::ListSpecimensResponse* response);

  // Recipes (inspection_client_recipes.cc). version 0 = the current one.
  grpc::Status CreateRecipe(const v1::Recipe& recipe, v1::Recipe* stored);
  grpc::Status UpdateRecipe(const v1::Recipe& recipe, int expected_version, v1::Recipe* stored);
  grpc::Status GetRecipe(const std::string& recipe_id, int version, v1::Recipe* recipe);
  grpc::Status ListRecipes(v1::ListRecipesResponse* response);
  grpc::Status DeleteRecipe(const std::string& recipe_id, v1::DeleteResponse* response);
  // Inspection results (ListResults with the request's filters and page).
  grpc::Status ListResults(const v1::ListResultsRequest& request, v1::ListResultsResponse* response);
  // Follows the result feed from after_sequence; on_result returns false to stop (the call then
  // ends OK). Without a stop it runs until the server ends the stream.
  grpc::Status WatchResults(int64_t after_sequence, const std::function<bool(const v1::InspectionResult&)>& on_result);

  // Type-1 gauge studies (inspection_client_study.cc): StartStudy follows the study job like Scan.
  grpc::Status StartStudy(const v1::StartStudyRequest& request, const EventCallback& on_event, v1::Job* job);
  grpc::Status GetStudy(const std::string& study_id, v1::Study* study);
  grpc::Status ListStudies(const v1::ListStudiesRequest& request, v1::ListStudiesResponse* response);
  // Instrument verification (inspection_client_verify.cc): follows the Verify job like Calibrate.
  grpc::Status Verify(const v1::VerifyRequest& request, const EventCallback& on_event, v1::Job* job);

  std::shared_ptr<grpc::Channel> channel() const { return channel_; }

 private:
  void Prepare(grpc::ClientContext* ctx) const;
  // Credentials and the unary deadline: every unary call's context.
  void PrepareUnary(grpc::ClientContext* ctx) const;
  // One unary call of either service: the options' error if they are unusable, else the call
  // with PrepareUnary's context.
  template <typename Stub, typename Request, typename Response>
  grpc::Status Unary(grpc::Status (Stub::*call)(grpc::ClientContext*, const Request&, Response*),
                     const Request& request, Response* response) {
    if (!init_status_.ok()) return init_status_;
    grpc::ClientContext ctx;
    PrepareUnary(&ctx);
    Stub* stub;
    if constexpr (std::is_same_v<Stub, v1::SimulationService::Stub>) {
      stub = sim_stub_.get();
    } else {
      stub = stub_.get();
    }
    return (stub->*call)(&ctx, request, response);
  }
  grpc::Status FollowStream(grpc::ClientReaderInterface<v1::JobEvent>* reader, const EventCallback& on_event,
                            v1::Job* job);

  ClientOptions options_;
  // Set when the options cannot be used (e.g. an unreadable CA file); every call returns it.
  grpc::Status init_status_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::InspectionService::Stub> stub_;
  std::unique_ptr<v1::SimulationService::Stub> sim_stub_;
};

}  // namespace inspection::client
