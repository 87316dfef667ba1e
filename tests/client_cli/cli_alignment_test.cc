// inspectctl --alignment through the built binary: a rig whose magnification
// breathes 2 %/100 um and drifts laterally; `reconstruct --scan-id ID --alignment estimate`
// prints the estimated alignment; `--alignment calibrated` without the focus_breathing step is
// FAILED_PRECONDITION naming it (exit 4); an unknown value exits 2.
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

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

// A plain image folder of n frames: a smooth random texture shifted by (shift_px, -shift_px / 2)
// * u^power, u = i / (n - 1) (featureless: flat grey, only sensor noise), defocus varying with
// the frame.
void WriteImages(const fs::path& dir, int n, double shift_px, bool textured, double power = 1.0) {
  fs::create_directories(dir);
  const cv::Size size(256, 192);
  cv::Mat scene(size, CV_32F);
  cv::RNG rng(21);
  rng.fill(scene, cv::RNG::NORMAL, 0.0, 1.0);
  cv::GaussianBlur(scene, scene, cv::Size(0, 0), 2.0);
  cv::normalize(scene, scene, 40, 216, cv::NORM_MINMAX);
  if (!textured) scene.setTo(128);
  for (int i = 0; i < n; ++i) {
    const double u = std::pow(double(i) / (n - 1), power);
    cv::Mat f;
    cv::warpAffine(scene, f, cv::Matx23d(1, 0, shift_px * u, 0, 1, -0.5 * shift_px * u), size,
                   cv::INTER_CUBIC | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT_101);
    cv::GaussianBlur(f, f, cv::Size(0, 0), 0.7 + 1.2 * std::abs(u - 0.4));
    cv::Mat noise(size, CV_32F);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
    cv::Mat out;
    cv::Mat(f + noise).convertTo(out, CV_8U);
    ASSERT_TRUE(cv::imwrite((dir / ("img" + std::to_string(i) + ".png")).string(), out));
  }
}

TEST_F(CliAlignmentTest, ImageFolderPrintsTheChainPerFrameAndTheDefaultsFallback) {
  StartServer();
  WriteImages(work_ / "moving", 9, 16.0, true);
  CliResult r = Run({"reconstruct", "--images", (work_ / "moving").string(), "--z-step", "5", "--alignment",
                     "estimate", "--out", (work_ / "m").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("alignment: estimate, scale change up to "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(", method chain\n"), std::string::npos) << r.out;
  // One line per frame; the last frame is 16 * (8 - 4) / 8 = 8 px right and 4 px up of the
  // reference (frame 4): its transform maps reference pixels to frame pixels, so x - 8, y + 4.
  EXPECT_NE(r.out.find("  frame 4 (reference): scale 1.00000, rotation 0.0000 deg, shift 0.00, 0.00 px\n"),
            std::string::npos)
      << r.out;
  const size_t last = r.out.find("  frame 8: scale ");
  ASSERT_NE(last, std::string::npos) << r.out;
  const std::string line = r.out.substr(last, r.out.find('\n', last) - last);
  const size_t shift_at = line.find("shift ");
  ASSERT_NE(shift_at, std::string::npos) << line;
  double sx = 0, sy = 0;
  ASSERT_EQ(std::sscanf(line.c_str() + shift_at, "shift %lf, %lf px", &sx, &sy), 2) << line;
  EXPECT_NEAR(sx, -8.0, 0.3) << line;
  EXPECT_NEAR(sy, 4.0, 0.3) << line;

  // The default on a folder whose motion is not linear in its z (shift ~ u^3): the linear-in-z
  // model does not fit, so the chain registers it, and the CLI prints why under the alignment line.
  WriteImages(work_ / "rail", 9, 16.0, true, 3.0);
  r = Run({"reconstruct", "--images", (work_ / "rail").string(), "--z-step", "5", "--out", (work_ / "r").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find(", method chain\n  why: the linear-in-z focus-breathing model did not fit ("), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("); registered as a chain of neighbouring frames instead\n"), std::string::npos) << r.out;

  WriteImages(work_ / "flat", 6, 0.0, false);
  r = Run({"reconstruct", "--images", (work_ / "flat").string(), "--z-step", "5", "--out", (work_ / "f").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("alignment: none (the default fell back to none: "),
            std::string::npos)
      << r.out;
}

}  // namespace
}  // namespace inspection::testing
