// Instrument verification through the real server on the simulated rig (docs/verification.md):
// Verify runs as a rig job, its record is stored with the active calibration and returned by
// GetCalibration, GetRigStatus shows the rig's verification state, later scans use the verified
// alpha_z and l_z in their uncertainty and warn while the state is due or failed. An injected z
// scale error is recovered within its U; a larger one appearing after the full verification fails
// the interim check. A rig without material measures is refused naming the field, and a
// cancelled verification stores nothing. Small camera (256 x 192): a full verification is 15 scans.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

const v1::VerificationCharacteristic& Characteristic(const v1::VerificationRecord& r, const std::string& name) {
  for (const v1::VerificationCharacteristic& c : r.characteristics()) {
    if (c.name() == name) return c;
  }
  ADD_FAILURE() << "no characteristic " << name;
  static const v1::VerificationCharacteristic none;
  return none;
}

void Print(const char* label, const v1::VerificationRecord& r) {
  std::printf("%s (%s, %d scans, %s):\n", label, v1::VerificationMode_Name(r.mode()).c_str(), r.scans(),
              v1::VerificationState_Name(r.state()).c_str());
  for (const v1::VerificationCharacteristic& c : r.characteristics()) {
    std::printf("  %-8s %.5f  U %.5f %s\n", c.name().c_str(), c.value(), c.expanded_uncertainty(), c.unit().c_str());
  }
  for (const v1::VerificationStepPoint& s : r.steps()) {
    std::printf("  %-6s %.4f +- %.4f um (certified %.3f)\n", s.specimen().c_str(), s.measured_um(),
                2 * s.measured_u_um(), s.certified_um());
  }
  for (const std::string& f : r.findings()) std::printf("  finding: %s\n", f.c_str());
}

// The 1 um step (specimen step1um, the step at the image's centre column) on the 256 x 192 camera.
v1::Recipe StepRecipe() {
  v1::Recipe r;
  const std::string json = R"({
    "recipe_id": "step",
    "scan": {"z_step_um": 2},
    "measurements": [
      {"name": "step", "parameter": "step_height",
       "roi": {"shape": "SHAPE_RECTANGLE", "x": 150, "y": 30, "width": 80, "height": 130},
       "reference_roi": {"shape": "SHAPE_RECTANGLE", "x": 26, "y": 30, "width": 80, "height": 130},
       "tolerance": {"nominal": 1.0, "lower": -0.5, "upper": 0.5}}
    ]})";
  auto s = google::protobuf::util::JsonStringToMessage(json, &r);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return r;
}

