// inspectctl --alignment through the built binary: a rig whose magnification
// breathes 2 %/100 um and drifts laterally; `reconstruct --scan-id ID --alignment estimate`
// prints the estimated alignment; `--alignment calibrated` without the focus_breathing step is
// FAILED_PRECONDITION naming it (exit 4); an unknown value exits 2.
#include "tests/client_cli/cli_fixture.h"

namespace inspection::testing {
namespace {

class CliAlignmentTest : public CliTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o = CliTest::SimOptions();
    o.seed = 4;
    o.focus_breathing_percent_per_100um = 2.0;
    o.lateral_drift_x_px_per_100um = 5.0;
    o.lateral_drift_y_px_per_100um = -3.0;
    return o;
  }
};

TEST_F(CliAlignmentTest, ReconstructEstimatesCalibratedNeedsTheStepUnknownIsUsage) {
  StartServer();
  v1::Job scan;
  ASSERT_TRUE(client_->Scan(v1::ScanRequest(), nullptr, &scan).ok());
  const std::string scan_id = scan.result().scan_id();
  ASSERT_FALSE(scan_id.empty());

  CliResult r = Run({"reconstruct", "--scan-id", scan_id, "--alignment", "estimate", "--out", (work_ / "e").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const size_t at = r.out.find("alignment: estimate, scale change up to ");
  ASSERT_NE(at, std::string::npos) << r.out;
  // The largest scale change against the middle frame: 2 %/100 um over half the stack's z span
  // (5 um steps, the rig's default).
  const double half_span_um = (scan.result().depth().frame_count() - 1) * 5.0 / 2.0;
  const double expected = 2.0 * half_span_um / 100.0;
  const double printed = std::stod(r.out.substr(at + std::string("alignment: estimate, scale change up to ").size()));
  std::printf("printed scale change %.3f %%, true %.3f %%\n", printed, expected);
  EXPECT_NEAR(printed, expected, 0.25 * expected);
  EXPECT_TRUE(fs::exists(work_ / "e" / "depth.tiff"));

  r = Run({"reconstruct", "--scan-id", scan_id, "--alignment", "calibrated", "--out", (work_ / "c").string()});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.err.rfind("inspectctl: FAILED_PRECONDITION: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("focus_breathing"), std::string::npos) << r.err;

  r = Run({"reconstruct", "--scan-id", scan_id, "--alignment", "sideways", "--out", (work_ / "u").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--alignment"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace inspection::testing
