// The HTTP port (metrics and dashboard) under the gRPC port's security, through real HTTPS
// requests (cpp-httplib's client) against the real server: with mTLS, client certificates from
// the client CA are required and name the caller, whose role comes from the same access policy
// (viewer or higher reads; an identity the policy does not list is 403, no certificate 401, a
// certificate from another CA fails the handshake); a policy reload applies to HTTP as to gRPC;
// with named tokens and a policy, the data routes need a listed token.
#include <gtest/gtest.h>

#include "tests/server/server_fixture.h"
#include "tests/server/test_certs.h"

// Last: httplib.h pulls in <resolv.h>, whose `_res` macro breaks Eigen's headers.
#include <httplib.h>

namespace inspection::testing {
namespace {

namespace fs = std::filesystem;

class HttpSecurityTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    pki_ = UniqueTempDir("http_pki");
    ca_ = MakeCertificate("Test Factory CA", "", nullptr, 1);
    const KeyAndCert other_ca = MakeCertificate("Other CA", "", nullptr, 2);
    const KeyAndCert server = MakeCertificate("inspectd", "DNS:localhost,IP:127.0.0.1", &ca_, 10);
    WriteText(pki_ / "ca.pem", ca_.cert_pem);
    WriteText(pki_ / "server.pem", server.cert_pem);
    WriteText(pki_ / "server.key", server.key_pem);
    ClientCert("line3-viewer", "", ca_, 20);                            // viewer by CN
    ClientCert("station 7", "DNS:station-7.factory.example", ca_, 21);  // operator by SAN
    ClientCert("stranger", "", ca_, 22);                                // from the CA, not in the policy
    ClientCert("intruder", "", other_ca, 23);                           // admin, but from an untrusted CA
    WritePolicy(R"({"identities": {"line3-viewer": "viewer", "station-7.factory.example": "operator",
                                   "intruder": "admin", "it-admin": "admin"}})");
    WriteText(pki_ / "tokens", "line3-viewer lv-0123456789abcdef\nit-admin ad-0123456789abcdef\n");
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
  void WritePolicy(const std::string& json) { WriteText(pki_ / "policy.json", json); }

  void Start(bool mtls) {
    ServerOptions opt;
    opt.listen_address = "127.0.0.1:0";
    opt.http_listen_address = "127.0.0.1:0";
    opt.data_dir = data_dir_;
    opt.simulation = SimOptions();
    opt.policy_file = (pki_ / "policy.json").string();
    if (mtls) {
      opt.tls_cert_file = (pki_ / "server.pem").string();
      opt.tls_key_file = (pki_ / "server.key").string();
      opt.tls_client_ca_file = (pki_ / "ca.pem").string();
    } else {
      opt.token_file = (pki_ / "tokens").string();
    }
    auto server = InspectionServer::Start(opt);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    ASSERT_GT(server_->http_port(), 0);
  }

  // An HTTPS client that verifies the server against the test CA and presents the certificate
  // of `cn` (none when empty).
  std::unique_ptr<httplib::SSLClient> Https(const std::string& cn) {
    auto c = cn.empty() ? std::make_unique<httplib::SSLClient>("127.0.0.1", server_->http_port())
                        : std::make_unique<httplib::SSLClient>("127.0.0.1", server_->http_port(),
                                                               (pki_ / (cn + ".pem")).string(),
                                                               (pki_ / (cn + ".key")).string());
    c->set_ca_cert_path((pki_ / "ca.pem").string().c_str());
    c->enable_server_certificate_verification(true);
    return c;
  }
  // Status of GET `path` with the certificate of `cn`; -1 when no HTTP answer came.
  int Status(const std::string& cn, const std::string& path, const httplib::Headers& headers = {}) {
    auto res = Https(cn)->Get(path, headers);
    return res ? res->status : -1;
  }

  fs::path pki_;
  KeyAndCert ca_;
};

TEST_F(HttpSecurityTest, MtlsRequiresAClientCertificateAndMapsItToTheGrpcRoles) {
  Start(/*mtls=*/true);
  // No certificate: the handshake completes, the data routes answer 401 saying why.
  auto none = Https("")->Get("/metrics");
  ASSERT_TRUE(none) << httplib::to_string(none.error());
  EXPECT_EQ(none->status, 401);
  EXPECT_NE(none->body.find("client certificate required"), std::string::npos) << none->body;
  EXPECT_EQ(Status("", "/api/status"), 401);
  EXPECT_EQ(Status("", "/"), 200) << "the page itself holds no data";

  // A viewer by CN, an operator by SAN: both may read.
  auto viewer = Https("line3-viewer")->Get("/metrics");
  ASSERT_TRUE(viewer) << httplib::to_string(viewer.error());
  EXPECT_EQ(viewer->status, 200) << viewer->body;
  EXPECT_NE(viewer->body.find("\ninspectd_rig_state{state=\"ready\"} 1\n"), std::string::npos) << viewer->body;
  EXPECT_EQ(Status("line3-viewer", "/api/jobs?limit=5"), 200);
  EXPECT_EQ(Status("station 7", "/api/status"), 200);

  // Signed by the CA but not in the policy: 403 naming it, as gRPC's PERMISSION_DENIED.
  auto stranger = Https("stranger")->Get("/api/status");
  ASSERT_TRUE(stranger);
  EXPECT_EQ(stranger->status, 403);
  EXPECT_EQ(stranger->body, "identity 'stranger' is not in the access policy\n");

  // From another CA: the handshake itself fails, whatever the policy says of its name.
  auto intruder = Https("intruder")->Get("/metrics");
  EXPECT_FALSE(intruder) << "status " << intruder->status;

  // With the certificate mandatory, a token adds to it and is checked like on gRPC.
  EXPECT_EQ(Status("", "/metrics", {{"Authorization", "Bearer ad-0123456789abcdef"}}), 401)
      << "a token without a certificate is not enough";
  EXPECT_EQ(Status("line3-viewer", "/metrics", {{"Authorization", "Bearer not-a-token-of-anyone"}}), 401);

  // The same AccessControl as gRPC: a policy reload (SIGHUP) admits the stranger here too.
  WritePolicy(R"({"identities": {"line3-viewer": "viewer", "stranger": "viewer"}})");
  ASSERT_TRUE(server_->ReloadAccessPolicy().ok());
  EXPECT_EQ(Status("stranger", "/api/status"), 200);
  EXPECT_EQ(Status("station 7", "/api/status"), 403) << "no longer listed";
}

TEST_F(HttpSecurityTest, NamedTokensWithAPolicyGuardTheDataRoutes) {
  Start(/*mtls=*/false);
  httplib::Client http("127.0.0.1", server_->http_port());
  auto none = http.Get("/metrics");
  ASSERT_TRUE(none);
  EXPECT_EQ(none->status, 401);
  EXPECT_EQ(http.Get("/api/status", {{"Authorization", "Bearer lv-0123456789abcdef"}})->status, 200);
  EXPECT_EQ(http.Get("/api/status", {{"Authorization", "Bearer zz-0123456789abcdef"}})->status, 401);
  EXPECT_EQ(http.Get("/")->status, 200);
}

}  // namespace
}  // namespace inspection::testing
