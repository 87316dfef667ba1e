// The caller's identity on inspectd's JSON log lines, through the real server: the lines a call
// logs on its gRPC thread and the lines its job logs on the worker carry "identity" (the token's
// identity from the token file), beside job_id; an unauthenticated call's lines carry none.
#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>

#include "server/logging/log_format.h"
#include "tests/server/server_fixture.h"
#include "tests/server/test_certs.h"

namespace inspection::testing {
namespace {

class LogIdentityTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    // The default logger is swapped only while no server runs (no thread logs meanwhile).
    previous_logger_ = spdlog::default_logger();
    auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out_);
    auto logger = std::make_shared<spdlog::logger>("", sink);
    logger->set_formatter(std::make_unique<JsonLogFormatter>());
    logger->set_level(spdlog::level::info);
    spdlog::set_default_logger(logger);
  }
  void TearDown() override {
    ServerTest::TearDown();  // joins every thread that logs
    spdlog::set_default_logger(previous_logger_);
  }

  std::vector<nlohmann::json> Lines() {
    spdlog::default_logger()->flush();
    std::vector<nlohmann::json> lines;
    std::istringstream in(out_.str());
    std::string line;
    while (std::getline(in, line)) lines.push_back(nlohmann::json::parse(line));  // throws on a non-JSON line
    return lines;
  }
  // The lines whose message starts with `prefix`.
  std::vector<nlohmann::json> LinesStartingWith(const std::string& prefix) {
    std::vector<nlohmann::json> out;
    for (auto& l : Lines()) {
      if (l["message"].get<std::string>().rfind(prefix, 0) == 0) out.push_back(l);
    }
    return out;
  }

  std::ostringstream out_;
  std::shared_ptr<spdlog::logger> previous_logger_;
};

TEST_F(LogIdentityTest, CallAndJobLinesNameTheTokenIdentity) {
  const std::filesystem::path tokens = data_dir_.parent_path() / (data_dir_.filename().string() + "_tokens");
  WriteText(tokens, "station-7 st7-0123456789abcdef\nline3-viewer lv-0123456789abcdef\n");
  const std::filesystem::path policy = data_dir_.parent_path() / (data_dir_.filename().string() + "_policy.json");
  WriteText(policy, R"({"identities": {"station-7": "operator", "line3-viewer": "viewer"}})");
  ServerOptions opt;
  opt.listen_address = "127.0.0.1:0";
  opt.data_dir = data_dir_;
  opt.simulation = SimOptions();
  opt.token_file = tokens.string();
  opt.policy_file = policy.string();
  auto server = InspectionServer::Start(opt);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  server_ = std::move(*server);

  client::ClientOptions co;
  co.target = server_->address();
  co.auth_token = "st7-0123456789abcdef";
  client::InspectionClient station(co);
  v1::ScanRequest req;
  req.set_z_step_um(10.0);
  v1::Job job;
  grpc::Status s = station.Scan(req, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(job.owner(), "station-7");

  // The viewer may not scan: its refused call is audited under its identity.
  co.auth_token = "lv-0123456789abcdef";
  v1::Job refused;
  EXPECT_EQ(client::InspectionClient(co).Scan(req, nullptr, &refused).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  // No credentials: no identity on the lines of that call.
  co.auth_token.clear();
  EXPECT_EQ(client::InspectionClient(co).Scan(req, nullptr, &refused).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  server_.reset();  // every line written

  // On the gRPC thread (JobManager::Submit inside the Scan handler): identity, no job scope.
  const auto queued = LinesStartingWith("job " + job.job_id() + " queued");
  ASSERT_EQ(queued.size(), 1u) << out_.str();
  EXPECT_EQ(queued[0]["identity"], "station-7") << queued[0];
  EXPECT_FALSE(queued[0].contains("job_id")) << queued[0];
  // On the rig worker: the job and its owner.
  const auto succeeded = LinesStartingWith("job " + job.job_id() + " succeeded");
  ASSERT_EQ(succeeded.size(), 1u) << out_.str();
  EXPECT_EQ(succeeded[0]["job_id"], job.job_id());
  EXPECT_EQ(succeeded[0]["identity"], "station-7");
  EXPECT_EQ(succeeded[0]["level"], "info");
  // The audit interceptor's lines run inside the call's scope too.
  const auto audit = LinesStartingWith("audit: Scan");
  ASSERT_EQ(audit.size(), 3u) << out_.str();
  EXPECT_EQ(audit[0]["identity"], "station-7") << audit[0];
  EXPECT_EQ(audit[1]["identity"], "line3-viewer") << audit[1];
  EXPECT_EQ(audit[1]["level"], "warning");
  EXPECT_FALSE(audit[2].contains("identity")) << "unauthenticated: " << audit[2];
  EXPECT_NE(audit[2]["message"].get<std::string>().find("denied"), std::string::npos) << audit[2];
  std::filesystem::remove(tokens);
  std::filesystem::remove(policy);
}

}  // namespace
}  // namespace inspection::testing
