// The audit trail's eye on the transport: a gRPC server interceptor that, when a call ends,
// appends one AuditLog record (audit_log.h) for every mutating call and for every call refused
// as UNAUTHENTICATED or PERMISSION_DENIED, whatever the method. It sees the method, the caller's
// credentials, the request's id fields and the final status, so handlers need no audit code; a
// handler that creates something (a job) names it with SetAuditTarget.
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include <memory>
#include <string>
#include <string_view>

#include "server/security/access_control.h"
#include "server/security/audit_log.h"

namespace grpc {
class ServerContext;
}

namespace inspection {

// True for RPCs that change state (start, cancel, delete, configure): every method that needs
// more than the viewer role, or none in the table (full method names, access_control.h). Reads
// are audited only when refused.
bool IsMutatingMethod(std::string_view full_method);

// Records the id a call created or acted on (sent to the client as trailing metadata
// "inspection-target", which is where the interceptor reads it; ids are not secret, the client
// gets them anyway).
void SetAuditTarget(grpc::ServerContext* context, const std::string& id);

class AuditInterceptorFactory : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  // Both must outlive the server.
  AuditInterceptorFactory(AuditLog* log, const AccessControl* access) : log_(log), access_(access) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override;

 private:
  AuditLog* log_;
  const AccessControl* access_;
};

}  // namespace inspection
