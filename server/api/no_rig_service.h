// The gRPC services of `inspectd --no-rig`: a reconstruct-only server for the scale-out pool
// (deploy/k8s/reconstruct). Job, artifact, calibration and Reconstruct calls go to the ordinary
// handlers, and so are the result feed's (a site replica's store holds every rig's results); the
// calls that need a rig (GetRigStatus, Scan, Calibrate, ResetRig, the recipes and the
// simulation's specimen calls) answer FAILED_PRECONDITION saying why, after the same
// authentication as every call.
#pragma once

#include <array>
#include <string_view>

#include "inspection/v1/inspection.grpc.pb.h"
#include "server/api/inspection_service.h"

namespace inspection {

// The message of every refused rig call, e.g. "Scan needs a rig; this inspectd runs with
// --no-rig (reconstruct only): send it to the rig's inspectd".
std::string NoRigMessage(std::string_view method);

// InspectionService methods by what --no-rig does with them. Together they are every method of
// the service (a test checks this against the proto, so a new RPC cannot fall through as
// UNIMPLEMENTED unnoticed).
// Recipes live on the rig's server: they are checked against its camera and run by its scans.
// Inspection results are served: a site replica (--no-rig on the site's PostgreSQL) holds every
// rig's forwarded results (server/results/result_forwarder.h); a plain pool holds none.
// Type-1 studies run on the rig (StartStudy refused); stored ones are read anywhere. So does a
// verification (Verify refused).
inline constexpr std::array<std::string_view, 11> kRigOnlyMethods = {
    "GetRigStatus", "Calibrate", "Scan", "ResetRig", "CreateRecipe", "UpdateRecipe",
    "GetRecipe",    "ListRecipes", "DeleteRecipe", "StartStudy", "Verify"};
inline constexpr std::array<std::string_view, 15> kNoRigServedMethods = {
    "Reconstruct",      "WatchJob",       "GetJob",           "ListJobs",  "CancelJob",
    "DownloadArtifact", "GetCalibration", "ListCalibrations", "DeleteJob", "DeleteScan",
    "PinJob",           "ListResults",    "WatchResults",     "GetStudy",  "ListStudies"};

class NoRigInspectionService final : public v1::InspectionService::Service {
 public:
  // `served` handles the calls a reconstruct server answers; it was built without a rig.
  NoRigInspectionService(const ServiceOptions& options, InspectionServiceImpl* served)
      : options_(options), served_(served) {}

  grpc::Status GetRigStatus(grpc::ServerContext*, const v1::GetRigStatusRequest*, v1::RigStatus*) override;
  grpc::Status Calibrate(grpc::ServerContext*, const v1::CalibrateRequest*, grpc::ServerWriter<v1::JobEvent>*) override;
  grpc::Status Scan(grpc::ServerContext*, const v1::ScanRequest*, grpc::ServerWriter<v1::JobEvent>*) override;
  grpc::Status ResetRig(grpc::ServerContext*, const v1::ResetRigRequest*, v1::RigStatus*) override;

