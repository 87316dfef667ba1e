// Rig state and health: a device failure mid-scan fails the job with a clear status, moves the
// rig to Error (health NOT_SERVING, rig jobs refused) until ResetRig reconnects it.
#include <gtest/gtest.h>

#include "tests/server/grpc_health_check.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

constexpr int kServing = 1;
constexpr int kNotServing = 2;

TEST_F(ServerTest, CameraLossMidScanFailsJobSetsErrorAndResetRecovers) {
  StartServer();
  EXPECT_EQ(HealthStatus(client_->channel(), ""), kServing);
  EXPECT_EQ(HealthStatus(client_->channel(), kRigHealthService), kServing);

  control_->fail_from_frame = 3;  // the camera "disappears" at the 4th frame
  v1::Job job;
  grpc::Status s = client_->Scan(v1::ScanRequest(), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_NE(s.error_message().find("camera disappeared"), std::string::npos) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(job.error_code(), int(grpc::StatusCode::UNAVAILABLE));
  EXPECT_FALSE(job.has_result());

  v1::RigStatus st;
  ASSERT_TRUE(client_->GetRigStatus(&st).ok());
  EXPECT_EQ(st.state(), v1::RIG_STATE_ERROR);
  EXPECT_NE(st.state_detail().find("camera"), std::string::npos);
  bool camera_reported = false;
  for (const auto& d : st.devices()) {
    if (d.role() == "camera") camera_reported = !d.connected();
  }
  EXPECT_TRUE(camera_reported);
  EXPECT_EQ(HealthStatus(client_->channel(), kRigHealthService), kNotServing);
  EXPECT_EQ(HealthStatus(client_->channel(), ""), kServing);  // the process itself is fine

  // Rig jobs are refused while in Error.
  s = client_->Scan(v1::ScanRequest(), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("ResetRig"), std::string::npos);

  grpc::Status rs = client_->ResetRig(&st);
  ASSERT_TRUE(rs.ok()) << rs.error_message();
  EXPECT_EQ(st.state(), v1::RIG_STATE_READY);
  EXPECT_EQ(HealthStatus(client_->channel(), kRigHealthService), kServing);
  EXPECT_TRUE(client_->Scan(v1::ScanRequest(), nullptr, &job).ok());
  EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
}

TEST_F(ServerTest, DegradedStartReportsWhyAndServesNotServing) {
  ServerOptions opt;
  opt.listen_address = "127.0.0.1:0";
  opt.data_dir = data_dir_;
  auto sim = CreateSimulatedRig(SimOptions());
  ASSERT_TRUE(sim.ok());
  auto server =
      InspectionServer::Start(opt, std::move(*sim), Status::Unavailable("stage apt-usb (serial 27000001) not found"));
  ASSERT_TRUE(server.ok());
  server_ = std::move(*server);
  client_ = NewClient();
  v1::RigStatus st;
  ASSERT_TRUE(client_->GetRigStatus(&st).ok());
  EXPECT_EQ(st.state(), v1::RIG_STATE_ERROR);
  EXPECT_NE(st.state_detail().find("stage apt-usb"), std::string::npos);
  EXPECT_EQ(HealthStatus(client_->channel(), kRigHealthService), kNotServing);
}

TEST_F(ServerTest, SpecimenChangesAtRunTimeOnTheSimulatedRig) {
  StartServer();
  v1::ListSpecimensResponse r;
  ASSERT_TRUE(client_->ListSpecimens(&r).ok());
  EXPECT_EQ(r.current(), "skew5");
  EXPECT_GE(r.specimens_size(), 3);
  ASSERT_TRUE(client_->SetSpecimen("plane", &r).ok());
  EXPECT_EQ(r.current(), "plane");
  grpc::Status s = client_->SetSpecimen("no-such-specimen", &r);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  v1::RigStatus st;
  ASSERT_TRUE(client_->GetRigStatus(&st).ok());
  EXPECT_EQ(st.specimen(), "plane");
}

TEST_F(ServerTest, BearerTokenIsRequiredWhenConfigured) {
  ServerOptions opt;
  opt.listen_address = "127.0.0.1:0";
  opt.data_dir = data_dir_;
  opt.auth_token = "s3cret";
  opt.simulation = SimOptions();
  auto server = InspectionServer::Start(opt);
  ASSERT_TRUE(server.ok());
  server_ = std::move(*server);
  client::ClientOptions co;
  co.target = server_->address();
  client::InspectionClient anonymous(co);
  v1::RigStatus st;
  EXPECT_EQ(anonymous.GetRigStatus(&st).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  co.auth_token = "wrong";
  EXPECT_EQ(client::InspectionClient(co).GetRigStatus(&st).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  co.auth_token = "s3cret";
  EXPECT_TRUE(client::InspectionClient(co).GetRigStatus(&st).ok());
}

}  // namespace
}  // namespace inspection::testing
