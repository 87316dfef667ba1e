// Access policy: identities from tokens and certificates, roles per RPC, the codes a caller gets.
#include "server/security/access_control.h"

#include <gtest/gtest.h>

#include <fstream>

namespace inspection {
namespace {

const char* kTokens =
    "# identity token\n"
    "station-7 s7-0123456789abcdef\n"
    "qa-lead   qa-0123456789abcdef\n"
    "it-admin  ad-0123456789abcdef\n"
    "stranger  st-0123456789abcdef\n";

const char* kPolicy = R"({"identities": {"station-7": "operator", "qa-lead": "engineer", "it-admin": "admin",
                          "line3.factory.example": "viewer"}})";

std::string Rpc(std::string_view method) { return "/inspection.v1.InspectionService/" + std::string(method); }

CallerCredentials Token(std::string t) {
  CallerCredentials c;
  c.bearer_token = std::move(t);
  c.peer = "ipv4:127.0.0.1:4242";
  return c;
}

TEST(AccessControlTest, RoleTableFollowsTheIssueLadder) {
  EXPECT_EQ(RequiredRole(Rpc("GetRigStatus")), Role::kViewer);
  EXPECT_EQ(RequiredRole(Rpc("DownloadArtifact")), Role::kViewer);
  EXPECT_EQ(RequiredRole(Rpc("WatchJob")), Role::kViewer);
  EXPECT_EQ(RequiredRole(Rpc("Scan")), Role::kOperator);
  EXPECT_EQ(RequiredRole(Rpc("Reconstruct")), Role::kOperator);
  EXPECT_EQ(RequiredRole(Rpc("CancelJob")), Role::kOperator);
  EXPECT_EQ(RequiredRole(Rpc("Calibrate")), Role::kEngineer);
  EXPECT_EQ(RequiredRole("/inspection.v1.SimulationService/SetSpecimen"), Role::kEngineer);
  EXPECT_EQ(RequiredRole(Rpc("CreateRecipe")), Role::kEngineer);
  EXPECT_EQ(RequiredRole(Rpc("ResetRig")), Role::kAdmin);
  EXPECT_EQ(RequiredRole(Rpc("DeleteJob")), Role::kAdmin);
  EXPECT_EQ(RequiredRole(Rpc("StartStudy")), Role::kEngineer);  // approving a gauge
  EXPECT_EQ(RequiredRole(Rpc("Verify")), Role::kEngineer);      // verifying the instrument
  EXPECT_EQ(RequiredRole(Rpc("GetStudy")), Role::kViewer);
  EXPECT_EQ(RequiredRole(Rpc("ListStudies")), Role::kViewer);
  // A method nobody classified has no rule, and Authorize refuses it even to an admin.
  EXPECT_FALSE(RequiredRole(Rpc("SomeFutureRpc")).has_value());
  EXPECT_FALSE(RequiredRole("Scan").has_value());  // bare names are not what gRPC routes by
  auto p = AccessPolicy::Parse(kPolicy, kTokens, false);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  AccessControl ac(std::move(*p));
  auto future = ac.Authorize(Token("ad-0123456789abcdef"), Rpc("SomeFutureRpc"));
  EXPECT_EQ(future.status().code(), StatusCode::kPermissionDenied);
  EXPECT_EQ(
      future.status().message(),
      "no access rule for /inspection.v1.InspectionService/SomeFutureRpc: refused until the role table names one");
}

TEST(AccessControlTest, TokensMapToIdentitiesAndRoles) {
  auto p = AccessPolicy::Parse(kPolicy, kTokens, false);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  AccessControl ac(std::move(*p));
  auto op = ac.Authorize(Token("s7-0123456789abcdef"), Rpc("Scan"));
  ASSERT_TRUE(op.ok()) << op.status().ToString();
  EXPECT_EQ(op->name, "station-7");
  EXPECT_EQ(op->role, Role::kOperator);
  EXPECT_EQ(op->peer, "ipv4:127.0.0.1:4242");

  auto denied = ac.Authorize(Token("s7-0123456789abcdef"), Rpc("Calibrate"));
  ASSERT_FALSE(denied.ok());
  EXPECT_EQ(denied.status().code(), StatusCode::kPermissionDenied);
  EXPECT_EQ(denied.status().message(), "Calibrate needs role engineer; 'station-7' has role operator");

  EXPECT_TRUE(ac.Authorize(Token("qa-0123456789abcdef"), Rpc("Calibrate")).ok());
  EXPECT_EQ(ac.Authorize(Token("qa-0123456789abcdef"), Rpc("ResetRig")).status().code(), StatusCode::kPermissionDenied);
  EXPECT_TRUE(ac.Authorize(Token("ad-0123456789abcdef"), Rpc("ResetRig")).ok());
}

TEST(AccessControlTest, MissingOrUnknownCredentialsAreUnauthenticated) {
  auto p = AccessPolicy::Parse(kPolicy, kTokens, false);
  ASSERT_TRUE(p.ok());
  AccessControl ac(std::move(*p));
  EXPECT_EQ(ac.Authorize(Token(""), Rpc("GetRigStatus")).status().code(), StatusCode::kUnauthenticated);
  EXPECT_EQ(ac.Authorize(Token("s7-0123456789abcdeX"), Rpc("GetRigStatus")).status().code(),
            StatusCode::kUnauthenticated);
  // A valid token whose identity the policy does not list: known, but not allowed anything.
  auto stranger = ac.Authorize(Token("st-0123456789abcdef"), Rpc("GetRigStatus"));
  EXPECT_EQ(stranger.status().code(), StatusCode::kPermissionDenied);
  EXPECT_NE(stranger.status().message().find("stranger"), std::string::npos);
}

