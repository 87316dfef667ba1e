// inspectctl scan --auto-range against the real server: the sweep's frames shown in their own
// phase, the chosen range in the summary, bad search flags as usage errors (exit 2) or one
// INVALID_ARGUMENT line naming the field (exit 4).
#include "tests/client_cli/cli_fixture.h"

namespace inspection::testing {
namespace {

TEST_F(CliTest, AutoRangeShowsTheSearchPhaseAndTheChosenRange) {
  StartServer();
  const fs::path out = work_ / "auto";
  // skew5 at 320x240: true heights 200 .. ~221 um; window 150 .. 330 um at 20 um: 10 frames
  // and up to 4 refinement frames planned; the field settles two frames past its top's focus,
  // so the sweep stops there, and 2-4 frames refine the range's ends.
  CliResult r = Run({"scan", "--out", out.string(), "--auto-range", "--search-window", "150:330", "--coarse-step", "20",
                     "--z-step", "5"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  v1::Job job;
  ASSERT_TRUE(client_->GetJob(NewestJobId(), &job).ok());
  const v1::ZRangeSearchResult& z = job.result().depth().z_range_search();
  EXPECT_TRUE(z.stopped_early());
  EXPECT_LT(z.coarse_frame_count(), 10);
  EXPECT_GE(z.coarse_frame_count(), 6);  // frames at 150 .. 250 um: 230 holds the top, 2 past it
  EXPECT_LE(z.z_start_um(), 200.0);
  EXPECT_GE(z.z_end_um(), 220.0);
  EXPECT_NE(r.out.find("FOCUS_SEARCH 1/14 z=15"), std::string::npos) << r.out;
  EXPECT_GE(z.refine_frame_count(), 2);
  const std::string last =
      "(capture " + std::to_string(z.coarse_frame_count() + z.refine_frame_count()) + ", not kept)";
  EXPECT_NE(r.out.find(last), std::string::npos) << r.out;
  char line[256];
  std::snprintf(line, sizeof line, "z range: automatic, %.2f .. %.2f um", z.z_start_um(), z.z_end_um());
  EXPECT_NE(r.out.find(line), std::string::npos) << r.out;
  std::snprintf(line, sizeof line,
                "%d coarse frames over 150.00 .. 330.00 um at 20.00 um (stopped early: %.1f %% of the field past "
                "focus), %d refining its ends",
                z.coarse_frame_count(), z.settled_percent(), z.refine_frame_count());
  EXPECT_NE(r.out.find(line), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(out / "depth.tiff"));
}

TEST_F(CliTest, AutoRangeBadFlagsAreUsageErrorsOrOneLineNamingTheField) {
  StartServer();
  const std::string out = (work_ / "bad").string();
  EXPECT_EQ(Run({"scan", "--out", out, "--auto-range", "--z-start", "100"}).exit_code, 2);
  EXPECT_EQ(Run({"scan", "--out", out, "--search-window", "100:200"}).exit_code, 2);  // needs --auto-range
  EXPECT_EQ(Run({"scan", "--out", out, "--auto-range", "--search-window", "100-200"}).exit_code, 2);
  CliResult r = Run({"scan", "--out", out, "--auto-range", "--search-window", "100:30000"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("inspectctl: INVALID_ARGUMENT: z_range_search.window_end_um", 0), 0u) << r.err;
  r = Run({"scan", "--out", out, "--auto-range", "--search-window", "100:140", "--coarse-step", "30"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_NE(r.err.find("z_range_search.coarse_step_um"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(fs::path(out) / "depth.tiff"));
}

}  // namespace
}  // namespace inspection::testing
