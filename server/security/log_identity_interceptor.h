// The caller's identity on inspectd's log lines: a gRPC server interceptor that authenticates the
// call's credentials with the server's AccessControl (the same answer the handlers and the audit
// trail get) and opens a ScopedLogIdentity (log_format.h) around the rest of the call, so every
// line logged while the call is handled - by the handler, the job manager, the audit interceptor -
// carries "identity" in the JSON format. Unauthenticated callers get no identity.
#pragma once

#include <grpcpp/support/server_interceptor.h>

#include "server/security/access_control.h"

namespace inspection {

class LogIdentityInterceptorFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  // `access` must outlive the gRPC server.
  explicit LogIdentityInterceptorFactory(const AccessControl* access) : access_(access) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override;

 private:
  const AccessControl* access_;
};

}  // namespace inspection