TEST(AccessControlTest, CertificateNamesMatchCnOrSan) {
  auto p = AccessPolicy::Parse(kPolicy, "", /*require_client_cert=*/true);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  AccessControl ac(std::move(*p));
  CallerCredentials by_cn;
  by_cn.cert_names = {"station-7", "station-7.factory.example"};
  auto a = ac.Authorize(by_cn, Rpc("Scan"));
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->name, "station-7");
  CallerCredentials by_san;
  by_san.cert_names = {"Line 3 viewer", "line3.factory.example"};
  auto b = ac.Authorize(by_san, Rpc("ListJobs"));
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->name, "line3.factory.example");
  EXPECT_EQ(b->role, Role::kViewer);
  EXPECT_EQ(ac.Authorize(by_san, Rpc("Scan")).status().code(), StatusCode::kPermissionDenied);
  CallerCredentials none;
  auto c = ac.Authorize(none, Rpc("ListJobs"));
  EXPECT_EQ(c.status().code(), StatusCode::kUnauthenticated);
  EXPECT_EQ(c.status().message(), "no client certificate and no bearer token");
}

TEST(AccessControlTest, DefaultRoleAndLegacySingleToken) {
  auto p = AccessPolicy::Parse(R"({"identities": {}, "default_role": "viewer"})", "", true);
  ASSERT_TRUE(p.ok());
  CallerCredentials someone;
  someone.cert_names = {"bench-12"};
  auto id = p->Authenticate(someone);
  ASSERT_TRUE(id.ok());
  EXPECT_EQ(id->role, Role::kViewer);

  // The earlier one-line token file: its holder may do everything, as before.
  auto legacy = AccessPolicy::Parse("", "the-only-token\n", false);
  ASSERT_TRUE(legacy.ok()) << legacy.status().ToString();
  auto l = legacy->Authenticate(Token("the-only-token"));
  ASSERT_TRUE(l.ok());
  EXPECT_EQ(l->name, "token");
  EXPECT_EQ(l->role, Role::kAdmin);

  auto open = AccessPolicy::Open().Authenticate(CallerCredentials{});
  ASSERT_TRUE(open.ok());
  EXPECT_EQ(open->name, "anonymous");
  EXPECT_FALSE(AccessPolicy::Open().enabled());
}

TEST(AccessControlTest, BadPolicyFilesNameTheProblem) {
  auto msg = [](const std::string& policy, const std::string& tokens) {
    auto p = AccessPolicy::Parse(policy, tokens, true);
    EXPECT_FALSE(p.ok());
    return p.ok() ? std::string() : p.status().message();
  };
  EXPECT_EQ(msg(R"({"identities": {"a": "root"}})", ""),
            "policy.identities.a: unknown role 'root' (expected viewer, operator, engineer or admin)");
  EXPECT_EQ(msg(R"({"identitys": {}})", ""), "policy: unknown key 'identitys'");
  EXPECT_EQ(msg("[1,2]", ""), "policy: not a JSON object");
  EXPECT_EQ(msg("{", ""), "policy: not a JSON object");
  EXPECT_EQ(msg("", "a short\n"), "token file line 1: token of 'a' is shorter than 16 characters");
  EXPECT_EQ(msg("", "a 0123456789abcdef01\na 0123456789abcdef02\n"),
            "token file line 2: identity 'a' has a token already (one token per identity)");
  EXPECT_EQ(msg("", "a 0123456789abcdef01\nb 0123456789abcdef01\n"), "token file line 2: token reused");
  auto none = AccessPolicy::Parse("{}", "", false);
  EXPECT_EQ(none.status().code(), StatusCode::kInvalidArgument);
}

TEST(AccessControlTest, ReloadSwapsThePolicyAndKeepsTheOldOneOnError) {
  const auto dir = std::filesystem::temp_directory_path() / ("ac-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto policy = dir / "policy.json";
  const auto tokens = dir / "tokens";
  std::ofstream(tokens) << kTokens;
  std::ofstream(policy) << kPolicy;
  auto p = AccessPolicy::Load(policy, tokens, false);
  ASSERT_TRUE(p.ok());
  AccessControl ac(std::move(*p));
  ac.SetSource(policy, tokens, false);
  EXPECT_EQ(ac.Authorize(Token("s7-0123456789abcdef"), Rpc("Calibrate")).status().code(),
            StatusCode::kPermissionDenied);

  std::ofstream(policy, std::ios::trunc) << R"({"identities": {"station-7": "engineer"}})";
  ASSERT_TRUE(ac.Reload().ok());
  EXPECT_TRUE(ac.Authorize(Token("s7-0123456789abcdef"), Rpc("Calibrate")).ok());

  std::ofstream(policy, std::ios::trunc) << R"({"identities": {"station-7": "superuser"}})";
  EXPECT_EQ(ac.Reload().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(ac.Authorize(Token("s7-0123456789abcdef"), Rpc("Calibrate")).ok());  // old policy kept
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace inspection
