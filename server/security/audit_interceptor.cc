// Audit interceptor (see audit_interceptor.h).
#include "server/security/audit_interceptor.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>
#include <grpcpp/server_context.h>
#include <spdlog/spdlog.h>

#include <algorithm>

namespace inspection {

namespace {

constexpr const char* kTargetKey = "inspection-target";

// The id a request names (job_id, scan_id, artifact_id, calibration_id, specimen), also one
// level down (ReconstructRequest.start.scan_id). Only these fields: never free text or data.
std::string RequestTarget(const google::protobuf::Message& m, int depth = 0) {
  static constexpr const char* kIdFields[] = {"job_id", "scan_id", "artifact_id", "calibration_id", "specimen"};
  const google::protobuf::Descriptor* d = m.GetDescriptor();
  const google::protobuf::Reflection* r = m.GetReflection();
  for (const char* name : kIdFields) {
    const google::protobuf::FieldDescriptor* f = d->FindFieldByName(name);
    // HasField: set in a oneof, or (proto3 scalars) not empty.
    if (f && !f->is_repeated() && f->type() == google::protobuf::FieldDescriptor::TYPE_STRING && r->HasField(m, f)) {
      return r->GetString(m, f);
    }
  }
  if (depth > 0) return {};
  for (int i = 0; i < d->field_count(); ++i) {
    const google::protobuf::FieldDescriptor* f = d->field(i);
    if (f->cpp_type() == google::protobuf::FieldDescriptor::CPPTYPE_MESSAGE && !f->is_repeated() && r->HasField(m, f)) {
      std::string v = RequestTarget(r->GetMessage(m, f), depth + 1);
      if (!v.empty()) return v;
    }
  }
  return {};
}

class AuditInterceptor : public grpc::experimental::Interceptor {
 public:
  AuditInterceptor(grpc::experimental::ServerRpcInfo* info, AuditLog* log, const AccessControl* access)
      : info_(info), log_(log), access_(access) {
    // Only the inspection API's own methods: health checks and reflection change nothing and
    // carry no identity, and their messages are raw bytes, not the generated classes.
    const std::string_view full = info_->method() ? info_->method() : "";
    if (full.rfind("/inspection.v1.", 0) == 0) {
      std::string name(full.substr(1));
      std::replace(name.begin(), name.end(), '/', '.');
      known_method_ = google::protobuf::DescriptorPool::generated_pool()->FindMethodByName(name) != nullptr;
    }
  }

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    using grpc::experimental::InterceptionHookPoints;
    if (!known_method_) {
      methods->Proceed();
      return;
    }
    // A known method of a generated synchronous service: the received message is its request class.
    if (methods->QueryInterceptionHookPoint(InterceptionHookPoints::POST_RECV_MESSAGE) && !seen_request_) {
      seen_request_ = true;  // the first message names the target (a stream's later chunks do not)
      if (const void* m = methods->GetRecvMessage()) {
        request_target_ = RequestTarget(*static_cast<const google::protobuf::Message*>(m));
      }
    }
    if (methods->QueryInterceptionHookPoint(InterceptionHookPoints::PRE_SEND_STATUS)) Record(methods);
    methods->Proceed();
  }

 private:
  void Record(grpc::experimental::InterceptorBatchMethods* methods) {
    const grpc::Status status = methods->GetSendStatus();
    const std::string_view full_method = info_->method() ? info_->method() : "";
    const std::string_view method = BareMethodName(full_method);
    const bool denied = status.error_code() == grpc::StatusCode::UNAUTHENTICATED ||
                        status.error_code() == grpc::StatusCode::PERMISSION_DENIED;
    if (!denied && !IsMutatingMethod(full_method)) return;
    AuditRecord r;
    r.method = std::string(method);
    r.code = static_cast<StatusCode>(static_cast<int>(status.error_code()));
    r.message = status.error_message();
    const CallerCredentials c = CredentialsFromContext(*info_->server_context());
    r.peer = c.peer;
    // The identity as the policy sees it; for an unauthenticated call, what it presented (never
    // the token itself).
    if (auto id = access_->Authenticate(c); id.ok()) {
      r.identity = id->name;
      r.role = RoleName(id->role);
    } else {
      r.identity = !c.cert_names.empty() ? c.cert_names.front() : c.bearer_token.empty() ? "(none)" : "(unknown token)";
    }
    r.target = request_target_;
    if (auto* trailing = methods->GetSendTrailingMetadata()) {
      if (auto it = trailing->find(kTargetKey); it != trailing->end()) r.target = it->second;
    }
    log_->Append(r);
    if (denied) {
      spdlog::warn("audit: {} {} by {} ({}) denied: {}", r.method, r.target, r.identity, r.peer, r.message);
    } else {
      spdlog::info("audit: {} {} by {} ({}) -> {}", r.method, r.target, r.identity, r.peer, StatusCodeName(r.code));
    }
  }

  grpc::experimental::ServerRpcInfo* info_;
  AuditLog* log_;
  const AccessControl* access_;
  bool known_method_ = false;
  bool seen_request_ = false;
  std::string request_target_;
};

}  // namespace

bool IsMutatingMethod(std::string_view full_method) { return RequiredRole(full_method) != Role::kViewer; }

void SetAuditTarget(grpc::ServerContext* context, const std::string& id) {
  if (context && !id.empty()) context->AddTrailingMetadata(kTargetKey, id);
}

grpc::experimental::Interceptor* AuditInterceptorFactory::CreateServerInterceptor(
    grpc::experimental::ServerRpcInfo* info) {
  return new AuditInterceptor(info, log_, access_);
}

}  // namespace inspection
