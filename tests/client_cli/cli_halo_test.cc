// inspectctl --halo-suppression through the built binary and the real server: on a plain image
// folder of a bright textured object in front of a dark textured background
// (tests/core/halo_scene_synthetic.h: thin lens with occlusion), the depth and all-in-focus
// errors in the halo band fall against the same run without it, the result prints its line, and
// with an integral method the server refuses it naming the field (exit 4).
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/io/depth_export.h"
#include "tests/client_cli/cli_fixture.h"
#include "tests/core/halo_scene_synthetic.h"

namespace inspection::testing {
namespace {

TEST_F(CliTest, HaloSuppressionReachesTheServerAndLowersTheHaloBandError) {
  StartServer();
  testing_halo::HaloSceneOptions o;
  o.seed = 3;
  const testing_halo::HaloScene s = testing_halo::RenderHaloScene(o);
  const fs::path images = work_ / "halo";
  fs::create_directories(images);
  for (size_t i = 0; i < s.frames.size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "img%02zu.png", i);
    ASSERT_TRUE(cv::imwrite((images / name).string(), s.frames[i]));
  }
  // The same folder, the same options, with and without: the difference is the halo pass.
  const std::vector<std::string> common = {"reconstruct", "--images", images.string(), "--z-step", "1",
                                           "--alignment", "none", "--dense", "off"};
  auto run = [&](const std::string& out, bool halo, CliResult* r) {
    std::vector<std::string> args = common;
    args.insert(args.end(), {"--out", (work_ / out).string()});
    if (halo) args.push_back("--halo-suppression");
    *r = Run(args);
    ASSERT_EQ(r->exit_code, 0) << r->err;
  };
  CliResult before_run, after_run;
  ASSERT_NO_FATAL_FAILURE(run("before", false, &before_run));
  ASSERT_NO_FATAL_FAILURE(run("after", true, &after_run));
  EXPECT_EQ(before_run.out.find("halo suppression:"), std::string::npos) << before_run.out;
  v1::Job job;
  ASSERT_TRUE(client_->GetJob(NewestJobId(), &job).ok());
  const v1::DepthSummary& d = job.result().depth();
  ASSERT_GT(d.halo_reassigned_percent(), 1.0);
  EXPECT_GE(d.halo_candidate_percent(), d.halo_reassigned_percent());
  char line[160];
  std::snprintf(line, sizeof line, "halo suppression: %.1f %% of the pixels re-examined near depth jumps, %.1f %% moved",
                d.halo_candidate_percent(), d.halo_reassigned_percent());
  EXPECT_NE(after_run.out.find(line), std::string::npos) << after_run.out;

  testing_halo::HaloBandError e[2];
  for (int k = 0; k < 2; ++k) {
    const fs::path dir = work_ / (k ? "after" : "before");
    auto depth = ReadDepthTiff(dir / "depth.tiff");
    ASSERT_TRUE(depth.ok()) << depth.status().ToString();
    const cv::Mat aif = cv::imread((dir / "all_in_focus.png").string(), cv::IMREAD_GRAYSCALE);
    ASSERT_EQ(aif.size(), s.foreground.size());
    e[k] = testing_halo::HaloBandErrorOf(s, *depth, aif);  // depth in um = frames (z step 1 from 0)
  }
  std::printf("halo band through inspectctl: depth RMSE %.2f -> %.2f frames (valid %.1f -> %.1f %%), AIF RMS %.2f -> "
              "%.2f grey\n",
              e[0].depth_rmse_frames, e[1].depth_rmse_frames, e[0].valid_percent, e[1].valid_percent, e[0].aif_rms,
              e[1].aif_rms);
  // The core test's figures on the same scene (post-processed 0.37 -> 0.31 frames; AIF down).
  EXPECT_LT(e[1].depth_rmse_frames, 0.9 * e[0].depth_rmse_frames);
  EXPECT_GE(e[1].valid_percent, 0.9 * e[0].valid_percent);
  EXPECT_LT(e[1].aif_rms, 0.95 * e[0].aif_rms);

  CliResult bad = Run({"reconstruct", "--images", images.string(), "--z-step", "1", "--method", "isff",
                       "--halo-suppression", "--out", (work_ / "isff").string()});
  EXPECT_EQ(bad.exit_code, 4) << bad.out;
  EXPECT_NE(bad.err.find("options.halo_suppression"), std::string::npos) << bad.err;
}

// A rig scan: the coin under STD (a bright polished field beside darker relief, whose blur
// spreads at depth jumps). The scan path runs the pass on the frames it stored; reconstructing
// the same stored scan with and without it isolates the pass (the same pixels).
TEST_F(CliTest, HaloSuppressionOnAScanAndOnItsStoredStack) {
  StartServer();
  ASSERT_EQ(Run({"specimen", "set", "coin"}).exit_code, 0);
  CliResult r = Run({"scan", "--out", (work_ / "scan").string(), "--halo-suppression"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  v1::Job scan;
  ASSERT_TRUE(client_->GetJob(NewestJobId(), &scan).ok());
  EXPECT_GT(scan.result().depth().halo_candidate_percent(), 5.0);
  EXPECT_NE(r.out.find("halo suppression: "), std::string::npos) << r.out;
  const std::string id = scan.result().scan_id();
  ASSERT_FALSE(id.empty());
  v1::DepthSummary d[2];
  for (int k = 0; k < 2; ++k) {
    std::vector<std::string> args = {"reconstruct", "--scan-id", id, "--out", (work_ / ("r" + std::to_string(k))).string()};
    if (k) args.push_back("--halo-suppression");
    r = Run(args);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    v1::Job job;
    ASSERT_TRUE(client_->GetJob(NewestJobId(), &job).ok());
    d[k] = job.result().depth();
    ASSERT_TRUE(d[k].has_ground_truth());
  }
  std::printf("coin STD %dx%d: RMSE %.3f -> %.3f um, valid %.1f -> %.1f %%, moved %.1f %% of %.1f %%\n", d[0].width(),
              d[0].height(), d[0].rmse_um(), d[1].rmse_um(), d[0].valid_percent(), d[1].valid_percent(),
              d[1].halo_reassigned_percent(), d[1].halo_candidate_percent());
  EXPECT_EQ(d[0].halo_candidate_percent(), 0.0);
  EXPECT_GT(d[1].halo_reassigned_percent(), 1.0);
  // Measured 3.105 -> 3.140 um at this 320x240 camera. Until the default
  // estimate tested its rates against their scatter it warped this still stack (the coin's
  // outline changes its apparent size with defocus), 8.339 -> 7.993 um: suppression made up for
  // part of that misregistration. On the still stack it moves 6-7 % of the pixels and costs at
  // most 2 % of RMSE; its gain is measured on the halo scene above.
  EXPECT_LT(d[1].rmse_um(), 1.02 * d[0].rmse_um());
  EXPECT_LT(d[0].rmse_um(), 4.0);
  EXPECT_GE(d[1].valid_percent(), 0.95 * d[0].valid_percent());
}

}  // namespace
}  // namespace inspection::testing
