// Identities, roles and the role table of the RPCs (see access_control.h).
#include "server/security/access_control.h"

#include <grpcpp/server_context.h>
#include <openssl/crypto.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

namespace inspection {

namespace {

constexpr std::string_view kInspection = "/inspection.v1.InspectionService/";
constexpr std::string_view kSimulation = "/inspection.v1.SimulationService/";

struct MethodRole {
  std::string_view service;  // "/<package>.<Service>/" as gRPC routes it
  std::string_view method;
  Role role;
};

// Every RPC of inspection.v1, by the full name gRPC routes it by (a test checks this table against
// the generated descriptors both ways). Reads are viewer; work on the rig or the archive is
// operator; what changes how the rig measures is engineer; what destroys data or overrides others
// is admin.
constexpr MethodRole kMethodRoles[] = {
    {kInspection, "GetRigStatus", Role::kViewer},
    {kInspection, "WatchJob", Role::kViewer},
    {kInspection, "GetJob", Role::kViewer},
    {kInspection, "ListJobs", Role::kViewer},
    {kInspection, "DownloadArtifact", Role::kViewer},
    {kInspection, "GetCalibration", Role::kViewer},
    {kInspection, "ListCalibrations", Role::kViewer},
    {kInspection, "GetRecipe", Role::kViewer},
    {kInspection, "ListRecipes", Role::kViewer},
    {kInspection, "Scan", Role::kOperator},
    {kInspection, "Reconstruct", Role::kOperator},
    {kInspection, "CancelJob", Role::kOperator},  // own jobs; the handler asks admin for others' jobs
    {kInspection, "ListResults", Role::kOperator},
    {kInspection, "WatchResults", Role::kOperator},
    {kInspection, "Calibrate", Role::kEngineer},
    {kInspection, "CreateRecipe", Role::kEngineer},
    {kInspection, "UpdateRecipe", Role::kEngineer},
    {kInspection, "DeleteRecipe", Role::kEngineer},
    {kInspection, "ResetRig", Role::kAdmin},
    {kInspection, "DeleteJob", Role::kAdmin},
    {kInspection, "DeleteScan", Role::kAdmin},
    {kInspection, "PinJob", Role::kAdmin},
    // Type-1 gauge studies: run by whoever approves the gauge, read by anyone.
    {kInspection, "StartStudy", Role::kEngineer},
    // Instrument verification: the metrologist's (engineer) job; its records are GetCalibration's.
    {kInspection, "Verify", Role::kEngineer},
    {kInspection, "GetStudy", Role::kViewer},
    {kInspection, "ListStudies", Role::kViewer},
    {kSimulation, "ListSpecimens", Role::kViewer},
    {kSimulation, "SetSpecimen", Role::kEngineer},
};

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

bool ConstantTimeEquals(const std::string& a, const std::string& b) {
  return a.size() == b.size() && CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

StatusOr<std::string> ReadText(const std::filesystem::path& path, const char* what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidArgument(std::string(what) + " '" + path.string() + "' cannot be read");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// "identity token" lines; a single bare token line is the legacy one-token file.
StatusOr<std::vector<std::pair<std::string, std::string>>> ParseTokens(const std::string& text) {
  std::vector<std::pair<std::string, std::string>> tokens;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  std::vector<std::string_view> bare;
  while (std::getline(in, line)) {
    ++line_no;
    std::string_view l = Trim(line);
    if (l.empty() || l.front() == '#') continue;
    const auto space = l.find_first_of(" \t");
    if (space == std::string_view::npos) {
      if (line_no > 1 || !tokens.empty()) {
        return Status::InvalidArgument("token file line " + std::to_string(line_no) + ": expected 'identity token'");
      }
      tokens.emplace_back(std::string(l), "token");
      continue;
    }
    std::string identity(Trim(l.substr(0, space)));
    std::string token(Trim(l.substr(space + 1)));
    if (token.size() < 16) {
      return Status::InvalidArgument("token file line " + std::to_string(line_no) + ": token of '" + identity +
                                     "' is shorter than 16 characters");
    }
    for (const auto& [t, id] : tokens) {
      if (id == identity) {
        return Status::InvalidArgument("token file line " + std::to_string(line_no) + ": identity '" + identity +
                                       "' has a token already (one token per identity)");
      }
      if (t == token) {
        return Status::InvalidArgument("token file line " + std::to_string(line_no) + ": token reused");
      }
    }
    tokens.emplace_back(std::move(token), std::move(identity));
  }
  return tokens;
}

}  // namespace

const char* RoleName(Role role) {
  switch (role) {
    case Role::kViewer:
      return "viewer";
    case Role::kOperator:
      return "operator";
    case Role::kEngineer:
      return "engineer";
    case Role::kAdmin:
      return "admin";
  }
  return "unknown";
}

StatusOr<Role> ParseRole(std::string_view name) {
  for (Role r : {Role::kViewer, Role::kOperator, Role::kEngineer, Role::kAdmin}) {
    if (name == RoleName(r)) return r;
  }
  return Status::InvalidArgument("unknown role '" + std::string(name) +
                                 "' (expected viewer, operator, engineer or admin)");
}

std::optional<Role> RequiredRole(std::string_view full_method) {
  for (const auto& m : kMethodRoles) {
    if (full_method.size() == m.service.size() + m.method.size() &&
        full_method.substr(0, m.service.size()) == m.service && full_method.substr(m.service.size()) == m.method) {
      return m.role;
    }
  }
  return std::nullopt;
}

std::vector<std::string> MethodsWithRoles() {
  std::vector<std::string> names;
  for (const auto& m : kMethodRoles) names.push_back(std::string(m.service) + std::string(m.method));
  return names;
}

std::string_view BareMethodName(std::string_view full_method) {
  const auto slash = full_method.rfind('/');
  return slash == std::string_view::npos ? full_method : full_method.substr(slash + 1);
}

CallerCredentials CredentialsFromContext(const grpc::ServerContextBase& context) {
  CallerCredentials c;
  const auto& md = context.client_metadata();
  if (auto it = md.find("authorization"); it != md.end()) {
    std::string_view v(it->second.data(), it->second.size());
    constexpr std::string_view kBearer = "Bearer ";
    if (v.substr(0, kBearer.size()) == kBearer) c.bearer_token = std::string(v.substr(kBearer.size()));
  }
  c.peer = context.peer();
  auto auth = context.auth_context();
  if (auth && auth->IsPeerAuthenticated()) {
    for (const auto& v : auth->FindPropertyValues("x509_common_name")) c.cert_names.emplace_back(v.data(), v.size());
    for (const auto& v : auth->FindPropertyValues("x509_subject_alternative_name")) {
      c.cert_names.emplace_back(v.data(), v.size());
    }
  }
  return c;
}

AccessPolicy AccessPolicy::Open() { return AccessPolicy(); }

StatusOr<AccessPolicy> AccessPolicy::Parse(const std::string& policy_json, const std::string& token_text,
                                           bool require_client_cert) {
  AccessPolicy p;
  p.enabled_ = true;
  p.require_client_cert_ = require_client_cert;
  INSPECT_ASSIGN_OR_RETURN(p.tokens_, ParseTokens(token_text));
  if (!policy_json.empty()) {
    p.have_policy_ = true;
    nlohmann::json j = nlohmann::json::parse(policy_json, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded() || !j.is_object()) return Status::InvalidArgument("policy: not a JSON object");
    for (auto it = j.begin(); it != j.end(); ++it) {
      if (it.key() != "identities" && it.key() != "default_role") {
        return Status::InvalidArgument("policy: unknown key '" + it.key() + "'");
      }
    }
    if (j.contains("identities")) {
      const auto& ids = j["identities"];
      if (!ids.is_object()) return Status::InvalidArgument("policy.identities: must be an object of identity: role");
      for (auto it = ids.begin(); it != ids.end(); ++it) {
        if (!it.value().is_string()) {
          return Status::InvalidArgument("policy.identities." + it.key() + ": role must be a string");
        }
        auto role = ParseRole(it.value().get<std::string>());
        if (!role.ok())
          return Status::InvalidArgument("policy.identities." + it.key() + ": " + role.status().message());
        p.roles_[it.key()] = *role;
      }
    }
    if (j.contains("default_role") && !j["default_role"].is_null()) {
      if (!j["default_role"].is_string()) return Status::InvalidArgument("policy.default_role: must be a string");
      auto role = ParseRole(j["default_role"].get<std::string>());
      if (!role.ok()) return Status::InvalidArgument("policy.default_role: " + role.status().message());
      p.default_role_ = *role;
    }
  }
  if (p.tokens_.empty() && !require_client_cert) {
    return Status::InvalidArgument("authentication configured without tokens or client certificates");
  }
  return p;
}

StatusOr<AccessPolicy> AccessPolicy::Load(const std::filesystem::path& policy_file,
                                          const std::filesystem::path& token_file, bool require_client_cert) {
  std::string policy, tokens;
  if (!policy_file.empty()) {
    INSPECT_ASSIGN_OR_RETURN(policy, ReadText(policy_file, "--policy"));
  }
  if (!token_file.empty()) {
    INSPECT_ASSIGN_OR_RETURN(tokens, ReadText(token_file, "--auth-token-file"));
  }
  return Parse(policy, tokens, require_client_cert);
}

StatusOr<Identity> AccessPolicy::Authenticate(const CallerCredentials& c) const {
  Identity id;
  id.peer = c.peer;
  if (!enabled_) {
    id.name = "anonymous";
    id.role = Role::kAdmin;
    return id;
  }
  // A token names an identity; otherwise the verified certificate does.
  std::vector<std::string> names;
  if (!c.bearer_token.empty()) {
    bool found = false;
    for (const auto& [token, identity] : tokens_) {
      // Compare every token so the time does not tell which one was close.
      if (ConstantTimeEquals(token, c.bearer_token) && !found) {
        names.push_back(identity);
        found = true;
      }
    }
    if (!found) return Status(StatusCode::kUnauthenticated, "unknown bearer token");
  } else if (!c.cert_names.empty()) {
    names = c.cert_names;
  } else {
    return Status(StatusCode::kUnauthenticated,
                  require_client_cert_ ? "no client certificate and no bearer token" : "missing bearer token");
  }
  if (!have_policy_) {  // tokens without a policy: every holder is trusted fully (legacy)
    id.name = names.front();
    id.role = Role::kAdmin;
    return id;
  }
  for (const auto& n : names) {
    if (auto it = roles_.find(n); it != roles_.end()) {
      id.name = n;
      id.role = it->second;
      return id;
    }
  }
  if (default_role_) {
    id.name = names.front();
    id.role = *default_role_;
    return id;
  }
  return Status(StatusCode::kPermissionDenied, "identity '" + names.front() + "' is not in the access policy");
}

Status CheckRole(const Identity& identity, Role required, std::string_view method) {
  if (static_cast<int>(identity.role) >= static_cast<int>(required)) return Status::Ok();
  return Status(StatusCode::kPermissionDenied, std::string(method) + " needs role " + RoleName(required) + "; '" +
                                                   identity.name + "' has role " + RoleName(identity.role));
}

void AccessControl::SetSource(std::filesystem::path policy_file, std::filesystem::path token_file,
                              bool require_client_cert) {
  std::lock_guard lock(mu_);
  policy_file_ = std::move(policy_file);
  token_file_ = std::move(token_file);
  require_client_cert_ = require_client_cert;
}

Status AccessControl::Reload() {
  std::filesystem::path policy_file, token_file;
  bool require_cert;
  {
    std::lock_guard lock(mu_);
    policy_file = policy_file_;
    token_file = token_file_;
    require_cert = require_client_cert_;
  }
  if (policy_file.empty() && token_file.empty() && !require_cert) return Status::Ok();  // nothing configured
  INSPECT_ASSIGN_OR_RETURN(AccessPolicy p, AccessPolicy::Load(policy_file, token_file, require_cert));
  std::lock_guard lock(mu_);
  policy_ = std::make_shared<const AccessPolicy>(std::move(p));
  return Status::Ok();
}

std::shared_ptr<const AccessPolicy> AccessControl::snapshot() const {
  std::lock_guard lock(mu_);
  return policy_;
}

StatusOr<Identity> AccessControl::Authorize(const CallerCredentials& credentials, std::string_view full_method) const {
  INSPECT_ASSIGN_OR_RETURN(Identity id, snapshot()->Authenticate(credentials));
  const std::optional<Role> required = RequiredRole(full_method);
  if (!required) {
    return Status(StatusCode::kPermissionDenied,
                  "no access rule for " + std::string(full_method) + ": refused until the role table names one");
  }
  INSPECT_RETURN_IF_ERROR(CheckRole(id, *required, BareMethodName(full_method)));
  return id;
}

}  // namespace inspection
