// The per-call authorization verdicts (call_authorization.h).
#include "server/security/call_authorization.h"

#include <grpcpp/server_context.h>

#include <mutex>
#include <optional>
#include <unordered_map>

namespace inspection {

namespace {

struct Verdict {
  std::string method;  // bare
  StatusOr<Identity> caller;
};

// Verdicts of the calls in flight, by their context; the interceptor that recorded one removes
// it when the call is done (after the handler returned).
class Verdicts {
 public:
  void Record(const grpc::ServerContextBase* ctx, Verdict v) {
    std::lock_guard lock(mu_);
    by_context_.insert_or_assign(ctx, std::move(v));
  }
  void Forget(const grpc::ServerContextBase* ctx) {
    std::lock_guard lock(mu_);
    by_context_.erase(ctx);
  }
  std::optional<Verdict> Find(const grpc::ServerContextBase* ctx) const {
    std::lock_guard lock(mu_);
    auto it = by_context_.find(ctx);
    if (it == by_context_.end()) return std::nullopt;
    return it->second;
  }

 private:
  mutable std::mutex mu_;
  std::unordered_map<const grpc::ServerContextBase*, Verdict> by_context_;
};

Verdicts& AllVerdicts() {
  static Verdicts* v = new Verdicts;  // never destroyed: calls may end during static destruction
  return *v;
}

class AuthorizationInterceptor final : public grpc::experimental::Interceptor {
 public:
  AuthorizationInterceptor(grpc::experimental::ServerRpcInfo* info, const AccessControl* access)
      : info_(info), access_(access) {}
  ~AuthorizationInterceptor() override {
    if (recorded_) AllVerdicts().Forget(info_->server_context());
  }

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    using grpc::experimental::InterceptionHookPoints;
    const std::string_view full = info_->method() ? info_->method() : "";
    // The inspection API's own services only: gRPC's health checks and reflection carry no
    // identity (reflection is off whenever authentication is on) and reach no handler of ours.
    if (full.rfind("/inspection.v1.", 0) != 0) {
      methods->Proceed();
      return;
    }
    if (!recorded_ && methods->QueryInterceptionHookPoint(InterceptionHookPoints::POST_RECV_INITIAL_METADATA)) {
      AllVerdicts().Record(info_->server_context(),
                           Verdict{std::string(BareMethodName(full)),
                                   access_->Authorize(CredentialsFromContext(*info_->server_context()), full)});
      recorded_ = true;
    }
    // A refused call ends refused even if a handler forgot to ask (the API test calls every
    // method unauthenticated to prove none does).
    if (recorded_ && methods->QueryInterceptionHookPoint(InterceptionHookPoints::PRE_SEND_STATUS)) {
      if (auto v = AllVerdicts().Find(info_->server_context()); v && !v->caller.ok()) {
        methods->ModifySendStatus(grpc::Status(
            static_cast<grpc::StatusCode>(static_cast<int>(v->caller.status().code())), v->caller.status().message()));
      }
    }
    methods->Proceed();
  }

 private:
  grpc::experimental::ServerRpcInfo* const info_;
  const AccessControl* const access_;
  bool recorded_ = false;
};

}  // namespace

StatusOr<Identity> CallerOf(const grpc::ServerContextBase* context) {
  if (auto v = AllVerdicts().Find(context)) return std::move(v->caller);
  return Status(StatusCode::kPermissionDenied, "the call passed no authorization decision; refused");
}

std::string CalledMethod(const grpc::ServerContextBase* context) {
  if (auto v = AllVerdicts().Find(context)) return v->method;
  return {};
}

grpc::experimental::Interceptor* AuthorizationInterceptorFactory::CreateServerInterceptor(
    grpc::experimental::ServerRpcInfo* info) {
  return new AuthorizationInterceptor(info, access_);
}

}  // namespace inspection