class VerificationApiTest : public ServerTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o;
    o.specimen = "plane";
    o.camera_size = {256, 192};
    o.projector_size = {96, 72};
    o.seed = 7;
    o.z_scale_error = z_scale_error_;
    o.material_measures = material_measures_;
    return o;
  }
  // Only the camera response: quick, and a calibration to store the records with.
  std::string Calibrate() {
    v1::CalibrateRequest req;
    req.add_steps(v1::CALIBRATION_STEP_CAMERA_RESPONSE);
    v1::Job job;
    grpc::Status s = client_->Calibrate(req, nullptr, &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return job.result().calibration_id();
  }
  v1::Job Verify(v1::VerificationMode mode, int* frame_events = nullptr, int* measure_events = nullptr) {
    v1::VerifyRequest req;
    req.set_mode(mode);
    v1::Job job;
    grpc::Status s = client_->Verify(
        req,
        [&](const v1::JobEvent& e) {
          if (frame_events && e.has_frame()) ++*frame_events;
          if (measure_events && e.phase() == v1::JOB_PHASE_RECONSTRUCTING) ++*measure_events;
        },
        &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
    return job;
  }
  v1::RigStatus RigStatusNow() {
    v1::RigStatus st;
    EXPECT_TRUE(client_->GetRigStatus(&st).ok());
    return st;
  }
  v1::InspectionResult ScanStep() {
    v1::ScanRequest scan;
    scan.set_recipe_id("step");
    scan.set_part_id("step-part");
    v1::Job job;
    grpc::Status s = client_->Scan(scan, nullptr, &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return job.result().inspection();
  }

  double z_scale_error_ = 0.0;
  bool material_measures_ = true;
};

TEST_F(VerificationApiTest, AFullVerificationIsStoredWithTheCalibrationAndUsedByLaterScans) {
  StartServer();
  const std::string cal = Calibrate();
  ASSERT_FALSE(cal.empty());
  v1::RigStatus st = RigStatusNow();
  EXPECT_EQ(st.verification_state(), v1::VERIFICATION_STATE_DUE);
  EXPECT_EQ(st.verification_detail(), "no full verification under calibration " + cal);

  // A scan before any verification: the worst-case bounds, and the warning.
  v1::ListSpecimensResponse specimens;
  ASSERT_TRUE(client_->SetSpecimen("step1um", &specimens).ok());
  v1::Recipe stored;
  ASSERT_TRUE(client_->CreateRecipe(StepRecipe(), &stored).ok());
  const v1::InspectionResult before = ScanStep();
  ASSERT_EQ(before.measurements_size(), 1);
  EXPECT_EQ(before.verification_warning(), "verification due: no full verification under calibration " + cal);
  EXPECT_EQ(before.measurements(0).amplification_uncertainty(), 0.0);
  ASSERT_TRUE(client_->SetSpecimen("plane", &specimens).ok());

  int frames = 0, measures = 0;
  const v1::Job job = Verify(v1::VERIFICATION_MODE_FULL, &frames, &measures);
  EXPECT_EQ(job.kind(), v1::JOB_KIND_VERIFY);
  EXPECT_EQ(job.job_id().rfind("ver-", 0), 0u) << job.job_id();
  const v1::VerificationRecord& full = job.result().verification();
  Print("full, no injection", full);
  EXPECT_EQ(full.verification_id(), job.job_id());
  EXPECT_EQ(full.mode(), v1::VERIFICATION_MODE_FULL);
  EXPECT_EQ(full.calibration_id(), cal);
  EXPECT_EQ(full.owner(), "anonymous");
  EXPECT_EQ(full.state(), v1::VERIFICATION_STATE_VERIFIED);
  // Valid for the server's verification_interval_days (default 30), to the second.
  ASSERT_TRUE(full.has_next_full_due());
  EXPECT_EQ(full.next_full_due().seconds() - full.finish_time().seconds(), 30 * 86400);
  EXPECT_EQ(full.next_full_due().nanos(), full.finish_time().nanos());
  EXPECT_EQ(full.z_step_um(), 2.0);  // l_z was determined at 2 um steps: it bounds 2 um scans and finer
  EXPECT_EQ(full.scans(), 15);  // afl x 2, pgr2/5/10/20, acg, 8 asg
  EXPECT_GT(frames, 15 * 5);
  EXPECT_EQ(measures, 2 + 4 + 1 + 8);
  ASSERT_EQ(full.characteristics_size(), 7);
  const char* names[] = {"N_M", "z_FLT", "alpha_z", "l_z", "alpha_x", "alpha_y", "W_R"};
  for (int i = 0; i < 7; ++i) {
    const v1::VerificationCharacteristic& c = full.characteristics(i);
    EXPECT_EQ(c.name(), names[i]);
    EXPECT_GT(c.standard_uncertainty(), 0.0) << c.name();
    EXPECT_DOUBLE_EQ(c.expanded_uncertainty(), 2 * c.standard_uncertainty()) << c.name();
  }
  EXPECT_EQ(full.steps_size(), 4);
  EXPECT_EQ(full.sinusoids_size(), 8);
  // A perfect simulated instrument: unit amplification within U.
  const v1::VerificationCharacteristic& alpha_z = Characteristic(full, "alpha_z");
  EXPECT_NEAR(alpha_z.value(), 1.0, alpha_z.expanded_uncertainty());
  EXPECT_NEAR(Characteristic(full, "alpha_x").value(), 1.0, Characteristic(full, "alpha_x").expanded_uncertainty());
  EXPECT_NEAR(Characteristic(full, "alpha_y").value(), 1.0, Characteristic(full, "alpha_y").expanded_uncertainty());

  // Stored with the calibration; the rig is verified.
  v1::Calibration c;
  ASSERT_TRUE(client_->GetCalibration("", &c).ok());
  EXPECT_EQ(c.latest_full_verification().SerializeAsString(), full.SerializeAsString());
  EXPECT_FALSE(c.has_latest_interim_verification());
  st = RigStatusNow();
  EXPECT_EQ(st.verification_state(), v1::VERIFICATION_STATE_VERIFIED);
  EXPECT_EQ(st.verification_detail(), "");

  // The interim check on the same instrument: within the full verification's limits.
  const v1::Job interim_job = Verify(v1::VERIFICATION_MODE_INTERIM);
  const v1::VerificationRecord& interim = interim_job.result().verification();
  Print("interim, same instrument", interim);
  EXPECT_EQ(interim.mode(), v1::VERIFICATION_MODE_INTERIM);
  EXPECT_EQ(interim.scans(), 3);
  EXPECT_EQ(interim.characteristics_size(), 3);
  EXPECT_EQ(interim.full_verification_id(), full.verification_id());
  EXPECT_EQ(interim.state(), v1::VERIFICATION_STATE_VERIFIED);
  EXPECT_EQ(interim.findings_size(), 0);
  ASSERT_TRUE(client_->GetCalibration(cal, &c).ok());
  EXPECT_EQ(c.latest_full_verification().verification_id(), full.verification_id());
  EXPECT_EQ(c.latest_interim_verification().SerializeAsString(), interim.SerializeAsString());
  EXPECT_EQ(RigStatusNow().verification_state(), v1::VERIFICATION_STATE_VERIFIED);

  // A scan now: no warning, the verified alpha_z's component u_alpha = sqrt(u^2 + (alpha - 1)^2) |H|
  // in its uncertainty, and the verified l_z (0.04 + 2 x 0.06 um, a bound) scaling the
  // uncharacterised prior of +-0.22 um at 2 um steps (no z linearity calibrated): U smaller
  // (0.59 -> 0.43 um), still covering the simulator's 1.000 um.
  ASSERT_TRUE(client_->SetSpecimen("step1um", &specimens).ok());
  const v1::InspectionResult after = ScanStep();
  ASSERT_EQ(after.measurements_size(), 1);
  const v1::MeasurementResult& b = before.measurements(0);
  const v1::MeasurementResult& a = after.measurements(0);
  std::printf("step1um at 2 um steps (the verification's): before %.4f um U %.4f; after %.4f um U %.4f (u_alpha %.5f um)\n", b.value(),
              b.expanded_uncertainty(), a.value(), a.expanded_uncertainty(), a.amplification_uncertainty());
  EXPECT_EQ(after.verification_warning(), "");
  const double rel = std::hypot(alpha_z.standard_uncertainty(), alpha_z.value() - 1.0);
  EXPECT_NEAR(a.amplification_uncertainty(), rel * std::abs(a.value()), 1e-12);
  EXPECT_GT(a.amplification_uncertainty(), 0.0);
  EXPECT_LE(a.amplification_uncertainty(), a.standard_uncertainty());
  EXPECT_LT(a.expanded_uncertainty(), 0.85 * b.expanded_uncertainty());
  EXPECT_NEAR(a.value(), 1.0, a.expanded_uncertainty());
  EXPECT_NEAR(b.value(), 1.0, b.expanded_uncertainty());

  // The report shows the state.
  ASSERT_FALSE(after.report_artifact_id().empty());
  const std::filesystem::path report = UniqueTempDir("verify") / "report.html";
  ASSERT_TRUE(client_->DownloadArtifact(after.report_artifact_id(), report, false).ok());
  std::stringstream html;
  html << std::ifstream(report).rdbuf();
  EXPECT_NE(html.str().find("<span id=\"verification\">verified</span>"), std::string::npos);
}

TEST_F(VerificationApiTest, AnInjectedZScaleErrorIsRecoveredAndALaterChangeFailsTheInterimCheck) {
  // Optics whose heights come out 0.5 % long: the full verification finds alpha_z = 1.005 within U.
  z_scale_error_ = 0.005;
  StartServer();
  const std::string cal = Calibrate();
  const v1::VerificationRecord full = Verify(v1::VERIFICATION_MODE_FULL).result().verification();
  Print("full, z scale +0.5 %", full);
  const v1::VerificationCharacteristic& alpha_z = Characteristic(full, "alpha_z");
  EXPECT_NEAR(alpha_z.value(), 1.005, alpha_z.expanded_uncertainty());
  // ... then they drift to +3 % (same data directory, same calibration): the interim check's
  // 10 um step reads ~0.25 um more than the full verification's, beyond their combined U.
  StopServer();
  z_scale_error_ = 0.03;
  StartServer();
  ASSERT_EQ(RigStatusNow().active_calibration_id(), cal);
  EXPECT_EQ(RigStatusNow().verification_state(), v1::VERIFICATION_STATE_VERIFIED);
  const v1::VerificationRecord interim = Verify(v1::VERIFICATION_MODE_INTERIM).result().verification();
  Print("interim after +3 % z scale", interim);
  EXPECT_EQ(interim.state(), v1::VERIFICATION_STATE_FAILED);
  EXPECT_EQ(interim.full_verification_id(), full.verification_id());
  ASSERT_GE(interim.findings_size(), 1);
  std::string findings;
  for (const std::string& f : interim.findings()) findings += (findings.empty() ? "" : "; ") + f;
  EXPECT_NE(findings.find("pgr10"), std::string::npos) << findings;
  v1::RigStatus st = RigStatusNow();
  EXPECT_EQ(st.verification_state(), v1::VERIFICATION_STATE_FAILED);
  EXPECT_EQ(st.verification_detail(), "interim check " + interim.verification_id() + ": " + findings);

  // Scans keep running and carry the warning, in the result feed too.
  v1::ListSpecimensResponse specimens;
  ASSERT_TRUE(client_->SetSpecimen("step1um", &specimens).ok());
  v1::Recipe stored;
  ASSERT_TRUE(client_->CreateRecipe(StepRecipe(), &stored).ok());
  const v1::InspectionResult result = ScanStep();
  EXPECT_EQ(result.verdict(), v1::VERDICT_OK);
  EXPECT_EQ(result.verification_warning(), "verification failed: " + st.verification_detail());
  v1::ListResultsResponse results;
  ASSERT_TRUE(client_->ListResults(v1::ListResultsRequest(), &results).ok());
  ASSERT_EQ(results.results_size(), 1);
  EXPECT_EQ(results.results(0).verification_warning(), result.verification_warning());
  ASSERT_TRUE(client_->SetSpecimen("plane", &specimens).ok());

  // A new full verification measures the instrument as it is now, and the rig is verified again.
  const v1::VerificationRecord again = Verify(v1::VERIFICATION_MODE_FULL).result().verification();
  Print("full, z scale +3 %", again);
  const v1::VerificationCharacteristic& alpha_again = Characteristic(again, "alpha_z");
  EXPECT_NEAR(alpha_again.value(), 1.03, alpha_again.expanded_uncertainty());
  EXPECT_EQ(RigStatusNow().verification_state(), v1::VERIFICATION_STATE_VERIFIED);
}

TEST_F(VerificationApiTest, ARigWithoutMaterialMeasuresIsRefusedNamingTheField) {
  material_measures_ = false;
  StartServer();
  v1::ListJobsResponse before;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &before).ok());
  v1::Job job;
  grpc::Status s = client_->Verify(v1::VerifyRequest(), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(s.error_message().rfind("material_measures: ", 0), 0u) << s.error_message();
  v1::VerifyRequest bad;
  bad.set_mode(v1::VerificationMode(7));
  s = client_->Verify(bad, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("mode 7"), std::string::npos) << s.error_message();
  v1::ListJobsResponse after;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &after).ok());
  EXPECT_EQ(after.jobs_size(), before.jobs_size());  // refused before anything queued
  EXPECT_EQ(RigStatusNow().verification_state(), v1::VERIFICATION_STATE_DUE);
}

