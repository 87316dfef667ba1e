// Recipe RPCs of InspectionService: create, update (a new version), get, list,
// delete. The document is checked in full (server/results/recipe_mapping.h, and its scan section as the
// ScanRequest it stands for) before anything is stored; the store assigns versions atomically.
#include <google/protobuf/util/time_util.h>

#include "server/security/audit_interceptor.h"
#include "server/api/grpc_status.h"
#include "server/api/inspection_service.h"
#include "server/security/call_authorization.h"
#include "server/results/recipe_mapping.h"
#include "server/api/request_mapping.h"

namespace inspection {
namespace {

// The recipe's regions against the rig's image, its scan section as a ScanRequest against the
// rig's travel and the active calibration (the field names get the "recipe.scan." prefix).
Status CheckRecipeDocument(const v1::Recipe& recipe, RigController& rig, CalibrationStore& calibrations) {
  Rig& r = rig.rig();
  INSPECT_RETURN_IF_ERROR(ValidateRecipe(recipe, r.camera().frame_size(), r.pixel_size_um()));
  ScanContext context;
  context.defaults = r.scan_defaults();
  context.stage = &r.stage();
  const std::shared_ptr<const CalibrationBundle> bundle = calibrations.active();
  context.calibration = bundle.get();
  const auto work = MapScanRequest(ScanRequestOfRecipe(recipe.scan()), context);
  if (!work.ok()) {
    const Status& s = work.status();
    // A scan the active calibration cannot run yet (FAILED_PRECONDITION) may still be stored:
    // the recipe is checked again when a scan uses it.
    if (s.code() == StatusCode::kFailedPrecondition) return Status::Ok();
    return Status(s.code(), "recipe.scan: " + s.message());
  }
  return Status::Ok();
}

// Create and update alike: check the document, stamp author and time, store the next version.
StatusOr<v1::Recipe> StoreRecipeVersion(v1::Recipe recipe, const Identity& who, bool create, int expected_version,
                                        RigController& rig, CalibrationStore& calibrations, DataStore& store) {
  INSPECT_RETURN_IF_ERROR(CheckRecipeDocument(recipe, rig, calibrations));
  recipe.set_author(who.name);
  *recipe.mutable_create_time() = google::protobuf::util::TimeUtil::GetCurrentTime();
  return store.StoreRecipe(std::move(recipe), create, expected_version);
}

}  // namespace

grpc::Status InspectionServiceImpl::CreateRecipe(grpc::ServerContext* ctx, const v1::CreateRecipeRequest* req,
                                                 v1::Recipe* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return ToGrpcStatus(s);
  if (!req->has_recipe()) return ToGrpcStatus(Status::InvalidArgument("recipe is required"));
  if (req->recipe().version() != 0) {
    return ToGrpcStatus(Status::InvalidArgument("recipe.version is set by the server; leave it 0"));
  }
  auto stored = StoreRecipeVersion(req->recipe(), *who, /*create=*/true, 0, *rig_, *calibrations_, *store_);
  if (!stored.ok()) return ToGrpcStatus(stored.status());
  SetAuditTarget(ctx, stored->recipe_id() + "@" + std::to_string(stored->version()));
  *out = *stored;
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::UpdateRecipe(grpc::ServerContext* ctx, const v1::UpdateRecipeRequest* req,
                                                 v1::Recipe* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return ToGrpcStatus(s);
  if (!req->has_recipe()) return ToGrpcStatus(Status::InvalidArgument("recipe is required"));
  if (req->expected_version() < 0) return ToGrpcStatus(Status::InvalidArgument("expected_version must be >= 0"));
  auto stored = StoreRecipeVersion(req->recipe(), *who, /*create=*/false, req->expected_version(), *rig_,
                                   *calibrations_, *store_);
  if (!stored.ok()) return ToGrpcStatus(stored.status());
  SetAuditTarget(ctx, stored->recipe_id() + "@" + std::to_string(stored->version()));
  *out = *stored;
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::GetRecipe(grpc::ServerContext* ctx, const v1::GetRecipeRequest* req,
                                              v1::Recipe* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return ToGrpcStatus(s);
  if (Status s = CheckRecipeName(req->recipe_id(), "recipe_id"); !s.ok()) return ToGrpcStatus(s);
  if (req->version() < 0) return ToGrpcStatus(Status::InvalidArgument("version must be >= 0 (0 = the current one)"));
  auto recipe = store_->GetRecipe(req->recipe_id(), req->version());
  if (!recipe.ok()) return ToGrpcStatus(recipe.status());
  *out = *recipe;
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::ListRecipes(grpc::ServerContext* ctx, const v1::ListRecipesRequest*,
                                                v1::ListRecipesResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return ToGrpcStatus(who.status());
  auto list = store_->ListRecipes();
  if (!list.ok()) return ToGrpcStatus(list.status());
  for (v1::Recipe& r : *list) *out->add_recipes() = std::move(r);
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::DeleteRecipe(grpc::ServerContext* ctx, const v1::DeleteRecipeRequest* req,
                                                 v1::DeleteResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return ToGrpcStatus(s);
  if (Status s = CheckRecipeName(req->recipe_id(), "recipe_id"); !s.ok()) return ToGrpcStatus(s);
  SetAuditTarget(ctx, req->recipe_id());
  // A queued scan holds its own copy of the recipe; refusing keeps "what will run" and "what
  // the recipe list shows" the same while it waits.
  auto unfinished = store_->UnfinishedJobs();
  if (!unfinished.ok()) return ToGrpcStatus(unfinished.status());
  for (const v1::Job& job : *unfinished) {
    if (job.recipe_id() == req->recipe_id()) {
      return ToGrpcStatus(Status::FailedPrecondition("recipe '" + req->recipe_id() + "' is used by " +
                                                     v1::JobState_Name(job.state()) + " job " + job.job_id()));
    }
  }
  auto n = store_->DeleteRecipe(req->recipe_id());
  if (!n.ok()) return ToGrpcStatus(n.status());
  out->set_id(req->recipe_id());
  return grpc::Status::OK;
}

}  // namespace inspection
