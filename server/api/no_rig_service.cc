// inspectd --no-rig: rig calls refused with FAILED_PRECONDITION, the rest served (no_rig_service.h).
#include "server/api/no_rig_service.h"

#include "server/api/grpc_status.h"
#include "server/security/call_authorization.h"

namespace inspection {

std::string NoRigMessage(std::string_view method) {
  return std::string(method) +
         " needs a rig; this inspectd runs with --no-rig (reconstruct only): send it to the rig's inspectd";
}

namespace {
// Authentication and the method's role first: an unauthenticated caller learns nothing about
// the server's role.
grpc::Status RefuseAfterAuth(grpc::ServerContext* ctx, const ServiceOptions&, std::string_view method) {
  if (auto who = CallerOf(ctx); !who.ok()) return ToGrpcStatus(who.status());
  return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, NoRigMessage(method));
}
}  // namespace

grpc::Status NoRigInspectionService::Refuse(grpc::ServerContext* ctx, std::string_view method) const {
  return RefuseAfterAuth(ctx, options_, method);
}

grpc::Status NoRigInspectionService::GetRigStatus(grpc::ServerContext* ctx, const v1::GetRigStatusRequest*,
                                                  v1::RigStatus*) {
  return Refuse(ctx, "GetRigStatus");
}

grpc::Status NoRigInspectionService::Calibrate(grpc::ServerContext* ctx, const v1::CalibrateRequest*,
                                               grpc::ServerWriter<v1::JobEvent>*) {
  return Refuse(ctx, "Calibrate");
}

grpc::Status NoRigInspectionService::Scan(grpc::ServerContext* ctx, const v1::ScanRequest*,
                                          grpc::ServerWriter<v1::JobEvent>*) {
  return Refuse(ctx, "Scan");
}

grpc::Status NoRigInspectionService::ResetRig(grpc::ServerContext* ctx, const v1::ResetRigRequest*, v1::RigStatus*) {
  return Refuse(ctx, "ResetRig");
}

grpc::Status NoRigSimulationService::ListSpecimens(grpc::ServerContext* ctx, const v1::ListSpecimensRequest*,
                                                   v1::ListSpecimensResponse*) {
  return RefuseAfterAuth(ctx, options_, "ListSpecimens");
}

grpc::Status NoRigSimulationService::SetSpecimen(grpc::ServerContext* ctx, const v1::SetSpecimenRequest*,
                                                 v1::ListSpecimensResponse*) {
  return RefuseAfterAuth(ctx, options_, "SetSpecimen");
}

}  // namespace inspection
