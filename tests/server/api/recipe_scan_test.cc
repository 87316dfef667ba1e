// Scans that run a recipe, through the real server on the simulated rig: the
// recipe's scan section runs, its measurements are made on the depth map with uncertainty and
// judged; the job and its result carry part, station and recipe version. The specimen is skew5,
// a textured plane tilted by 5.000 deg about the image's y axis (devices/sim/specimen.cc), so the
// tilt has a known true value.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <cmath>
#include <thread>

#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

// Three tilt measurements of the whole field, in, out of and tighter than the uncertainty allows,
// and Sa with a limit wide enough for the uncharacterised z-linearity bound (U ~ 5.5 um at 5 um
// steps: the z grid's peak-locking sawtooth reads as roughness until the rig is characterised).
v1::Recipe TiltRecipe() {
  v1::Recipe r;
  const std::string json = R"({
    "recipe_id": "tilt-check",
    "scan": {"z_step_um": 5},
    "measurements": [
      {"name": "tilt_in", "parameter": "tilt", "tolerance": {"nominal": 5.0, "lower": -0.5, "upper": 0.5,
                                                             "min_coverage_percent": 90}},
      {"name": "tilt_out", "parameter": "tilt", "tolerance": {"nominal": 3.0, "lower": -0.5, "upper": 0.5}},
      {"name": "tilt_tight", "parameter": "tilt", "tolerance": {"nominal": 5.0, "lower": -1e-6, "upper": 1e-6}},
      {"name": "roughness", "parameter": "Sa", "tolerance": {"nominal": 0, "upper": 20.0}}
    ]})";
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(json, &r).ok());
  return r;
}

class RecipeScanTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
    v1::Recipe stored;
    ASSERT_TRUE(client_->CreateRecipe(TiltRecipe(), &stored).ok());
  }
  static v1::ScanRequest PartScan(const std::string& part) {
    v1::ScanRequest req;
    req.set_part_id(part);
    req.set_station("station-7");
    req.set_recipe_id("tilt-check");
    return req;
  }
};

TEST_F(RecipeScanTest, MeasurementsCarryValueUncertaintyCoverageAndVerdict) {
  v1::Job job;
  grpc::Status s = client_->Scan(PartScan("4711"), {}, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(job.part_id(), "4711");
  EXPECT_EQ(job.station(), "station-7");
  EXPECT_EQ(job.recipe_id(), "tilt-check");
  EXPECT_EQ(job.recipe_version(), 1);
  const v1::InspectionResult& ins = job.result().inspection();
  EXPECT_EQ(ins.recipe_id(), "tilt-check");
  EXPECT_EQ(ins.recipe_version(), 1);
  EXPECT_EQ(ins.part_id(), "4711");
  EXPECT_EQ(ins.station(), "station-7");
  ASSERT_EQ(ins.measurements_size(), 4);
  for (const auto& m : ins.measurements()) {
    std::cout << m.name() << ": " << m.value() << " " << m.unit() << " u " << m.standard_uncertainty() << " U "
              << m.expanded_uncertainty() << " coverage " << m.coverage_percent() << " % "
              << v1::Verdict_Name(m.verdict()) << " (" << m.reason() << ")\n";
    EXPECT_TRUE(m.measured());
    EXPECT_GT(m.coverage_percent(), 95.0);
    EXPECT_GT(m.standard_uncertainty(), 0.0);
    EXPECT_DOUBLE_EQ(m.expanded_uncertainty(), 2.0 * m.standard_uncertainty());
    EXPECT_FALSE(m.reason().empty());
  }
  const v1::MeasurementResult& in = ins.measurements(0);
  EXPECT_EQ(in.parameter(), "tilt");
  EXPECT_EQ(in.unit(), "deg");
  EXPECT_NEAR(in.value(), 5.0, 0.05);  // the specimen's true tilt
  // The expanded uncertainty covers the true value. Without a characterised z linearity the
  // server uses the peak-locking bound (+-1/2 step, core/metrology/z_linearity.h): safe and wide.
  EXPECT_GT(in.expanded_uncertainty(), std::abs(in.value() - 5.0));
  EXPECT_LT(in.expanded_uncertainty(), 0.5);
  EXPECT_DOUBLE_EQ(in.tolerance().nominal(), 5.0);
  EXPECT_EQ(in.verdict(), v1::VERDICT_OK);
  EXPECT_EQ(ins.measurements(1).verdict(), v1::VERDICT_NOT_OK);
  EXPECT_EQ(ins.measurements(2).verdict(), v1::VERDICT_NOT_DECIDABLE);  // 2U wider than the band
  EXPECT_EQ(ins.measurements(3).unit(), "um");
  EXPECT_EQ(ins.measurements(3).verdict(), v1::VERDICT_OK);
  EXPECT_EQ(ins.verdict(), v1::VERDICT_NOT_OK);  // a proven defect decides
  // The recipe's scan section ran: 5 um steps over the rig's default range.
  v1::RigStatus rig;
  ASSERT_TRUE(client_->GetRigStatus(&rig).ok());
  const double span_um = std::abs(rig.scan_defaults().z_end_um() - rig.scan_defaults().z_start_um());
  EXPECT_EQ(job.result().depth().frame_count(), int(std::floor(span_um / 5.0 + 1e-6)) + 1);
}

TEST_F(RecipeScanTest, RecipeVersionsAndBadRequests) {
  v1::Recipe v2 = TiltRecipe();
  v2.mutable_measurements()->DeleteSubrange(1, 3);  // only tilt_in
  v1::Recipe stored;
  ASSERT_TRUE(client_->UpdateRecipe(v2, 1, &stored).ok());
  v1::ScanRequest req = PartScan("4712");
  req.set_recipe_version(1);  // the older version still runs on request
  v1::Job job;
  ASSERT_TRUE(client_->Scan(req, {}, &job).ok());
  EXPECT_EQ(job.recipe_version(), 1);
  EXPECT_EQ(job.result().inspection().measurements_size(), 4);
  ASSERT_TRUE(client_->Scan(PartScan("4713"), {}, &job).ok());
  EXPECT_EQ(job.recipe_version(), 2);
  ASSERT_EQ(job.result().inspection().measurements_size(), 1);
  EXPECT_EQ(job.result().inspection().verdict(), v1::VERDICT_OK);

  v1::ListJobsResponse before;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &before).ok());
  req = PartScan("4714");
  req.set_recipe_id("no-such-recipe");
  grpc::Status s = client_->Scan(req, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
  req = PartScan("4714");
  req.set_recipe_version(9);
  s = client_->Scan(req, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
  req = PartScan("4714");
  req.set_z_step_um(2.0);
  s = client_->Scan(req, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message(), "z_step_um is fixed by recipe 'tilt-check'; leave it unset");
  req = PartScan(std::string(300, 'p'));
  s = client_->Scan(req, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("part_id"), std::string::npos) << s.error_message();
  v1::ListJobsResponse after;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &after).ok());
  EXPECT_EQ(after.jobs_size(), before.jobs_size());  // refused requests queue nothing
}

