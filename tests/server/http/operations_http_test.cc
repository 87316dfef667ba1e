// inspectd's HTTP port through a real HTTP client (cpp-httplib) against the real server: the
// Prometheus exposition after a scan, the dashboard's JSON and images, bearer-token checks, and
// `--no-rig` (reconstruct only) through gRPC.
#include <google/protobuf/util/json_util.h>
#include <grpcpp/generic/generic_stub.h>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "server/api/no_rig_service.h"
#include "tests/server/grpc_health_check.h"
#include "tests/server/server_fixture.h"
#include "tests/server/test_certs.h"

// Last: httplib.h pulls in <resolv.h>, whose `_res` macro breaks Eigen's headers.
#include <httplib.h>

namespace inspection::testing {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

class OperationsHttpTest : public ServerTest {
 protected:
  void Start(const std::string& token = "", bool no_rig = false, const fs::path& tls_dir = {}) {
    ServerOptions opt;
    if (!tls_dir.empty()) {
      opt.tls_cert_file = (tls_dir / "server.crt").string();
      opt.tls_key_file = (tls_dir / "server.key").string();
    }
    opt.listen_address = "127.0.0.1:0";
    opt.http_listen_address = "127.0.0.1:0";
    opt.data_dir = data_dir_;
    opt.simulation = SimOptions();
    opt.auth_token = token;
    opt.no_rig = no_rig;
    std::unique_ptr<Rig> rig;
    if (!no_rig) {
      control_ = std::make_shared<RigControl>();
      auto sim = CreateSimulatedRig(opt.simulation);
      ASSERT_TRUE(sim.ok()) << sim.status().ToString();
      rig = std::make_unique<ControlledRig>(std::move(*sim), control_);
    }
    auto server = InspectionServer::Start(opt, std::move(rig));
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    ASSERT_GT(server_->http_port(), 0);
    http_ = std::make_unique<httplib::Client>("127.0.0.1", server_->http_port());
    client::ClientOptions co;
    co.target = server_->address();
    co.auth_token = token;
    if (!tls_dir.empty()) co.tls_ca_file = (tls_dir / "ca.crt").string();
    client_ = std::make_unique<client::InspectionClient>(co);
    ASSERT_TRUE(client_->WaitConnected().ok());
  }

  // GET that must answer 200; returns the body.
  std::string Get(const std::string& path, const httplib::Headers& headers = {}) {
    auto res = http_->Get(path, headers);
    EXPECT_TRUE(res) << path << ": " << httplib::to_string(res.error());
    if (!res) return {};
    EXPECT_EQ(res->status, 200) << path << ": " << res->body;
    return res->body;
  }

