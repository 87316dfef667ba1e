// Authentication and the role check of every RPC, in one place. A gRPC server interceptor
// decides each call when its metadata arrives, keyed by the full method name gRPC routes the call
// by ("/inspection.v1.InspectionService/Scan", the name the generated code registers), and
// records the verdict against the call's ServerContext. Handlers take the caller from CallerOf:
// they name no method and check no role. A call that passed no decision (the interceptor is not
// installed) or a method without a rule in the role table is refused: fail closed.
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include <string>
#include <string_view>

#include "core/util/status.h"
#include "server/security/access_control.h"

namespace grpc {
class ServerContextBase;
}

namespace inspection {

// The caller of a call the interceptor decided: its identity, or UNAUTHENTICATED /
// PERMISSION_DENIED as the policy answered; PERMISSION_DENIED when no decision was recorded.
StatusOr<Identity> CallerOf(const grpc::ServerContextBase* context);

// The bare method name ("Scan") of a decided call, for messages; empty when none was recorded.
std::string CalledMethod(const grpc::ServerContextBase* context);

class AuthorizationInterceptorFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  // `access` must outlive the gRPC server.
  explicit AuthorizationInterceptorFactory(const AccessControl* access) : access_(access) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override;

 private:
  const AccessControl* access_;
};

}  // namespace inspection
