// Type-1 gauge study RPCs of InspectionService: StartStudy (a rig job like Scan, its events
// streamed back), GetStudy and ListStudies (the stored studies).
#include <cmath>
#include <functional>
#include <string>

#include "core/metrology/capability.h"
#include "server/api/grpc_status.h"
#include "server/api/inspection_service.h"
#include "server/api/recipe_scan.h"
#include "server/api/request_mapping.h"
#include "server/results/study_result.h"
#include "server/security/audit_interceptor.h"
#include "server/security/call_authorization.h"
#include "server/storage/data_lifecycle.h"

namespace inspection {
namespace {

grpc::Status Grpc(const Status& s) { return ToGrpcStatus(s); }

// Re-positioning of the simulated part when the request leaves it unset: a few um laterally
// (a part put back against a fixture) and in height (the fixture's seat).
constexpr double kDefaultRepositionXyUm = 5.0;
constexpr double kDefaultRepositionZUm = 2.0;

// As the Scan handler streams its job (inspection_service.cc): every event from the first to the
// terminal one, then the job's outcome as the stream's status.
grpc::Status StreamStudyJob(grpc::ServerContext* ctx, const std::shared_ptr<JobRecord>& r,
                            grpc::ServerWriter<v1::JobEvent>* writer) {
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
  const v1::Job job = r->Snapshot();
  switch (job.state()) {
    case v1::JOB_STATE_SUCCEEDED:
      return grpc::Status::OK;
    case v1::JOB_STATE_CANCELLED:
      return Grpc(Status::Cancelled(job.error_message()));
    default:
      return Grpc(Status(job.error_code() ? StatusCode(job.error_code()) : StatusCode::kUnknown, job.error_message()));
  }
}

// The request's own fields, before any recipe is read.
Status CheckStartStudyRequest(const v1::StartStudyRequest& req) {
  if (req.recipe_id().empty()) return Status::InvalidArgument("recipe_id is required: the recipe to study");
  if (req.repeats() < kMinType1Repeats || req.repeats() > kMaxType1Repeats) {
    return Status::InvalidArgument("repeats must be " + std::to_string(kMinType1Repeats) + ".." +
                                   std::to_string(kMaxType1Repeats) + " (VDA 5 recommends 25 or 50), got " +
                                   std::to_string(req.repeats()));
  }
  if (!std::isfinite(req.reposition_xy_um()) || req.reposition_xy_um() < 0 || req.reposition_xy_um() > 1000) {
    return Status::InvalidArgument("reposition_xy_um must be 0..1000 (0 = the default)");
  }
  if (!std::isfinite(req.reposition_z_um()) || req.reposition_z_um() < 0 || req.reposition_z_um() > 1000) {
    return Status::InvalidArgument("reposition_z_um must be 0..1000 (0 = the default)");
  }
  return Status::Ok();
}

}  // namespace

grpc::Status InspectionServiceImpl::StartStudy(grpc::ServerContext* ctx, const v1::StartStudyRequest* req,
                                               grpc::ServerWriter<v1::JobEvent>* writer) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  if (Status s = CheckStartStudyRequest(*req); !s.ok()) return Grpc(s);
  if (Status s = CheckFreeSpaceReserve(store_->data_dir(), options_.min_free_bytes); !s.ok()) return Grpc(s);
  auto r = jobs_->Submit(
      v1::JOB_KIND_STUDY, req->request_id(), req->label(),
      [&]() -> StatusOr<JobWork> {
        INSPECT_RETURN_IF_ERROR(rig_->CheckUsable());
        const std::shared_ptr<const CalibrationBundle> calibration = calibrations_->active();
        ScanContext context;
        context.defaults = rig_->rig().scan_defaults();
        context.stage = &rig_->rig().stage();
        context.calibration = calibration.get();
        Rig& rig = rig_->rig();
        v1::ScanRequest scan;
        scan.set_recipe_id(req->recipe_id());
        scan.set_recipe_version(req->recipe_version());
        scan.set_part_id(req->part_id());
        INSPECT_ASSIGN_OR_RETURN(
            ScanWork scan_work,
            MapScanRequestWithRecipe(scan, context, *store_, rig.camera().frame_size(), rig.pixel_size_um()));
        INSPECT_RETURN_IF_ERROR(CheckStudyRecipe(scan_work.recipe->recipe, req->reference_values()));
        StudyWork work;
        work.scan = std::move(scan_work);
        work.repeats = req->repeats();
        work.reference_values.insert(req->reference_values().begin(), req->reference_values().end());
        const bool defaulted = req->reposition_xy_um() == 0 && req->reposition_z_um() == 0;
        work.reposition_xy_um = defaulted ? kDefaultRepositionXyUm : req->reposition_xy_um();
        work.reposition_z_um = defaulted ? kDefaultRepositionZUm : req->reposition_z_um();
        if (defaulted && rig_->simulated()) work.repositioning_note = " (default: the request set none)";
        work.seed = std::hash<std::string>()(NewId("study"));
        return JobWork(std::move(work));
      },
      who->name);
  if (!r.ok()) return Grpc(r.status());
  SetAuditTarget(ctx, (*r)->job_id());
  return StreamStudyJob(ctx, *r, writer);
}

grpc::Status InspectionServiceImpl::GetStudy(grpc::ServerContext* ctx, const v1::GetStudyRequest* req,
                                             v1::Study* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (req->study_id().empty()) return Grpc(Status::InvalidArgument("study_id is required"));
  auto s = store_->GetStudy(req->study_id());
  if (!s.ok()) return Grpc(s.status());
  *out = std::move(*s);
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ListStudies(grpc::ServerContext* ctx, const v1::ListStudiesRequest* req,
                                                v1::ListStudiesResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (req->page_size() < 0) return Grpc(Status::InvalidArgument("page_size must be >= 0"));
  const int limit = req->page_size() == 0 ? 50 : std::min(req->page_size(), 500);
  auto list = store_->ListStudies(req->recipe_id(), limit);
  if (!list.ok()) return Grpc(list.status());
  for (v1::Study& s : *list) *out->add_studies() = std::move(s);
  return grpc::Status::OK;
}

}  // namespace inspection