TEST_F(RecipeScanTest, ARecipeInUseByARunningScanCannotBeDeleted) {
  control_->hold_at_frame = 1;
  v1::Job job;
  std::thread scan([&] {
    auto c = NewClient();
    c->Scan(PartScan("4720"), {}, &job).IgnoreError();
  });
  ASSERT_TRUE(control_->WaitUntilHolding());
  v1::DeleteResponse deleted;
  grpc::Status s = client_->DeleteRecipe("tilt-check", &deleted);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << s.error_message();
  EXPECT_NE(s.error_message().find("JOB_STATE_RUNNING"), std::string::npos) << s.error_message();
  control_->Release();
  scan.join();
  EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_TRUE(client_->DeleteRecipe("tilt-check", &deleted).ok());
}

// The z-linearity calibration step replaces the +-1/2 step bound in the uncertainty by the rig's
// measured periodic error: the tilt's U shrinks several times and still covers the truth.
TEST_F(RecipeScanTest, ZLinearityCalibrationNarrowsTheUncertaintyAndStillCoversTheTruth) {
  v1::Job before;
  ASSERT_TRUE(client_->Scan(PartScan("4730"), {}, &before).ok());
  v1::CalibrateRequest cal_req;
  cal_req.add_steps(v1::CALIBRATION_STEP_Z_LINEARITY);
  v1::Job cal;
  grpc::Status s = client_->Calibrate(cal_req, nullptr, &cal);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(cal.state(), v1::JOB_STATE_SUCCEEDED) << cal.error_message();
  v1::Job after;
  ASSERT_TRUE(client_->Scan(PartScan("4731"), {}, &after).ok());
  ASSERT_EQ(after.result().calibration_id(), cal.result().calibration_id());
  const v1::MeasurementResult& t0 = before.result().inspection().measurements(0);
  const v1::MeasurementResult& t1 = after.result().inspection().measurements(0);
  const v1::MeasurementResult& sa0 = before.result().inspection().measurements(3);
  const v1::MeasurementResult& sa1 = after.result().inspection().measurements(3);
  std::printf("tilt %.4f deg U %.4f -> %.4f deg U %.4f; Sa %.4f um U %.3f -> %.4f um U %.3f\n", t0.value(),
              t0.expanded_uncertainty(), t1.value(), t1.expanded_uncertainty(), sa0.value(), sa0.expanded_uncertainty(),
              sa1.value(), sa1.expanded_uncertainty());
  EXPECT_LT(t1.expanded_uncertainty(), 0.5 * t0.expanded_uncertainty());
  EXPECT_GT(t1.expanded_uncertainty(), std::abs(t1.value() - 5.0));  // the true tilt is 5.000 deg
  EXPECT_LT(sa1.expanded_uncertainty(), 0.25 * sa0.expanded_uncertainty());
}

}  // namespace
}  // namespace inspection::testing