  v1::Job SmallScan() {
    v1::ScanRequest req;
    req.set_z_step_um(10.0);
    req.set_label("http-test");
    v1::Job job;
    grpc::Status s = client_->Scan(req, nullptr, &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
    return job;
  }

  std::unique_ptr<httplib::Client> http_;
};

bool HasLine(const std::string& text, const std::string& line) {
  return text.find("\n" + line + "\n") != std::string::npos;
}

TEST_F(OperationsHttpTest, MetricsAfterAScanCountTheJobFramesAndCalls) {
  Start();
  auto before = http_->Get("/metrics");
  ASSERT_TRUE(before);
  EXPECT_EQ(before->get_header_value("Content-Type"), "text/plain; version=0.0.4; charset=utf-8");
  EXPECT_TRUE(HasLine(before->body, "inspectd_frames_acquired_total 0")) << before->body;
  EXPECT_TRUE(HasLine(before->body, "inspectd_rig_state{state=\"ready\"} 1")) << before->body;

  const v1::Job job = SmallScan();
  const int frames = job.result().depth().frame_count();
  ASSERT_GT(frames, 2);
  int64_t artifact_bytes = 0;
  for (const auto& a : job.result().artifacts()) artifact_bytes += a.size_bytes();

  const std::string text = Get("/metrics");
  EXPECT_TRUE(HasLine(text, "inspectd_jobs_total{kind=\"scan\",state=\"succeeded\"} 1")) << text;
  // STD illumination: one capture per stack frame.
  EXPECT_TRUE(HasLine(text, "inspectd_frames_acquired_total " + std::to_string(frames))) << text;
  EXPECT_TRUE(HasLine(text, "inspectd_last_scan_frames " + std::to_string(frames))) << text;
  EXPECT_TRUE(HasLine(text, "inspectd_job_duration_seconds_count{kind=\"scan\"} 1")) << text;
  EXPECT_TRUE(HasLine(text, "inspectd_job_duration_seconds_bucket{kind=\"scan\",le=\"+Inf\"} 1")) << text;
  EXPECT_TRUE(HasLine(text, "inspectd_job_queue_wait_seconds_count{kind=\"scan\"} 1")) << text;
  EXPECT_TRUE(HasLine(text, "inspectd_reconstruct_engine_seconds_count{kind=\"scan\"} 1")) << text;
  EXPECT_TRUE(HasLine(text, "inspectd_artifact_bytes_total{kind=\"scan\"} " + std::to_string(artifact_bytes))) << text;
  EXPECT_TRUE(HasLine(text, "inspectd_grpc_calls_total{method=\"inspection.v1.InspectionService/Scan\",code=\"OK\"} 1"))
      << text;
  EXPECT_NE(text.find("\ninspectd_data_disk_free_bytes "), std::string::npos);
  EXPECT_TRUE(HasLine(text, "inspectd_rig_state{state=\"ready\"} 1")) << text;

  // A refused call counts under its code.
  v1::ScanRequest bad;
  bad.set_z_step_um(-1);
  v1::Job unused;
  EXPECT_EQ(client_->Scan(bad, nullptr, &unused).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(HasLine(Get("/metrics"),
                      "inspectd_grpc_calls_total{method=\"inspection.v1.InspectionService/Scan\","
                      "code=\"INVALID_ARGUMENT\"} 1"));
}

// The rig's instrument verification on /metrics and the dashboard's status, read from the
// stored records at scrape time: due until a full verification, then verified with the record's
// characteristics as gauges.
TEST_F(OperationsHttpTest, VerificationStateAndCharacteristicsAreScrapedAndShown) {
  Start();
  std::string metrics = Get("/metrics");
  EXPECT_NE(metrics.find("\ninspectd_verification_state{state=\"due\"} 1\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("\ninspectd_verification_state{state=\"verified\"} 0\n"), std::string::npos);
  EXPECT_EQ(metrics.find("inspectd_verification_characteristic{"), std::string::npos) << "none before a full one";
  Json status = Json::parse(Get("/api/status"));
  EXPECT_EQ(status["rig"]["verificationState"], "VERIFICATION_STATE_DUE");
  EXPECT_EQ(status["rig"]["verificationDetail"], "no full verification under the uncalibrated rig");

  v1::Job job;
  grpc::Status s = client_->Verify(v1::VerifyRequest(), nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  const v1::VerificationRecord& r = job.result().verification();
  ASSERT_EQ(r.characteristics_size(), 7);
  metrics = Get("/metrics");
  EXPECT_NE(metrics.find("\ninspectd_verification_state{state=\"verified\"} 1\n"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("\ninspectd_verification_state{state=\"due\"} 0\n"), std::string::npos);
  EXPECT_NE(metrics.find("\ninspectd_verification_characteristic{characteristic=\"alpha_z\"} "), std::string::npos);
  EXPECT_NE(metrics.find("\ninspectd_verification_characteristic_expanded_uncertainty{characteristic=\"W_R\"} "),
            std::string::npos);
  EXPECT_NE(metrics.find("\ninspectd_verification_full_age_days "), std::string::npos);
  EXPECT_NE(metrics.find("\ninspectd_jobs_total{kind=\"verify\",state=\"succeeded\"} 1\n"), std::string::npos);
  status = Json::parse(Get("/api/status"));
  EXPECT_EQ(status["rig"]["verificationState"], "VERIFICATION_STATE_VERIFIED");
  EXPECT_NE(Get("/dashboard.js").find("VERIFICATION_STATE_"), std::string::npos);
}

TEST_F(OperationsHttpTest, DashboardServesPageStatusJobsAndPreview) {
  Start();
  const std::string page = Get("/");
  EXPECT_NE(page.find("<title>inspectd</title>"), std::string::npos);
  EXPECT_NE(page.find("src=\"/dashboard.js\""), std::string::npos);
  EXPECT_EQ(page.find("http://"), std::string::npos) << "nothing from other sites";
  EXPECT_NE(Get("/dashboard.js").find("/api/live"), std::string::npos);

  Json status = Json::parse(Get("/api/status"));
  EXPECT_EQ(status["no_rig"], false);
  EXPECT_EQ(status["rig"]["state"], "RIG_STATE_READY");
  EXPECT_EQ(status["rig"]["devices"].size(), 3u);
  EXPECT_EQ(status["queue"].size(), 0u);

  const v1::Job job = SmallScan();
  Json jobs = Json::parse(Get("/api/jobs?limit=5"));
  ASSERT_EQ(jobs["jobs"].size(), 1u);
  EXPECT_EQ(jobs["jobs"][0]["jobId"], job.job_id());
  EXPECT_EQ(jobs["jobs"][0]["state"], "JOB_STATE_SUCCEEDED");
  EXPECT_EQ(jobs["jobs"][0]["label"], "http-test");
  EXPECT_EQ(jobs["jobs"][0]["result"]["depth"]["frameCount"], job.result().depth().frame_count());
  EXPECT_EQ(Json::parse(Get("/api/live"))["jobs"].size(), 0u) << "a finished job is not live";

  const std::string png = Get("/api/jobs/" + job.job_id() + "/preview.png");
  const cv::Mat preview = cv::imdecode(std::vector<uchar>(png.begin(), png.end()), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(preview.empty());
  EXPECT_LE(preview.cols, 480);

  EXPECT_EQ(http_->Get("/api/jobs?limit=0")->status, 400);
  EXPECT_EQ(http_->Get("/api/jobs?limit=5x")->status, 400);
  EXPECT_EQ(http_->Get("/api/jobs/scan-0000/preview.png")->status, 404);
  EXPECT_EQ(http_->Get("/api/jobs/" + job.job_id() + "/frame.png")->status, 404) << "not running";
  EXPECT_EQ(http_->Get("/api/jobs/..%2F..%2Fetc/preview.png")->status, 404);
}

TEST_F(OperationsHttpTest, RecentJobsCarryTheVerdictOfARecipeScan) {
  Start();
  // skew5 is a plane tilted by 5.000 deg: a recipe expecting 3 +-0.5 deg judges it NOT_OK.
  const std::string recipe_json = R"({
      "recipe_id": "tilt-three", "scan": {"z_step_um": 10},
      "measurements": [{"name": "tilt", "parameter": "tilt", "tolerance": {"nominal": 3.0, "lower": -0.5, "upper": 0.5}}]
    })";
  v1::Recipe recipe;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(recipe_json, &recipe).ok());
  v1::Recipe stored;
  ASSERT_TRUE(client_->CreateRecipe(recipe, &stored).ok());
  v1::ScanRequest req;
  req.set_recipe_id("tilt-three");
  req.set_part_id("P-17");
  v1::Job job;
  grpc::Status s = client_->Scan(req, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.result().inspection().verdict(), v1::VERDICT_NOT_OK);
  const v1::Job plain = SmallScan();  // no recipe: no verdict

  Json jobs = Json::parse(Get("/api/jobs?limit=5"));
  ASSERT_EQ(jobs["jobs"].size(), 2u);
  EXPECT_EQ(jobs["jobs"][0]["jobId"], plain.job_id());
  EXPECT_FALSE(jobs["jobs"][0]["result"].contains("inspection"));
  const Json& inspected = jobs["jobs"][1];
  EXPECT_EQ(inspected["jobId"], job.job_id());
  EXPECT_EQ(inspected["result"]["inspection"]["verdict"], "VERDICT_NOT_OK");
  EXPECT_EQ(inspected["result"]["inspection"]["recipeId"], "tilt-three");
  EXPECT_EQ(inspected["result"]["inspection"]["partId"], "P-17");
  EXPECT_EQ(inspected["result"]["inspection"]["measurements"][0]["verdict"], "VERDICT_NOT_OK");
  // The page draws it from there (the browser test, ops_dashboard_browser, sees the text).
  const std::string script = Get("/dashboard.js");
  EXPECT_NE(script.find("result?.inspection"), std::string::npos);
  EXPECT_NE(script.find("\"verdict-\" + verdict"), std::string::npos);
}

TEST_F(OperationsHttpTest, LiveViewShowsTheRunningScanAndItsNewestStoredFrame) {
  Start();
  control_->hold_at_frame = 3;  // captures 0..2 are reported and stored, capture 3 waits
  v1::ScanRequest req;
  req.set_z_step_um(10.0);
  v1::Job job;
  std::thread scan([&] { EXPECT_TRUE(client_->Scan(req, nullptr, &job).ok()); });
  ASSERT_TRUE(control_->WaitUntilHolding());

  Json live = Json::parse(Get("/api/live"));
  ASSERT_EQ(live["jobs"].size(), 1u);
  const Json& j = live["jobs"][0];
  EXPECT_EQ(j["frame_events"], 3);
  EXPECT_EQ(j["frame_event"]["frame"]["frameIndex"], 2);
  EXPECT_GT(j["frame_event"]["frame"]["statistics"]["meanGrey"].get<double>(), 0.0);
  Json status = Json::parse(Get("/api/status"));
  EXPECT_EQ(status["rig"]["state"], "RIG_STATE_BUSY");
  ASSERT_EQ(status["queue"].size(), 1u);
  EXPECT_EQ(status["queue"][0]["state"], "JOB_STATE_RUNNING");

  auto res = http_->Get("/api/jobs/" + j["job_id"].get<std::string>() + "/frame.png");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(res->get_header_value("X-Frame-Index"), "1");  // frame 2's file may still be being written
  const cv::Mat thumb = cv::imdecode(std::vector<uchar>(res->body.begin(), res->body.end()), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(thumb.empty());
  EXPECT_EQ(thumb.cols, 320);  // the 320x240 test camera, not enlarged
  EXPECT_EQ(thumb.type(), CV_8UC1);

  control_->Release();
  scan.join();
  EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(Json::parse(Get("/api/live"))["jobs"].size(), 0u);
}

TEST_F(OperationsHttpTest, DataRoutesNeedTheGrpcBearerTokenButThePageDoesNot) {
  Start("s3cret-token");
  auto none = http_->Get("/metrics");
  ASSERT_TRUE(none);
  EXPECT_EQ(none->status, 401);
  EXPECT_EQ(none->get_header_value("WWW-Authenticate"), "Bearer realm=\"inspectd\"");
  EXPECT_EQ(http_->Get("/api/status", {{"Authorization", "Bearer wrong"}})->status, 401);
  EXPECT_EQ(http_->Get("/api/jobs", {{"Authorization", "Basic czNjcmV0LXRva2Vu"}})->status, 401);
  const httplib::Headers auth = {{"Authorization", "Bearer s3cret-token"}};
  // An unlabelled family: it has its series before any job (a labelled one is written once it has one).
  EXPECT_NE(Get("/metrics", auth).find("\ninspectd_frames_acquired_total "), std::string::npos);
  EXPECT_EQ(Json::parse(Get("/api/status", auth))["rig"]["state"], "RIG_STATE_READY");
  EXPECT_NE(Get("/").find("token-form"), std::string::npos) << "the page itself holds no data";
}

TEST_F(OperationsHttpTest, WithTlsTheHttpPortSpeaksHttpsWithTheGrpcCertificate) {
  const fs::path tls = data_dir_.parent_path() / (data_dir_.filename().string() + "_tls");
  fs::create_directories(tls);
  const KeyAndCert ca = MakeCertificate("inspect test CA", "", nullptr, 1);
  const KeyAndCert server = MakeCertificate("localhost", "DNS:localhost,IP:127.0.0.1", &ca, 2);
  WriteText(tls / "ca.crt", ca.cert_pem);
  WriteText(tls / "server.crt", server.cert_pem);
  WriteText(tls / "server.key", server.key_pem);
  Start("tls-token", false, tls);
  httplib::SSLClient https("127.0.0.1", server_->http_port());
  https.set_ca_cert_path((tls / "ca.crt").string().c_str());
  https.enable_server_certificate_verification(true);
  auto res = https.Get("/metrics", {{"Authorization", "Bearer tls-token"}});
  ASSERT_TRUE(res) << httplib::to_string(res.error());
  EXPECT_EQ(res->status, 200);
  EXPECT_NE(res->body.find("inspectd_rig_state{state=\"ready\"} 1"), std::string::npos);
  EXPECT_EQ(https.Get("/metrics")->status, 401);
  EXPECT_FALSE(http_->Get("/metrics")) << "no plaintext answer on the HTTPS port";
  fs::remove_all(tls);
}

TEST_F(OperationsHttpTest, NoRigServesReconstructsAndRefusesRigCalls) {
  // A stack to reconstruct: scanned by an ordinary server first.
  Start();
  const v1::Job scan = SmallScan();
  const fs::path stack = data_dir_.parent_path() / (data_dir_.filename().string() + "_stack");
  fs::remove_all(stack);
  ExtractStoredStack(data_dir_, scan.job_id(), stack);
  client_.reset();
  server_.reset();
  fs::remove_all(data_dir_);
  control_.reset();

  Start("", /*no_rig=*/true);
  v1::RigStatus rig_status;
  grpc::Status s = client_->GetRigStatus(&rig_status);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(s.error_message(), NoRigMessage("GetRigStatus"));
  EXPECT_NE(s.error_message().find("--no-rig"), std::string::npos);
  v1::Job job;
  s = client_->Scan(v1::ScanRequest(), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(s.error_message(), NoRigMessage("Scan"));
  EXPECT_EQ(client_->Calibrate(v1::CalibrateRequest(), nullptr, &job).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(client_->ResetRig(&rig_status).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  v1::ListRecipesResponse recipes;
  s = client_->ListRecipes(&recipes);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(s.error_message(), NoRigMessage("ListRecipes"));
  v1::ListSpecimensResponse specimens;
  EXPECT_EQ(client_->ListSpecimens(&specimens).error_code(), grpc::StatusCode::FAILED_PRECONDITION);

  // Readiness: the pool's replicas can always take reconstructs.
  EXPECT_EQ(HealthStatus(client_->channel(), kRigHealthService), 1);

  v1::Job rec;
  s = client_->ReconstructUpload(stack, v1::ReconstructStart(), nullptr, &rec);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(rec.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(rec.result().depth().frame_count(), scan.result().depth().frame_count());
  EXPECT_EQ(rec.result().depth().rmse_um(), scan.result().depth().rmse_um()) << "same stack, same engine";

  const std::string text = Get("/metrics");
  EXPECT_TRUE(HasLine(text, "inspectd_rig_present 0")) << text;
  EXPECT_TRUE(HasLine(text, "inspectd_jobs_total{kind=\"reconstruct\",state=\"succeeded\"} 1")) << text;
  EXPECT_TRUE(HasLine(text,
                      "inspectd_grpc_calls_total{method=\"inspection.v1.InspectionService/Scan\","
                      "code=\"FAILED_PRECONDITION\"} 1"))
      << text;
  Json status = Json::parse(Get("/api/status"));
  EXPECT_EQ(status["no_rig"], true);
  EXPECT_TRUE(status["rig"].is_null());
  fs::remove_all(stack);
}

TEST(NoRigServiceTest, EveryInspectionMethodIsEitherServedOrRefused) {
  const auto* service =
      google::protobuf::DescriptorPool::generated_pool()->FindServiceByName(v1::InspectionService::service_full_name());
  ASSERT_NE(service, nullptr);
  ASSERT_EQ(size_t(service->method_count()), kRigOnlyMethods.size() + kNoRigServedMethods.size())
      << "a new RPC must be sorted into kRigOnlyMethods or kNoRigServedMethods (no_rig_service.h)";
  for (int i = 0; i < service->method_count(); ++i) {
    const std::string& name = service->method(i)->name();
    const bool listed = std::count(kRigOnlyMethods.begin(), kRigOnlyMethods.end(), name) +
                        std::count(kNoRigServedMethods.begin(), kNoRigServedMethods.end(), name);
    EXPECT_EQ(listed, 1) << name;
  }
}

}  // namespace
}  // namespace inspection::testing
