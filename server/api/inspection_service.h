// gRPC handlers of inspection.v1.InspectionService and SimulationService. Who may call what is
// decided before a handler runs (server/security/call_authorization.h); a handler takes the
// verdict with CallerOf and names no method and no role. Thin: requests go
// through the request mapping (request_mapping.h, which validates and names the field), work
// goes to the JobManager, and a JobRecord's events are streamed back. Every error leaves as a
// gRPC status built by ToGrpcStatus (grpc_status.h); no exception crosses this boundary.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "inspection/v1/inspection.grpc.pb.h"
#include "server/jobs/job_manager.h"
#include "server/jobs/retention_sweeper.h"
#include "server/jobs/rig_controller.h"
#include "server/results/result_feed.h"
#include "server/security/access_control.h"
#include "server/storage/calibration_store.h"
#include "server/storage/data_store.h"

namespace inspection {

struct ServiceOptions {
  std::string server_version;
  // An upload's total size: 300 frames of 24 MP at 16 bits are 14.4 GB grey, 43 GB colour. The
  // data disk's free-space reserve is what bounds an upload in practice (checked at its start;
  // a full disk ends it with RESOURCE_EXHAUSTED and the upload folder removed).
  int64_t max_upload_bytes = int64_t(64) << 30;
  // User scenes of the simulated rig: SetSpecimen takes a scene by NAME from this folder
  // (<name>.json); empty = built-in specimens only. Paths ("file:...") are always refused.
  std::filesystem::path scene_dir;
  // Deletion, pins (retention_sweeper.h); must outlive the service.
  DataJanitor* janitor = nullptr;
  // New scans and uploads are refused with RESOURCE_EXHAUSTED while the data disk has less free
  // space than this (0 = no reserve).
  int64_t min_free_bytes = 0;
  // The inspection result feed (ListResults reads the store directly); must outlive the service.
  ResultFeed* results = nullptr;
  // Frames decode while an upload arrives (server/jobs/job_work.h).
  ReconstructPipelineOptions reconstruct;
  // A full verification's validity (inspectd verification_interval_days).
  int verification_interval_days = 30;
};

class InspectionServiceImpl final : public v1::InspectionService::Service {
 public:
  InspectionServiceImpl(const ServiceOptions& options, DataStore* store, JobManager* jobs, RigController* rig,
                        CalibrationStore* calibrations)
      : options_(options), store_(store), jobs_(jobs), rig_(rig), calibrations_(calibrations) {}

  grpc::Status GetRigStatus(grpc::ServerContext*, const v1::GetRigStatusRequest*, v1::RigStatus*) override;
  grpc::Status Calibrate(grpc::ServerContext*, const v1::CalibrateRequest*, grpc::ServerWriter<v1::JobEvent>*) override;
  grpc::Status Scan(grpc::ServerContext*, const v1::ScanRequest*, grpc::ServerWriter<v1::JobEvent>*) override;
  grpc::Status Reconstruct(grpc::ServerContext*,
                           grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>*) override;
  grpc::Status WatchJob(grpc::ServerContext*, const v1::WatchJobRequest*, grpc::ServerWriter<v1::JobEvent>*) override;
  grpc::Status GetJob(grpc::ServerContext*, const v1::GetJobRequest*, v1::Job*) override;
  grpc::Status ListJobs(grpc::ServerContext*, const v1::ListJobsRequest*, v1::ListJobsResponse*) override;
  grpc::Status CancelJob(grpc::ServerContext*, const v1::CancelJobRequest*, v1::Job*) override;
  grpc::Status DownloadArtifact(grpc::ServerContext*, const v1::DownloadArtifactRequest*,
                                grpc::ServerWriter<v1::ArtifactChunk>*) override;
  grpc::Status ResetRig(grpc::ServerContext*, const v1::ResetRigRequest*, v1::RigStatus*) override;
  grpc::Status GetCalibration(grpc::ServerContext*, const v1::GetCalibrationRequest*, v1::Calibration*) override;
  grpc::Status ListCalibrations(grpc::ServerContext*, const v1::ListCalibrationsRequest*,
                                v1::ListCalibrationsResponse*) override;
  grpc::Status DeleteJob(grpc::ServerContext*, const v1::DeleteJobRequest*, v1::DeleteResponse*) override;
  grpc::Status DeleteScan(grpc::ServerContext*, const v1::DeleteScanRequest*, v1::DeleteResponse*) override;
  grpc::Status PinJob(grpc::ServerContext*, const v1::PinJobRequest*, v1::PinJobResponse*) override;
  // Recipes (inspection_service_recipes.cc).
  grpc::Status CreateRecipe(grpc::ServerContext*, const v1::CreateRecipeRequest*, v1::Recipe*) override;
  grpc::Status UpdateRecipe(grpc::ServerContext*, const v1::UpdateRecipeRequest*, v1::Recipe*) override;
  grpc::Status GetRecipe(grpc::ServerContext*, const v1::GetRecipeRequest*, v1::Recipe*) override;
  grpc::Status ListRecipes(grpc::ServerContext*, const v1::ListRecipesRequest*, v1::ListRecipesResponse*) override;
  grpc::Status DeleteRecipe(grpc::ServerContext*, const v1::DeleteRecipeRequest*, v1::DeleteResponse*) override;
  // Inspection results (inspection_service_results.cc).
  grpc::Status ListResults(grpc::ServerContext*, const v1::ListResultsRequest*, v1::ListResultsResponse*) override;
  grpc::Status WatchResults(grpc::ServerContext*, const v1::WatchResultsRequest*,
                            grpc::ServerWriter<v1::InspectionResult>*) override;
  // Type-1 gauge studies (inspection_service_study.cc).
  grpc::Status StartStudy(grpc::ServerContext*, const v1::StartStudyRequest*,
                          grpc::ServerWriter<v1::JobEvent>*) override;
  grpc::Status GetStudy(grpc::ServerContext*, const v1::GetStudyRequest*, v1::Study*) override;
  grpc::Status ListStudies(grpc::ServerContext*, const v1::ListStudiesRequest*, v1::ListStudiesResponse*) override;
  // Instrument verification on the material measures (a rig job, docs/verification.md).
  grpc::Status Verify(grpc::ServerContext*, const v1::VerifyRequest*, grpc::ServerWriter<v1::JobEvent>*) override;

 private:
  void FillRigStatus(v1::RigStatus* status);

  ServiceOptions options_;
  DataStore* store_;
  JobManager* jobs_;
  RigController* rig_;
  CalibrationStore* calibrations_;
};

class SimulationServiceImpl final : public v1::SimulationService::Service {
 public:
  SimulationServiceImpl(const ServiceOptions& options, RigController* rig) : options_(options), rig_(rig) {}
  grpc::Status ListSpecimens(grpc::ServerContext*, const v1::ListSpecimensRequest*,
                             v1::ListSpecimensResponse*) override;
  grpc::Status SetSpecimen(grpc::ServerContext*, const v1::SetSpecimenRequest*, v1::ListSpecimensResponse*) override;

 private:
  ServiceOptions options_;
  RigController* rig_;
};

}  // namespace inspection