TEST_F(VerificationApiTest, ACancelledVerificationStoresNothing) {
  StartServer();
  const std::string cal = Calibrate();
  control_->hold_at_frame = control_->captures + 40;  // within the third measure's scan
  v1::Job job;
  grpc::Status s;
  std::thread verify([&] {
    auto c = NewClient();
    s = c->Verify(v1::VerifyRequest(), nullptr, &job);
  });
  ASSERT_TRUE(control_->WaitUntilHolding());
  v1::RigStatus rig = RigStatusNow();
  ASSERT_EQ(rig.running_job_id().rfind("ver-", 0), 0u) << rig.running_job_id();
  v1::Job cancelled;
  ASSERT_TRUE(client_->CancelJob(rig.running_job_id(), &cancelled).ok());
  control_->Release();
  verify.join();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::CANCELLED) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_CANCELLED);
  v1::Calibration c;
  ASSERT_TRUE(client_->GetCalibration(cal, &c).ok());
  EXPECT_FALSE(c.has_latest_full_verification());
  EXPECT_FALSE(c.has_latest_interim_verification());
  EXPECT_EQ(RigStatusNow().verification_state(), v1::VERIFICATION_STATE_DUE);
  EXPECT_FALSE(std::filesystem::exists(data_dir_ / "tmp" / (job.job_id() + ".verify")));
  EXPECT_EQ(RigStatusNow().specimen(), "plane");  // the measure taken off again
}

}  // namespace
}  // namespace inspection::testing
