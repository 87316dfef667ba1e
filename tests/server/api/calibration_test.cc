// Calibrate through the service: a step runs as a rig job, its bundle is stored, becomes active,
// is reported by GetRigStatus and recorded by later scans; calibration and scans never
// interleave.
#include <gtest/gtest.h>

#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

class CalibrationServiceTest : public ServerTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o = ServerTest::SimOptions();
    o.projector_size = {160, 90};  // small projector: calibration steps stay quick in tests
    return o;
  }
};

TEST_F(CalibrationServiceTest, CameraResponseStepIsStoredActiveAndRecordedByScans) {
  StartServer();
  v1::CalibrateRequest req;
  req.add_steps(v1::CALIBRATION_STEP_CAMERA_RESPONSE);
  std::vector<std::string> steps_seen;
  v1::Job job;
  grpc::Status s = client_->Calibrate(
      req,
      [&](const v1::JobEvent& e) {
        if (!e.step().empty()) steps_seen.push_back(e.step());
      },
      &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  const std::string id = job.result().calibration_id();
  ASSERT_FALSE(id.empty());
  EXPECT_FALSE(steps_seen.empty());
  EXPECT_EQ(steps_seen.front(), "camera_response");
  EXPECT_GT(job.result().calibration().figures().count("camera_response.duration_s"), 0u);

  v1::RigStatus st;
  ASSERT_TRUE(client_->GetRigStatus(&st).ok());
  EXPECT_EQ(st.active_calibration_id(), id);
  v1::Calibration cal;
  ASSERT_TRUE(client_->GetCalibration("", &cal).ok());
  EXPECT_EQ(cal.calibration_id(), id);
  EXPECT_TRUE(cal.active());
  EXPECT_TRUE(std::filesystem::exists(data_dir_ / "calibrations" / id / "bundle.json"));

  v1::Job scan;
  ASSERT_TRUE(client_->Scan(v1::ScanRequest(), nullptr, &scan).ok());
  EXPECT_EQ(scan.result().calibration_id(), id);

  // The active bundle is loaded again after a restart.
  StopServer();
  StartServer();
  ASSERT_TRUE(client_->GetRigStatus(&st).ok());
  EXPECT_EQ(st.active_calibration_id(), id);
  v1::ListCalibrationsResponse list;
  ASSERT_TRUE(client_->ListCalibrations(&list).ok());
  EXPECT_EQ(list.calibrations_size(), 1);
}

TEST_F(CalibrationServiceTest, CalibrateWhileAScanRunsIsAborted) {
  StartServer();
  control_->hold_at_frame = 2;
  v1::Job scan;
  std::thread t([&] { client_->Scan(v1::ScanRequest(), nullptr, &scan); });
  ASSERT_TRUE(control_->WaitUntilHolding());
  auto other = NewClient();
  v1::CalibrateRequest req;
  req.add_steps(v1::CALIBRATION_STEP_CAMERA_RESPONSE);
  v1::Job cal;
  grpc::Status s = other->Calibrate(req, nullptr, &cal);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED);
  EXPECT_NE(s.error_message().find("scan is running"), std::string::npos) << s.error_message();
  control_->Release();
  t.join();
  EXPECT_EQ(scan.state(), v1::JOB_STATE_SUCCEEDED);
}

TEST_F(CalibrationServiceTest, ScanWhileACalibrationIsQueuedOrRunningIsAborted) {
  StartServer();
  // Hold the calibration's third capture; a scan submitted meanwhile is refused.
  control_->hold_at_frame = 2;
  v1::CalibrateRequest req;
  req.add_steps(v1::CALIBRATION_STEP_CAMERA_RESPONSE);
  v1::Job cal;
  std::thread t([&] { client_->Calibrate(req, nullptr, &cal); });
  ASSERT_TRUE(control_->WaitUntilHolding());
  auto other = NewClient();
  v1::Job scan;
  grpc::Status s = other->Scan(v1::ScanRequest(), nullptr, &scan);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED);
  EXPECT_NE(s.error_message().find("calibration is running"), std::string::npos) << s.error_message();
  control_->Release();
  t.join();
  EXPECT_EQ(cal.state(), v1::JOB_STATE_SUCCEEDED);
}

TEST_F(CalibrationServiceTest, BadStepIsInvalidArgument) {
  StartServer();
  v1::CalibrateRequest req;
  req.add_steps(v1::CALIBRATION_STEP_UNSPECIFIED);
  v1::Job job;
  grpc::Status s = client_->Calibrate(req, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("steps[0]"), std::string::npos);
}

}  // namespace
}  // namespace inspection::testing
