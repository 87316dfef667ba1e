// Trust on the factory network, end to end through the real server on loopback: mTLS identities
// and roles per RPC, named tokens, job owners and who may cancel, certificate reload without a
// restart, plaintext only on loopback, reflection off with authentication, bounded free text,
// and user scenes by name only.
#include <grpcpp/generic/generic_stub.h>
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <future>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <sstream>

#include "server/security/access_control.h"
#include "tests/server/server_fixture.h"
#include "tests/server/test_certs.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

class SecurityTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    pki_ = UniqueTempDir("pki");
    ca_ = MakeCertificate("Test Factory CA", "", nullptr, 1);
    other_ca_ = MakeCertificate("Other CA", "", nullptr, 2);
    const KeyAndCert server = MakeCertificate("inspectd", "DNS:localhost,IP:127.0.0.1", &ca_, 10);
    WriteText(pki_ / "ca.pem", ca_.cert_pem);
    WriteText(pki_ / "server.pem", server.cert_pem);
    WriteText(pki_ / "server.key", server.key_pem);
    WriteText(pki_ / "client-ca.pem", ca_.cert_pem);
    ClientCert("alice", "", ca_, 20);                                   // operator by CN
    ClientCert("station 7", "DNS:station-7.factory.example", ca_, 21);  // operator by SAN
    ClientCert("qa-lead", "", ca_, 22);                                 // engineer
    ClientCert("line3-viewer", "", ca_, 23);                            // viewer
    ClientCert("intruder", "", other_ca_, 24);                          // admin, but from an untrusted CA
    WriteText(pki_ / "policy.json",
              R"({"identities": {"alice": "operator", "station-7.factory.example": "operator",
                                 "qa-lead": "engineer", "line3-viewer": "viewer", "bob": "operator",
                                 "it-admin": "admin", "intruder": "admin"}})");
    WriteText(pki_ / "tokens",
              "# identity token\n"
              "alice al-0123456789abcdef\n"
              "bob bo-0123456789abcdef\n"
              "line3-viewer lv-0123456789abcdef\n"
              "it-admin ad-0123456789abcdef\n");
  }
  void TearDown() override {
    ServerTest::TearDown();
    fs::remove_all(pki_);
  }
  void ClientCert(const std::string& cn, const std::string& sans, const KeyAndCert& ca, long serial) {
    const KeyAndCert c = MakeCertificate(cn, sans, &ca, serial);
    WriteText(pki_ / (cn + ".pem"), c.cert_pem);
    WriteText(pki_ / (cn + ".key"), c.key_pem);
  }
  ServerOptions BaseOptions() {
    ServerOptions opt;
    opt.listen_address = "127.0.0.1:0";
    opt.data_dir = data_dir_;
    opt.simulation = SimOptions();
    return opt;
  }
  ServerOptions MtlsOptions() {
    ServerOptions opt = BaseOptions();
    opt.tls_cert_file = (pki_ / "server.pem").string();
    opt.tls_key_file = (pki_ / "server.key").string();
    opt.tls_client_ca_file = (pki_ / "client-ca.pem").string();
    opt.policy_file = (pki_ / "policy.json").string();
    opt.tls_reload_interval_s = 1;
    return opt;
  }
  ServerOptions TokenOptions() {
    ServerOptions opt = BaseOptions();
    opt.token_file = (pki_ / "tokens").string();
    opt.policy_file = (pki_ / "policy.json").string();
    return opt;
  }
  void Start(const ServerOptions& opt) {
    auto server = InspectionServer::Start(opt);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
  }
  // A client presenting the certificate of `cn` (none when empty), trusting `ca_file`.
  std::unique_ptr<client::InspectionClient> WithCert(const std::string& cn, const std::string& ca_file = "") {
    client::ClientOptions co;
    co.target = server_->address();
    co.tls_ca_file = ca_file.empty() ? (pki_ / "ca.pem").string() : ca_file;
    co.connect_timeout_seconds = 5;
    if (!cn.empty()) {
      co.tls_client_cert_file = (pki_ / (cn + ".pem")).string();
      co.tls_client_key_file = (pki_ / (cn + ".key")).string();
    }
    return std::make_unique<client::InspectionClient>(co);
  }
  std::unique_ptr<client::InspectionClient> WithToken(const std::string& token) {
    client::ClientOptions co;
    co.target = server_->address();
    co.auth_token = token;
    return std::make_unique<client::InspectionClient>(co);
  }
  // Calls the reflection service with a list_services request, as grpcurl would.
  grpc::Status CallReflection() {
    auto channel = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
    grpc::GenericStub stub(channel);
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    const char request_bytes[] = {0x3a, 0x00};  // ServerReflectionRequest{list_services: ""}
    grpc::Slice slice(request_bytes, sizeof(request_bytes));
    grpc::ByteBuffer request(&slice, 1), response;
    std::promise<grpc::Status> done;
    stub.UnaryCall(&ctx, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", grpc::StubOptions(),
                   &request, &response, [&](grpc::Status s) { done.set_value(s); });
    return done.get_future().get();
  }

  std::string AuditText() {
    std::ifstream in(server_->audit_log_path());
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  std::vector<nlohmann::json> Audit() {
    std::vector<nlohmann::json> out;
    std::istringstream in(AuditText());
    std::string line;
    while (std::getline(in, line)) out.push_back(nlohmann::json::parse(line));
    return out;
  }

  fs::path pki_;
  KeyAndCert ca_, other_ca_;
};

