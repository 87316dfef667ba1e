// Opens the caller's log identity around each gRPC call (log_identity_interceptor.h).
#include "server/security/log_identity_interceptor.h"

#include <grpcpp/server_context.h>

#include <string>

#include "server/logging/log_format.h"

namespace inspection {

namespace {

class LogIdentityInterceptor final : public grpc::experimental::Interceptor {
 public:
  LogIdentityInterceptor(grpc::experimental::ServerRpcInfo* info, const AccessControl* access)
      : info_(info), access_(access) {}

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    using grpc::experimental::InterceptionHookPoints;
    if (opened_ || !methods->QueryInterceptionHookPoint(InterceptionHookPoints::POST_RECV_INITIAL_METADATA)) {
      methods->Proceed();
      return;
    }
    opened_ = true;
    std::string identity;
    if (auto id = access_->Authenticate(CredentialsFromContext(*info_->server_context())); id.ok()) {
      identity = std::move(id->name);
    }
    // The synchronous server runs the rest of the interceptor chain and then the handler inside
    // this Proceed (on this thread), and the handler's sends run their hooks inside the handler:
    // the scope covers the whole call. (Were the handler run later elsewhere, its lines would
    // merely lack the identity; the log_format test through the real server checks it is there.)
    const ScopedLogIdentity scope(std::move(identity));
    methods->Proceed();
  }

 private:
  grpc::experimental::ServerRpcInfo* const info_;
  const AccessControl* const access_;
  bool opened_ = false;
};

}  // namespace

grpc::experimental::Interceptor* LogIdentityInterceptorFactory::CreateServerInterceptor(
    grpc::experimental::ServerRpcInfo* info) {
  return new LogIdentityInterceptor(info, access_);
}

}  // namespace inspection