  grpc::Status Reconstruct(grpc::ServerContext* c,
                           grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>* s) override {
    return served_->Reconstruct(c, s);
  }
  grpc::Status WatchJob(grpc::ServerContext* c, const v1::WatchJobRequest* r,
                        grpc::ServerWriter<v1::JobEvent>* w) override {
    return served_->WatchJob(c, r, w);
  }
  grpc::Status GetJob(grpc::ServerContext* c, const v1::GetJobRequest* r, v1::Job* o) override {
    return served_->GetJob(c, r, o);
  }
  grpc::Status ListJobs(grpc::ServerContext* c, const v1::ListJobsRequest* r, v1::ListJobsResponse* o) override {
    return served_->ListJobs(c, r, o);
  }
  grpc::Status CancelJob(grpc::ServerContext* c, const v1::CancelJobRequest* r, v1::Job* o) override {
    return served_->CancelJob(c, r, o);
  }
  grpc::Status DownloadArtifact(grpc::ServerContext* c, const v1::DownloadArtifactRequest* r,
                                grpc::ServerWriter<v1::ArtifactChunk>* w) override {
    return served_->DownloadArtifact(c, r, w);
  }
  grpc::Status GetCalibration(grpc::ServerContext* c, const v1::GetCalibrationRequest* r, v1::Calibration* o) override {
    return served_->GetCalibration(c, r, o);
  }
  grpc::Status ListCalibrations(grpc::ServerContext* c, const v1::ListCalibrationsRequest* r,
                                v1::ListCalibrationsResponse* o) override {
    return served_->ListCalibrations(c, r, o);
  }
  grpc::Status DeleteJob(grpc::ServerContext* c, const v1::DeleteJobRequest* r, v1::DeleteResponse* o) override {
    return served_->DeleteJob(c, r, o);
  }
  grpc::Status DeleteScan(grpc::ServerContext* c, const v1::DeleteScanRequest* r, v1::DeleteResponse* o) override {
    return served_->DeleteScan(c, r, o);
  }
  grpc::Status PinJob(grpc::ServerContext* c, const v1::PinJobRequest* r, v1::PinJobResponse* o) override {
    return served_->PinJob(c, r, o);
  }
  grpc::Status CreateRecipe(grpc::ServerContext* c, const v1::CreateRecipeRequest*, v1::Recipe*) override {
    return Refuse(c, "CreateRecipe");
  }
  grpc::Status UpdateRecipe(grpc::ServerContext* c, const v1::UpdateRecipeRequest*, v1::Recipe*) override {
    return Refuse(c, "UpdateRecipe");
  }
  grpc::Status GetRecipe(grpc::ServerContext* c, const v1::GetRecipeRequest*, v1::Recipe*) override {
    return Refuse(c, "GetRecipe");
  }
  grpc::Status ListRecipes(grpc::ServerContext* c, const v1::ListRecipesRequest*, v1::ListRecipesResponse*) override {
    return Refuse(c, "ListRecipes");
  }
  grpc::Status DeleteRecipe(grpc::ServerContext* c, const v1::DeleteRecipeRequest*, v1::DeleteResponse*) override {
    return Refuse(c, "DeleteRecipe");
  }
  grpc::Status ListResults(grpc::ServerContext* c, const v1::ListResultsRequest* r,
                           v1::ListResultsResponse* o) override {
    return served_->ListResults(c, r, o);
  }
  grpc::Status WatchResults(grpc::ServerContext* c, const v1::WatchResultsRequest* r,
                            grpc::ServerWriter<v1::InspectionResult>* w) override {
    return served_->WatchResults(c, r, w);
  }
  grpc::Status StartStudy(grpc::ServerContext* c, const v1::StartStudyRequest*,
                          grpc::ServerWriter<v1::JobEvent>*) override {
    return Refuse(c, "StartStudy");
  }
  grpc::Status Verify(grpc::ServerContext* c, const v1::VerifyRequest*, grpc::ServerWriter<v1::JobEvent>*) override {
    return Refuse(c, "Verify");
  }
  grpc::Status GetStudy(grpc::ServerContext* c, const v1::GetStudyRequest* r, v1::Study* o) override {
    return served_->GetStudy(c, r, o);
  }
  grpc::Status ListStudies(grpc::ServerContext* c, const v1::ListStudiesRequest* r,
                           v1::ListStudiesResponse* o) override {
    return served_->ListStudies(c, r, o);
  }

 private:
  grpc::Status Refuse(grpc::ServerContext* ctx, std::string_view method) const;

  ServiceOptions options_;
  InspectionServiceImpl* served_;
};

// SimulationService without a rig: both calls refused the same way.
class NoRigSimulationService final : public v1::SimulationService::Service {
 public:
  explicit NoRigSimulationService(const ServiceOptions& options) : options_(options) {}
  grpc::Status ListSpecimens(grpc::ServerContext*, const v1::ListSpecimensRequest*,
                             v1::ListSpecimensResponse*) override;
  grpc::Status SetSpecimen(grpc::ServerContext*, const v1::SetSpecimenRequest*, v1::ListSpecimensResponse*) override;

 private:
  ServiceOptions options_;
};

}  // namespace inspection