TEST_F(SecurityTest, ClientCertificatesNameTheCallerAndRolesGateEveryCall) {
  Start(MtlsOptions());
  v1::RigStatus st;
  ASSERT_TRUE(WithCert("line3-viewer")->GetRigStatus(&st).ok());

  // A viewer may read but not scan; the message names the missing role.
  v1::Job job;
  grpc::Status denied = WithCert("line3-viewer")->Scan(v1::ScanRequest(), {}, &job);
  EXPECT_EQ(denied.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(denied.error_message(), "Scan needs role operator; 'line3-viewer' has role viewer");

  // alice (operator by CN) scans; the job records her as its owner. Calibrate needs engineer.
  v1::ScanRequest scan;
  scan.set_label("part-4711");
  ASSERT_TRUE(WithCert("alice")->Scan(scan, {}, &job).ok());
  EXPECT_EQ(job.owner(), "alice");
  v1::Job stored;
  ASSERT_TRUE(WithCert("line3-viewer")->GetJob(job.job_id(), &stored).ok());
  EXPECT_EQ(stored.owner(), "alice");
  grpc::Status calibrate = WithCert("alice")->Calibrate(v1::CalibrateRequest(), {}, &job);
  EXPECT_EQ(calibrate.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(calibrate.error_message(), "Calibrate needs role engineer; 'alice' has role operator");
  // So does an instrument verification: refused before any job is queued.
  grpc::Status verify = WithCert("alice")->Verify(v1::VerifyRequest(), {}, &job);
  EXPECT_EQ(verify.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(verify.error_message(), "Verify needs role engineer; 'alice' has role operator");
  verify = WithCert("line3-viewer")->Verify(v1::VerifyRequest(), {}, &job);
  EXPECT_EQ(verify.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(verify.error_message(), "Verify needs role engineer; 'line3-viewer' has role viewer");

  // The policy matches a subject alternative name as well as the CN.
  ASSERT_TRUE(WithCert("station 7")->Scan(scan, {}, &job).ok());
  EXPECT_EQ(job.owner(), "station-7.factory.example");

  grpc::Status reset = WithCert("qa-lead")->ResetRig(&st);
  EXPECT_EQ(reset.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(reset.error_message(), "ResetRig needs role admin; 'qa-lead' has role engineer");
  v1::ListSpecimensResponse specimens;
  EXPECT_TRUE(WithCert("qa-lead")->SetSpecimen("lens", &specimens).ok());
  EXPECT_EQ(WithCert("alice")->SetSpecimen("lens", &specimens).error_code(), grpc::StatusCode::PERMISSION_DENIED);

  // No certificate, or one from a CA the server does not trust: the handshake fails.
  EXPECT_EQ(WithCert("")->GetRigStatus(&st).error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(WithCert("intruder")->GetRigStatus(&st).error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_TRUE(server_->authentication_enabled());
  EXPECT_FALSE(server_->reflection_enabled());
}

TEST_F(SecurityTest, OperatorsCancelOnlyTheirOwnJobsAdminsAny) {
  Start(TokenOptions());
  v1::Job job;
  ASSERT_TRUE(WithToken("al-0123456789abcdef")->Scan(v1::ScanRequest(), {}, &job).ok());
  EXPECT_EQ(job.owner(), "alice");
  v1::Job out;
  grpc::Status other = WithToken("bo-0123456789abcdef")->CancelJob(job.job_id(), &out);
  EXPECT_EQ(other.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(other.error_message(),
            "CancelJob of another identity's job ('alice') needs role admin; 'bob' has role operator");
  EXPECT_TRUE(WithToken("al-0123456789abcdef")->CancelJob(job.job_id(), &out).ok());
  EXPECT_TRUE(WithToken("ad-0123456789abcdef")->CancelJob(job.job_id(), &out).ok());
  EXPECT_EQ(out.state(), v1::JOB_STATE_SUCCEEDED);  // it had ended: returned unchanged
  // Deleting and pinning are the admin's.
  v1::DeleteResponse deleted;
  grpc::Status del = WithToken("al-0123456789abcdef")->DeleteJob(job.job_id(), &deleted);
  EXPECT_EQ(del.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(del.error_message(), "DeleteJob needs role admin; 'alice' has role operator");
  v1::PinJobResponse pin;
  EXPECT_EQ(WithToken("al-0123456789abcdef")->PinJob(job.job_id(), true, &pin).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_TRUE(WithToken("ad-0123456789abcdef")->PinJob(job.job_id(), true, &pin).ok());
  EXPECT_TRUE(WithToken("ad-0123456789abcdef")->DeleteJob(job.job_id(), &deleted).ok());
}

TEST_F(SecurityTest, AuditLogHoldsMutatingAndDeniedCallsWithoutSecrets) {
  ServerOptions opt = TokenOptions();
  opt.audit_log = pki_ / "audit" / "inspectd-audit.jsonl";
  Start(opt);
  ASSERT_EQ(server_->audit_log_path(), opt.audit_log);
  v1::RigStatus st;
  v1::Job job;
  EXPECT_EQ(WithToken("")->GetRigStatus(&st).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(WithToken("zz-0123456789abcdef")->GetRigStatus(&st).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  v1::ScanRequest scan;
  scan.set_label("part-4711-secret-label");
  EXPECT_EQ(WithToken("lv-0123456789abcdef")->Scan(scan, {}, &job).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  ASSERT_TRUE(WithToken("lv-0123456789abcdef")->GetRigStatus(&st).ok());  // a read: not audited
  ASSERT_TRUE(WithToken("al-0123456789abcdef")->Scan(scan, {}, &job).ok());
  const std::string scan_id = job.job_id();
  v1::Job out;
  EXPECT_EQ(WithToken("bo-0123456789abcdef")->CancelJob(scan_id, &out).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  v1::ListSpecimensResponse specimens;
  EXPECT_TRUE(WithToken("ad-0123456789abcdef")->SetSpecimen("lens", &specimens).ok());

  const std::vector<nlohmann::json> audit = Audit();
  ASSERT_EQ(audit.size(), 6u) << AuditText();
  EXPECT_EQ(audit[0]["method"], "GetRigStatus");
  EXPECT_EQ(audit[0]["identity"], "(none)");
  EXPECT_EQ(audit[0]["code"], "UNAUTHENTICATED");
  EXPECT_EQ(audit[1]["identity"], "(unknown token)");
  EXPECT_EQ(audit[2]["method"], "Scan");
  EXPECT_EQ(audit[2]["identity"], "line3-viewer");
  EXPECT_EQ(audit[2]["role"], "viewer");
  EXPECT_EQ(audit[2]["code"], "PERMISSION_DENIED");
  EXPECT_EQ(audit[2]["message"], "Scan needs role operator; 'line3-viewer' has role viewer");
  EXPECT_EQ(audit[3]["method"], "Scan");
  EXPECT_EQ(audit[3]["identity"], "alice");
  EXPECT_EQ(audit[3]["role"], "operator");
  EXPECT_EQ(audit[3]["code"], "OK");
  EXPECT_EQ(audit[3]["target"], scan_id);
  EXPECT_EQ(audit[3]["peer"].get<std::string>().rfind("ipv4:127.0.0.1:", 0), 0u);
  EXPECT_EQ(audit[4]["method"], "CancelJob");
  EXPECT_EQ(audit[4]["identity"], "bob");
  EXPECT_EQ(audit[4]["target"], scan_id);
  EXPECT_EQ(audit[4]["code"], "PERMISSION_DENIED");
  EXPECT_EQ(audit[5]["method"], "SetSpecimen");
  EXPECT_EQ(audit[5]["identity"], "it-admin");
  EXPECT_EQ(audit[5]["target"], "lens");
  for (const auto& r : audit) EXPECT_FALSE(r["time"].get<std::string>().empty());
  // Never a token (not even the unknown one) and never the request's free text.
  const std::string text = AuditText();
  EXPECT_EQ(text.find("0123456789abcdef"), std::string::npos);
  EXPECT_EQ(text.find("secret-label"), std::string::npos);
}

TEST_F(SecurityTest, NamedTokensOnPlaintextLoopback) {
  Start(TokenOptions());
  v1::RigStatus st;
  grpc::Status none = WithToken("")->GetRigStatus(&st);
  EXPECT_EQ(none.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(none.error_message(), "missing bearer token");
  grpc::Status unknown = WithToken("xx-0123456789abcdef")->GetRigStatus(&st);
  EXPECT_EQ(unknown.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(unknown.error_message(), "unknown bearer token");
  EXPECT_TRUE(WithToken("lv-0123456789abcdef")->GetRigStatus(&st).ok());
  v1::Job job;
  EXPECT_EQ(WithToken("lv-0123456789abcdef")->CancelJob("scan-1", &job).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  // Reflection is off because authentication is configured: the service is not there at all.
  EXPECT_EQ(CallReflection().error_code(), grpc::StatusCode::UNIMPLEMENTED);
}

// The role table and the services agree both ways, and every method of every service is decided
// before its handler: each one, called with no credentials, answers UNAUTHENTICATED.
TEST_F(SecurityTest, EveryMethodOfEveryServiceHasARuleAndIsRefusedWithoutCredentials) {
  const google::protobuf::FileDescriptor* file = v1::ScanRequest::descriptor()->file();
  std::set<std::string> methods;
  for (int s = 0; s < file->service_count(); ++s) {
    const google::protobuf::ServiceDescriptor* service = file->service(s);
    for (int m = 0; m < service->method_count(); ++m) {
      const std::string full = "/" + service->full_name() + "/" + service->method(m)->name();
      EXPECT_TRUE(RequiredRole(full).has_value()) << full << " has no access rule";
      methods.insert(full);
    }
  }
  EXPECT_EQ(methods.size(), 28u);  // 26 InspectionService + 2 SimulationService
  const std::vector<std::string> ruled = MethodsWithRoles();
  EXPECT_EQ(std::set<std::string>(ruled.begin(), ruled.end()), methods) << "rules for methods no service has";

  Start(TokenOptions());
  auto channel = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  for (const std::string& full : methods) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    grpc::Slice slice("", 0);  // the empty request of every method (a stream's first message)
    grpc::ByteBuffer request(&slice, 1), response;
    std::promise<grpc::Status> done;
    stub.UnaryCall(&ctx, full, grpc::StubOptions(), &request, &response, [&](grpc::Status s) { done.set_value(s); });
    const grpc::Status s = done.get_future().get();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED) << full << ": " << s.error_message();
    EXPECT_EQ(s.error_message(), "missing bearer token") << full;
  }
}

TEST_F(SecurityTest, ReflectionStaysOnWithoutAuthentication) {
  Start(BaseOptions());
  EXPECT_FALSE(server_->authentication_enabled());
  EXPECT_TRUE(CallReflection().ok());
  v1::Job job;
  ASSERT_TRUE(WithToken("")->Scan(v1::ScanRequest(), {}, &job).ok());
  EXPECT_EQ(job.owner(), "anonymous");
}

TEST_F(SecurityTest, NewServerCertificateIsServedWithoutRestart) {
  Start(MtlsOptions());
  v1::RigStatus st;
  ASSERT_TRUE(WithCert("alice")->GetRigStatus(&st).ok());
  // The admin rotates the server certificate to one from a new CA; clients that trust only the
  // new CA connect once the server has re-read its files (checked every second).
  const KeyAndCert new_ca = MakeCertificate("New Factory CA", "", nullptr, 3);
  const KeyAndCert renewed = MakeCertificate("inspectd", "DNS:localhost,IP:127.0.0.1", &new_ca, 11);
  WriteText(pki_ / "new-ca.pem", new_ca.cert_pem);
  EXPECT_EQ(WithCert("alice", (pki_ / "new-ca.pem").string())->GetRigStatus(&st).error_code(),
            grpc::StatusCode::UNAVAILABLE);
  WriteText(pki_ / "server.key", renewed.key_pem);
  WriteText(pki_ / "server.pem", renewed.cert_pem);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  grpc::Status s;
  int attempts = 0;
  do {
    s = WithCert("alice", (pki_ / "new-ca.pem").string())->GetRigStatus(&st);
    ++attempts;
  } while (!s.ok() && std::chrono::steady_clock::now() < deadline);
  EXPECT_TRUE(s.ok()) << s.error_message() << " after " << attempts << " attempts";
  // and a client that trusts only the old CA no longer does.
  EXPECT_EQ(WithCert("alice")->GetRigStatus(&st).error_code(), grpc::StatusCode::UNAVAILABLE);
}

TEST_F(SecurityTest, PlaintextBeyondLoopbackNeedsInsecure) {
  ServerOptions opt = BaseOptions();
  opt.listen_address = "0.0.0.0:0";
  auto refused = InspectionServer::Start(opt);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(refused.status().message(),
            "plaintext listening on 0.0.0.0:0 is allowed only on loopback: give --tls-cert/--tls-key, or --insecure");
  opt.insecure = true;
  auto allowed = InspectionServer::Start(opt);
  EXPECT_TRUE(allowed.ok()) << allowed.status().ToString();
}

TEST_F(SecurityTest, PolicyWithoutIdentitiesIsRefusedAtStart) {
  ServerOptions opt = BaseOptions();
  opt.policy_file = (pki_ / "policy.json").string();
  auto refused = InspectionServer::Start(opt);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().message(),
            "policy_file needs identities: token_file or tls_client_ca (client certificates)");
}

TEST_F(SecurityTest, FreeTextIsBoundedAndNamesTheField) {
  Start(BaseOptions());
  auto c = WithToken("");
  v1::Job job;
  v1::ScanRequest big;
  big.set_label(std::string(3 << 20, 'x'));
  grpc::Status s = c->Scan(big, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message(), "label is 3145728 bytes; at most 256");
  v1::ScanRequest long_id;
  long_id.set_request_id(std::string(257, 'r'));
  s = c->Scan(long_id, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message(), "request_id is 257 bytes; at most 256");
  v1::ReconstructStart start;
  start.set_scan_id("scan-1");
  start.set_label(std::string(1000, 'l'));
  s = c->ReconstructStored(start, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message(), "start.label is 1000 bytes; at most 256");
  s = c->GetJob(std::string(300, 'j'), &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message(), "job_id is 300 bytes; at most 256");
  // Exactly at the limit is fine, and nothing above was stored.
  v1::ScanRequest at_limit;
  at_limit.set_label(std::string(256, 'x'));
  ASSERT_TRUE(c->Scan(at_limit, {}, &job).ok());
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(c->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  ASSERT_EQ(jobs.jobs_size(), 1);
  EXPECT_EQ(jobs.jobs(0).label().size(), 256u);
}

TEST_F(SecurityTest, UserScenesByNameFromTheSceneDirectoryOnly) {
  const fs::path scenes = pki_ / "scenes";
  fs::create_directories(scenes);
  cv::Mat height(240, 320, CV_8UC1);
  for (int y = 0; y < height.rows; ++y) height.row(y).setTo(y);
  ASSERT_TRUE(cv::imwrite((scenes / "ramp.png").string(), height));
  WriteText(scenes / "ramp.json", R"({"height": "ramp.png", "height_scale_um": 100})");
  WriteText(pki_ / "secret.json", R"({"height": "ramp.png"})");
  ServerOptions opt = BaseOptions();
  opt.scene_dir = scenes;
  Start(opt);
  auto c = WithToken("");
  v1::ListSpecimensResponse list;
  // A path is refused whether or not the file exists: the answer tells nothing about the disk.
  const std::string refused =
      "is not a specimen name: give a built-in specimen or the name of a scene in the server's scene directory "
      "(--scene-dir), not a path";
  for (const std::string& path : {"file:" + (pki_ / "secret.json").string(), std::string("file:/no/such.json"),
                                  std::string("../secret"), std::string("/etc/passwd")}) {
    grpc::Status s = c->SetSpecimen(path, &list);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << path;
    EXPECT_EQ(s.error_message(), "specimen '" + path + "' " + refused) << path;
  }
  grpc::Status unknown = c->SetSpecimen("secret", &list);
  EXPECT_EQ(unknown.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(unknown.error_message().find("unknown specimen 'secret'; known: plane,"), std::string::npos);
  ASSERT_TRUE(c->SetSpecimen("ramp", &list).ok());
  EXPECT_EQ(list.current(), "ramp");
  EXPECT_EQ(list.specimens(list.specimens_size() - 1), "ramp");
}

}  // namespace
}  // namespace inspection::testing
