// inspectctl verify as a metrologist runs it: the built binary against the real server on the
// simulated rig's material measures (256 x 192 camera). The full verification prints each
// characteristic with its U and unit and the state, the interim check its state against the full
// one, `status` the rig's verification state; a rig without material measures exits 4 with one
// line naming the field.
#include "tests/client_cli/cli_fixture.h"

namespace inspection::testing {
namespace {

class CliVerifyTest : public CliTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o;
    o.specimen = "plane";
    o.camera_size = {256, 192};
    o.projector_size = {96, 72};
    o.seed = 7;
    o.material_measures = material_measures_;
    return o;
  }
  bool material_measures_ = true;
};

TEST_F(CliVerifyTest, VerifyPrintsTheRecordAndStatusTheState) {
  StartServer();
  CliResult r = Run({"status"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("verification: verification due (no full verification under the uncalibrated rig)\n"),
            std::string::npos)
      << r.out;

  r = Run({"verify"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::printf("%s", r.out.c_str());
  EXPECT_NE(r.out.find(": verified (15 scans, calibration none)\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  characteristic          value        U (k=2)  unit\n"), std::string::npos) << r.out;
  for (const char* name : {"N_M", "z_FLT", "alpha_z", "l_z", "alpha_x", "alpha_y", "W_R"}) {
    EXPECT_NE(r.out.find(std::string("\n  ") + name + " "), std::string::npos) << name << "\n" << r.out;
  }
  EXPECT_NE(r.out.find("  step pgr10    certified 10.0000 um, measured "), std::string::npos) << r.out;

  // The record as JSON: the job's result.
  r = Run({"--json", "verify", "--interim"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto lines = JsonLines(r.out);
  ASSERT_FALSE(lines.empty());
  const json& v = lines.back()["job"]["result"]["verification"];
  EXPECT_EQ(v["mode"], "VERIFICATION_MODE_INTERIM");
  EXPECT_EQ(v["state"], "VERIFICATION_STATE_VERIFIED");
  EXPECT_EQ(v["characteristics"].size(), 3u);
  EXPECT_EQ(v["characteristics"][2]["name"], "alpha_z");

  r = Run({"status"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("verification: verified\n"), std::string::npos) << r.out;
}

TEST_F(CliVerifyTest, CalibrationShowListsTheNewestVerificationOfEachMode) {
  StartServer();
  v1::CalibrateRequest cal;
  cal.add_steps(v1::CALIBRATION_STEP_CAMERA_RESPONSE);
  v1::Job job;
  ASSERT_TRUE(client_->Calibrate(cal, nullptr, &job).ok());
  CliResult r = Run({"--quiet", "verify", "--interim"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = Run({"calibration", "show"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // An interim check without a full verification under the calibration: due.
  EXPECT_NE(r.out.find("  interim verification ver-"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(": verification due, N_M "), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("  full verification"), std::string::npos) << r.out;
}

TEST_F(CliVerifyTest, ARigWithoutMaterialMeasuresExitsFourWithOneLine) {
  material_measures_ = false;
  StartServer();
  CliResult r = Run({"verify", "--interim"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.out, "");
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("inspectctl: FAILED_PRECONDITION: material_measures: ", 0), 0u) << r.err;
}

}  // namespace
}  // namespace inspection::testing
