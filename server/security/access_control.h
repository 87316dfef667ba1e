// Who is calling and what they may do: identities from client certificates (mTLS) or named
// bearer tokens, roles from a policy file, and the role each RPC needs. The gRPC handlers ask
// Authorize() once per call; the answer is UNAUTHENTICATED (no or unknown credentials) or
// PERMISSION_DENIED naming the missing role.
//
// Roles are ordered: viewer < operator < engineer < admin; a role may do everything the roles
// below it may.
//   viewer   status, get/list/watch, download
//   operator + scan, reconstruct, cancel own jobs
//   engineer + calibrate, recipes, specimen
//   admin    + reset, cancel any job, delete, retention settings
#pragma once

#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/status.h"

namespace grpc {
class ServerContextBase;
}

namespace inspection {

enum class Role { kViewer = 0, kOperator = 1, kEngineer = 2, kAdmin = 3 };

const char* RoleName(Role role);  // "viewer", "operator", "engineer", "admin"
StatusOr<Role> ParseRole(std::string_view name);

// The role an RPC needs, by its full method name as gRPC routes it
// ("/inspection.v1.InspectionService/Scan"); none for a method the table does not name, which
// Authorize refuses, so a new RPC is closed until someone decides who may call it.
std::optional<Role> RequiredRole(std::string_view full_method);
// Every full method name the role table names (the test checks them against the descriptors).
std::vector<std::string> MethodsWithRoles();
// "/inspection.v1.InspectionService/Scan" -> "Scan"
std::string_view BareMethodName(std::string_view full_method);

// What a call presented, extracted from the transport. Kept free of gRPC types so the policy
// is testable without a server.
struct CallerCredentials {
  std::string bearer_token;             // from "authorization: Bearer <token>"; empty if none
  std::vector<std::string> cert_names;  // verified client certificate: CN first, then SANs
  std::string peer;                     // "ipv4:127.0.0.1:5432"
};
CallerCredentials CredentialsFromContext(const grpc::ServerContextBase& context);

struct Identity {
  std::string name;  // certificate CN/SAN or token identity; "anonymous" when auth is off
  Role role = Role::kViewer;
  std::string peer;
};

// Identities and their roles. Immutable once built; AccessControl swaps whole policies on reload.
//
// Policy file (JSON):
//   {"identities": {"station-7": "operator", "qa-lead": "engineer", "it-admin": "admin"},
//    "default_role": "viewer"}          // optional: role of an authenticated identity not listed
// Token file (text, one token per identity): "identity token" per line, '#' starts a comment.
//   A token file without a policy file gives every token holder admin (the single-token setup
//   of earlier versions: --auth-token-file with one bare token line is identity "token").
class AccessPolicy {
 public:
  // No authentication configured: every caller is "anonymous" with admin.
  static AccessPolicy Open();
  // policy_json may be empty (no policy file); token_text may be empty (certificates only).
  // require_client_cert: mTLS is on, so a call without a verified certificate name and without
  // a valid token is unauthenticated.
  static StatusOr<AccessPolicy> Parse(const std::string& policy_json, const std::string& token_text,
                                      bool require_client_cert);
  static StatusOr<AccessPolicy> Load(const std::filesystem::path& policy_file, const std::filesystem::path& token_file,
                                     bool require_client_cert);

  bool enabled() const { return enabled_; }
  // UNAUTHENTICATED without credentials or with an unknown token; PERMISSION_DENIED for a
  // verified identity that the policy does not list (and no default role).
  StatusOr<Identity> Authenticate(const CallerCredentials& credentials) const;

 private:
  bool enabled_ = false;
  bool require_client_cert_ = false;
  bool have_policy_ = false;
  std::map<std::string, Role> roles_;  // identity -> role
  std::optional<Role> default_role_;
  std::vector<std::pair<std::string, std::string>> tokens_;  // (token, identity)
};

// PERMISSION_DENIED "<method> needs role <required>; '<name>' has role <role>" when short.
Status CheckRole(const Identity& identity, Role required, std::string_view method);

// The policy in force, reloadable (SIGHUP) without dropping calls in flight: each call takes a
// snapshot. Thread-safe.
class AccessControl {
 public:
  explicit AccessControl(AccessPolicy policy) : policy_(std::make_shared<const AccessPolicy>(std::move(policy))) {}
  // Remembers where the policy came from so Reload() can read it again.
  void SetSource(std::filesystem::path policy_file, std::filesystem::path token_file, bool require_client_cert);
  Status Reload();  // keeps the old policy when the new one does not parse

  bool enabled() const { return snapshot()->enabled(); }
  // Who the caller is, without a role check (the audit log names denied callers with it).
  StatusOr<Identity> Authenticate(const CallerCredentials& credentials) const {
    return snapshot()->Authenticate(credentials);
  }
  // Authenticate and check the role for one call of `full_method` (RequiredRole); PERMISSION_DENIED
  // for a method without a rule.
  StatusOr<Identity> Authorize(const CallerCredentials& credentials, std::string_view full_method) const;

 private:
  std::shared_ptr<const AccessPolicy> snapshot() const;

  mutable std::mutex mu_;  // guards the members below
  std::shared_ptr<const AccessPolicy> policy_;
  std::filesystem::path policy_file_;
  std::filesystem::path token_file_;
  bool require_client_cert_ = false;
};

}  // namespace inspection
