// Illumination modes of thesis 5-6 on the simulated rig (small size), against ground truth
// (figures: sigma, bias = mean signed error, RMSE): every mode's bias stays within
// max(0.1 um, 0.02 z steps) on textured specimens, whichever the scan direction; ADAPT and
// HF+ADAPT measure the saturating cutter with at most STD + 3 frames where HDR3 leaves the land
// empty, TEXTURE makes the textureless lens measurable, HF+ADAPT has fewer outliers than STD on
// the coin, ADAPT's image reaches the target grey within 3 frames, missing calibration steps
// are named, and the default post-processing (depth consistency) leaves textured specimens as
// they are while removing wrong depths from the saturating cutter.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "core/metrology/depth_metrics.h"
#include "devices/sim/simulated_rig.h"
#include "server/procedures/calibration_procedure.h"
#include "server/procedures/illumination_strategy.h"
#include "server/procedures/scan_procedure.h"
#include "tests/lib/user_scene.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

SimulatedRigOptions SmallRig() {
  SimulatedRigOptions o;
  o.camera_size = {256, 192};
  o.projector_size = {96, 72};
  o.seed = 5;
  return o;
}

struct ModeRun {
  DepthErrorStats error;
  int images = 0;
  std::vector<FrameStatistics> captures;
  cv::Mat depth_um, truth_um;
  double z_step_um = 0;
  IlluminationMode ran = IlluminationMode::kStd;  // AUTO: the mode it chose
  StackManifest manifest;                         // read back from the stack folder
};

// docs/illumination.md: |bias| <= 0.1 um or 0.02 z steps, whichever is larger.
double BiasBoundUm(double z_step_um) { return std::max(0.1, 0.02 * z_step_um); }

// a's depth error on the pixels both a and b measured: a method that leaves the hard pixels
// without depth is not rewarded for it.
DepthErrorStats ErrorOnCommonPixels(const ModeRun& a, const ModeRun& b) {
  const cv::Mat both = (a.depth_um == a.depth_um) & (b.depth_um == b.depth_um);
  return CompareDepth(a.depth_um, a.truth_um, both, 10.0, 9);
}

class ScanModesTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto rig = CreateSimulatedRig(SmallRig());
    ASSERT_TRUE(rig.ok()) << rig.status().ToString();
    rig_ = rig->release();
    CalibrationOptions o;
    o.steps = {CalibrationStep::kCameraResponse, CalibrationStep::kProjectorResponse, CalibrationStep::kGeometry,
               CalibrationStep::kPsf, CalibrationStep::kScatterMatrix};
    o.crf_exposure_count = 16;
    o.prf_level_step = 15;
    o.geometry_grid_spacing_px = 6;
    o.psf_defocus_um = {-10.0, 0.0, 10.0};
    o.psf_grid_spacing_px = 12;
    o.scatter_grid_spacing_px = 6;
    std::atomic<bool> cancel{false};
    auto b = RunCalibration(*rig_, o, nullptr, nullptr, cancel);
    ASSERT_TRUE(b.ok()) << b.status().ToString();
    bundle_ = new CalibrationBundle(std::move(b).value());
    dir_ = new fs::path(fs::temp_directory_path() / ("scan_modes_test_" + std::to_string(::getpid())));
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    if (dir_) fs::remove_all(*dir_, ec);
    delete dir_;
    delete bundle_;
    delete rig_;
  }

  static StatusOr<ModeRun> Scan(const std::string& specimen, IlluminationMode mode, IlluminationParams params = {},
                                int window_px = 9, double z_step_um = 0, std::vector<ScanFrameEvent>* events = nullptr,
                                bool downwards = false, bool consistency = false, bool illumination_invariant = false) {
    INSPECT_RETURN_IF_ERROR(rig_->simulation()->SetSpecimen(specimen));
    const ScanDefaults d = rig_->scan_defaults();
    const double step = z_step_um > 0 ? z_step_um : d.z_step_um;
    INSPECT_ASSIGN_OR_RETURN(ScanPlan plan,
                             downwards ? MakeScanPlan(d.z_end_um, d.z_start_um, step, d.exposure_us, rig_->stage())
                                       : MakeScanPlan(d.z_start_um, d.z_end_um, step, d.exposure_us, rig_->stage()));
    plan.mode = mode;
    plan.params = params;
    plan.sff.window_px = window_px;
    // The thesis's comparisons (ch. 6) are of the SFF output itself; the default post-processing
    // rejects inconsistent pixels (core/sff/depth_postprocess.h), which removes most of STD's outliers
    // together with their coverage. It is checked on its own in
    // DefaultPostProcessingKeepsTexturedSpecimensAndRemovesWrongDepths.
    plan.postprocess.consistency = consistency;
    plan.sff.illumination_invariant = illumination_invariant;
    std::atomic<bool> cancel{false};
    const fs::path stack = *dir_ / (specimen + "_" + IlluminationModeName(mode, params.hdr_exposures));
    auto on_frame = [&](const ScanFrameEvent& e) {
      if (events) events->push_back(e);
    };
    INSPECT_ASSIGN_OR_RETURN(ScanOutcome o, RunScan(*rig_, plan, stack, on_frame, cancel, bundle_));
    ModeRun r;
    r.error = CompareDepth(o.depth.depth_um, o.ground_truth_um, 2.0 * d.z_step_um, window_px);
    r.images = o.images_acquired;
    r.captures = o.capture_statistics;
    r.depth_um = o.depth.depth_um;
    r.truth_um = o.ground_truth_um;
    r.z_step_um = step;
    r.ran = o.illumination;
    INSPECT_ASSIGN_OR_RETURN(r.manifest, ReadStackManifest(stack));
    std::printf("%-8s %-10s%s%s%s sigma %.3f um  bias %+.3f um  RMSE %.3f um  valid %.1f %%  outliers %.2f %%  images %d\n",
                specimen.c_str(), IlluminationModeName(mode, params.hdr_exposures).c_str(), downwards ? " (down)" : "",
                consistency ? " (consistency)" : "", illumination_invariant ? " (invariant)" : "",
                r.error.stddev_error_um, r.error.mean_error_um, r.error.rmse_um, r.error.valid_percent,
                r.error.outlier_percent, r.images);
    return r;
  }

  static Rig* rig_;
  static CalibrationBundle* bundle_;
  static fs::path* dir_;
};
Rig* ScanModesTest::rig_ = nullptr;
CalibrationBundle* ScanModesTest::bundle_ = nullptr;
fs::path* ScanModesTest::dir_ = nullptr;

// The ADAPT family carried a depth bias that followed the scan direction (corrections computed
// at one z lit the next while it passed through focus; core/illumination/compensation.h). Every mode that
// measures >= 95 % of a textured specimen must stay within the bias bound, up and down.
TEST_F(ScanModesTest, BiasWithinBoundOnTexturedFlatAndSaturatingSpecimens) {
  ASSERT_NE(bundle_, nullptr);
  const IlluminationMode all[] = {
      IlluminationMode::kStd,      IlluminationMode::kHdr,     IlluminationMode::kAdaptIterative,
      IlluminationMode::kAdapt,    IlluminationMode::kTexture, IlluminationMode::kHfAdapt,
      IlluminationMode::kAdaptedHf, IlluminationMode::kAuto};
  auto check = [](const std::string& what, const StatusOr<ModeRun>& r) {
    ASSERT_TRUE(r.ok()) << what << ": " << r.status().ToString();
    EXPECT_GE(r->error.valid_percent, 95.0) << what;
    EXPECT_LE(std::abs(r->error.mean_error_um), BiasBoundUm(r->z_step_um)) << what;
  };
  // Specimens whose heights span many z steps: every mode, the default (AUTO) included.
  for (const char* specimen : {"wedge", "skew5", "skew10"}) {
    double best_std_texture_rmse = 1e9, default_rmse = 0;
    for (IlluminationMode m : all) {
      auto r = Scan(specimen, m);
      check(std::string(specimen) + " " + IlluminationModeName(m), r);
      if (!r.ok()) continue;
      if (m == IlluminationMode::kStd || m == IlluminationMode::kTexture) {
        best_std_texture_rmse = std::min(best_std_texture_rmse, r->error.rmse_um);
      }
      if (m == IlluminationMode::kAuto) default_rmse = r->error.rmse_um;
    }
    // The default's target against the better of STD and TEXTURE: within 10 %.
    std::printf("%s: default AUTO RMSE %.3f um, better of STD and TEXTURE %.3f um, ratio %.2f\n", specimen,
                default_rmse, best_std_texture_rmse, default_rmse / best_std_texture_rmse);
    EXPECT_LE(default_rmse, 1.1 * best_std_texture_rmse) << specimen;
  }
  // Flat specimens put every pixel between the same two frames, so a sub-step interpolation
  // error is a bias of the whole map; the defocus parabola keeps these modes within the bound on
  // the 1 um step and TEXTURE and HF+ADAPT on the mirror (the Gaussian: -0.07 to -0.17 um). On a
  // flat part one scan's bias also holds the stage's +-0.1 um repeatability on the 2-3 frames in
  // focus (scan-to-scan sd 0.03-0.07 um, inspect-evaluate --repeats), so the bound is asserted
  // on the mean of 4 scans (the systematic part) and each scan within twice the bound.
  auto check_flat = [&](const std::string& specimen, IlluminationMode m) {
    const std::string what = specimen + " " + IlluminationModeName(m);
    double sum = 0, bound = 0;
    constexpr int kScans = 4;
    for (int k = 0; k < kScans; ++k) {
      auto r = Scan(specimen, m);
      ASSERT_TRUE(r.ok()) << what << ": " << r.status().ToString();
      EXPECT_GE(r->error.valid_percent, 95.0) << what;
      bound = BiasBoundUm(r->z_step_um);
      EXPECT_LE(std::abs(r->error.mean_error_um), 2.0 * bound) << what << " scan " << k;
      sum += r->error.mean_error_um;
    }
    std::printf("%s: mean bias over %d scans %+.3f um\n", what.c_str(), kScans, sum / kScans);
    EXPECT_LE(std::abs(sum / kScans), bound) << what;
  };
  for (IlluminationMode m : {IlluminationMode::kStd, IlluminationMode::kHdr, IlluminationMode::kAdaptIterative,
                             IlluminationMode::kAdapt, IlluminationMode::kTexture, IlluminationMode::kAuto}) {
    check_flat("step1um", m);
  }
  for (IlluminationMode m : {IlluminationMode::kTexture, IlluminationMode::kHfAdapt, IlluminationMode::kAuto}) {
    check_flat("mirror", m);
  }
  // The saturating cutter, where STD and HDR3 leave pixels without depth: the adaptive modes.
  // (TEXTURE's bias there, -0.08 to -0.11 um, comes from pixels its checkerboard saturates.)
  for (IlluminationMode m : {IlluminationMode::kAdaptIterative, IlluminationMode::kAdapt, IlluminationMode::kHfAdapt,
                             IlluminationMode::kAdaptedHf, IlluminationMode::kAuto}) {
    check("cutter " + IlluminationModeName(m), Scan("cutter", m));
  }
  // The lag's signature was a bias whose sign followed the scan direction.
  check("wedge HF+ADAPT downwards", Scan("wedge", IlluminationMode::kHfAdapt, {}, 9, 0, nullptr, true));
  check("wedge ADAPT downwards", Scan("wedge", IlluminationMode::kAdapt, {}, 9, 0, nullptr, true));
}

// The cause, kept as a regression guard: with the thesis's per-pixel eq. 5.5 for corrections
// shown at the next z (reflectance window 1), HF+ADAPT's depth is shifted towards the start of
// the scan, whichever its direction (-0.4 um up, +0.4 um down on the wedge; windowed: ~0).
// AUTO (illumination_auto.h): the probe finds the cutter's glints and runs HF+ADAPT, finds none
// on the wedge and runs TEXTURE; each within 10 % of the better single mode's RMSE, at most STD's
// frames + 3, the decision in stack.json and the probe under raw/.
TEST_F(ScanModesTest, AutoChoosesCompensationForGlintsAndTextureOtherwise) {
  ASSERT_NE(bundle_, nullptr);
  struct Case {
    const char* specimen;
    IlluminationMode expected;
  };
  for (const Case c : {Case{"cutter", IlluminationMode::kHfAdapt}, Case{"wedge", IlluminationMode::kTexture}}) {
    auto std_run = Scan(c.specimen, IlluminationMode::kStd);
    auto texture = Scan(c.specimen, IlluminationMode::kTexture);
    auto hf_adapt = Scan(c.specimen, IlluminationMode::kHfAdapt);
    auto automatic = Scan(c.specimen, IlluminationMode::kAuto);
    ASSERT_TRUE(std_run.ok() && texture.ok() && hf_adapt.ok() && automatic.ok()) << c.specimen;
    EXPECT_EQ(automatic->ran, c.expected) << c.specimen;
    EXPECT_EQ(automatic->manifest.illumination, IlluminationModeName(c.expected));
    EXPECT_EQ(automatic->manifest.illumination_decision.rfind("AUTO -> " + IlluminationModeName(c.expected), 0), 0u)
        << automatic->manifest.illumination_decision;
    EXPECT_LE(automatic->images, std_run->images + 3) << c.specimen;
    const double best = std::min(texture->error.rmse_um, hf_adapt->error.rmse_um);
    std::printf(
        "%s: AUTO ran %s, RMSE %.3f um against the better of TEXTURE and HF+ADAPT %.3f um; %d frames (STD %d)\n",
        c.specimen, IlluminationModeName(automatic->ran).c_str(), automatic->error.rmse_um, best, automatic->images,
        std_run->images);
    EXPECT_LE(automatic->error.rmse_um, 1.1 * best) << c.specimen;
    EXPECT_GE(automatic->error.valid_percent, 99.0) << c.specimen;
    const int mid = int(automatic->manifest.frames.size()) / 2;
    EXPECT_TRUE(fs::exists(*dir_ / (std::string(c.specimen) + "_AUTO") / "raw" / RawFrameName(mid, "probe", 0)));
  }
}

TEST_F(ScanModesTest, PerPixelReflectanceForTheNextZShiftsDepthAgainstTheScanDirection) {
  ASSERT_NE(bundle_, nullptr);
  IlluminationParams per_pixel;
  per_pixel.compensation.reflectance_window_px = 1;
  auto up = Scan("wedge", IlluminationMode::kHfAdapt, per_pixel);
  auto down = Scan("wedge", IlluminationMode::kHfAdapt, per_pixel, 9, 0, nullptr, true);
  ASSERT_TRUE(up.ok()) << up.status().ToString();
  ASSERT_TRUE(down.ok()) << down.status().ToString();
  EXPECT_LT(up->error.mean_error_um, -0.25);
  EXPECT_GT(down->error.mean_error_um, 0.25);
}

TEST_F(ScanModesTest, AdaptiveModesMeasureSaturatingCutterWithFewFrames) {
  ASSERT_NE(bundle_, nullptr);
  auto std_run = Scan("cutter", IlluminationMode::kStd);
  IlluminationParams hdr;
  hdr.hdr_exposures = 3;
  auto hdr_run = Scan("cutter", IlluminationMode::kHdr, hdr);
  auto adapt = Scan("cutter", IlluminationMode::kAdapt);
  auto hf = Scan("cutter", IlluminationMode::kHfAdapt);
  ASSERT_TRUE(std_run.ok()) << std_run.status().ToString();
  ASSERT_TRUE(hdr_run.ok()) << hdr_run.status().ToString();
  ASSERT_TRUE(adapt.ok()) << adapt.status().ToString();
  ASSERT_TRUE(hf.ok()) << hf.status().ToString();
  EXPECT_EQ(hdr_run->images, 3 * std_run->images);
  EXPECT_LE(adapt->images, std_run->images + 3);
  EXPECT_EQ(hf->images, adapt->images);
  // HDR3 (log radiance) is a fair baseline: it beats STD, as in thesis Table 6.3.
  EXPECT_LT(hdr_run->error.stddev_error_um, 0.5 * std_run->error.stddev_error_um);
  // ADAPT and HF+ADAPT measure the polished land HDR3 leaves without depth, and are clearly
  // better than STD.
  EXPECT_GT(adapt->error.valid_percent, hdr_run->error.valid_percent + 10.0);
  EXPECT_GT(hf->error.valid_percent, hdr_run->error.valid_percent + 10.0);
  EXPECT_LT(adapt->error.rmse_um, 0.5 * std_run->error.rmse_um);
  // HF+ADAPT (the default when calibrated) is more accurate than HDR3 over its own pixels and over
  // the pixels both measured. (Plain ADAPT, whose corrections may no longer follow the glints'
  // focus, is not: 1.1 against 0.85 um, docs/illumination.md.)
  EXPECT_LT(hf->error.rmse_um, hdr_run->error.rmse_um);
  const double hf_common = ErrorOnCommonPixels(*hf, *hdr_run).stddev_error_um;
  const double hdr_common = ErrorOnCommonPixels(*hdr_run, *hf).stddev_error_um;
  std::printf("cutter on common pixels: HF+ADAPT %.3f um, HDR3 %.3f um\n", hf_common, hdr_common);
  EXPECT_LT(hf_common, hdr_common);
}

TEST_F(ScanModesTest, AdaptReachesTargetGreyWithinThreeFrames) {
  ASSERT_NE(bundle_, nullptr);
  auto std_run = Scan("cutter", IlluminationMode::kStd);
  auto adapt = Scan("cutter", IlluminationMode::kAdapt);
  ASSERT_TRUE(std_run.ok() && adapt.ok());
  ASSERT_GE(adapt->captures.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    std::printf("frame %d: STD mean %.1f sd %.1f sat %.2f %% | ADAPT mean %.1f sd %.1f sat %.2f %%\n", k,
                std_run->captures[k].mean_grey, std_run->captures[k].stddev_grey,
                std_run->captures[k].saturated_percent, adapt->captures[k].mean_grey, adapt->captures[k].stddev_grey,
                adapt->captures[k].saturated_percent);
  }
  EXPECT_GT(std_run->captures[0].saturated_percent, 5.0);
  const FrameStatistics& third = adapt->captures[2];
  EXPECT_NEAR(third.mean_grey, IlluminationParams{}.target_grey, 10.0);
  EXPECT_LT(third.saturated_percent, 1.0);
  EXPECT_LT(third.stddev_grey, 0.7 * std_run->captures[2].stddev_grey);
}

TEST_F(ScanModesTest, TextureMakesTexturelessLensMeasurable) {
  ASSERT_NE(bundle_, nullptr);
  // 2.5 um steps (21 frames), as Table 6.5.
  auto std_run = Scan("lens", IlluminationMode::kStd, {}, 9, 2.5);
  auto tex = Scan("lens", IlluminationMode::kTexture, {}, 9, 2.5);
  ASSERT_TRUE(std_run.ok()) << std_run.status().ToString();
  ASSERT_TRUE(tex.ok()) << tex.status().ToString();
  EXPECT_LT(std_run->error.valid_percent, 20.0);
  EXPECT_GT(tex->error.valid_percent, 95.0);
  EXPECT_LT(tex->error.stddev_error_um, 0.5);
  EXPECT_EQ(tex->error.outlier_percent, 0.0);
  EXPECT_EQ(tex->images, std_run->images);
  // The default 5 um steps (11 frames): the confidence's noise level rests on few second
  // differences, two of them the peak's own flanks; weighted down (core/sff/depth_interpolation.h
  // FocusConfidence) TEXTURE keeps the whole lens, counted plainly it kept ~93 %.
  auto tex_default = Scan("lens", IlluminationMode::kTexture);
  ASSERT_TRUE(tex_default.ok()) << tex_default.status().ToString();
  EXPECT_GT(tex_default->error.valid_percent, 97.0);
  EXPECT_LT(tex_default->error.stddev_error_um, 0.5);
  EXPECT_LT(tex_default->error.outlier_percent, 0.1);
}

TEST_F(ScanModesTest, HfAdaptHasFewerOutliersThanStdOnCoin) {
  ASSERT_NE(bundle_, nullptr);
  auto std_run = Scan("coin", IlluminationMode::kStd);
  auto hf = Scan("coin", IlluminationMode::kHfAdapt);
  ASSERT_TRUE(std_run.ok()) << std_run.status().ToString();
  ASSERT_TRUE(hf.ok()) << hf.status().ToString();
  const double std_bad = std_run->error.outlier_percent + (100.0 - std_run->error.valid_percent);
  const double hf_bad = hf->error.outlier_percent + (100.0 - hf->error.valid_percent);
  EXPECT_LT(hf_bad, std_bad);
  EXPECT_LT(hf->error.outlier_percent, std_run->error.outlier_percent);
  // Also by the thesis's reference-free measure (depth jumps against the neighbours).
  const double std_local = LocalOutlierPercent(std_run->depth_um, 10.0, 9);
  const double hf_local = LocalOutlierPercent(hf->depth_um, 10.0, 9);
  std::printf("coin local outliers: STD %.2f %%, HF+ADAPT %.2f %%\n", std_local, hf_local);
  EXPECT_LT(hf_local, 0.5 * std_local);
}

// A weld bead (inspect-evaluate's user scene): glints along the crest ~500:1 against its dark
// flanks (reflectance 0.01). The compensation asks for more light on the flanks than the
// projector has, and eq. 5.18's clamp would then shrink the added checkerboard to 255 / 191;
// the flanks keep the full 255 / 127 swing instead (core/illumination/texture_pattern.h). Here, with the
// clamp: 23 % of the flanks, 62 % of the bead, RMSE 0.75 um; without it: 43 %, 71 %, 0.44 um
// (both before the confidence weighted down the peak's flank terms; since: 44 %, 72 %, 0.46 um).
TEST_F(ScanModesTest, HfAdaptKeepsItsTextureWhereTheProjectorIsAtItsLimit) {
  ASSERT_NE(bundle_, nullptr);
  const cv::Size size = SmallRig().camera_size;
  const double px = SmallRig().pixel_size_um, h = size.height * px, bead_w = 0.3 * h;
  const std::string scene =
      test_scenes::WriteUserScene(*dir_ / "scenes", "weld_bead", size, px, test_scenes::WeldBeadScene(size, px));
  // With the default post-processing, as the product runs it.
  auto hf = Scan(scene, IlluminationMode::kHfAdapt, {}, 9, 0, nullptr, false, true);
  auto std_run = Scan(scene, IlluminationMode::kStd, {}, 9, 0, nullptr, false, true);
  ASSERT_TRUE(hf.ok()) << hf.status().ToString();
  ASSERT_TRUE(std_run.ok()) << std_run.status().ToString();
  // The dark flanks: 0.35 < |u| < 0.95, away from the crest's glints and the bead's rim.
  auto flank_valid = [&](const cv::Mat& depth) {
    int n = 0, valid = 0;
    for (int r = 0; r < depth.rows; ++r) {
      const double u = std::abs(((r + 0.5) * px - 0.5 * h) / bead_w);
      if (u < 0.35 || u > 0.95) continue;
      for (int c = 0; c < depth.cols; ++c, ++n) valid += std::isfinite(depth.at<float>(r, c)) ? 1 : 0;
    }
    return 100.0 * valid / std::max(n, 1);
  };
  const double hf_flanks = flank_valid(hf->depth_um), std_flanks = flank_valid(std_run->depth_um);
  const DepthErrorStats hf_common = ErrorOnCommonPixels(*hf, *std_run);
  std::printf("weld bead flanks measured: HF+ADAPT %.1f %%, STD %.1f %%; whole bead HF+ADAPT %.1f %% RMSE %.3f um\n",
              hf_flanks, std_flanks, hf->error.valid_percent, hf->error.rmse_um);
  EXPECT_GT(hf_flanks, 38.0);
  EXPECT_GT(hf->error.valid_percent, 68.0);
  EXPECT_LT(hf->error.rmse_um, 0.6);
  EXPECT_LT(hf_common.rmse_um, 0.6);
  EXPECT_LE(hf->images, std_run->images + 3);
}

TEST_F(ScanModesTest, DefaultPostProcessingKeepsTexturedSpecimensAndRemovesWrongDepths) {
  ASSERT_NE(bundle_, nullptr);
  // Textured specimens measured through focus: the consistency check keeps (nearly) every pixel
  // and the error does not grow beyond scan-to-scan noise. (The window-mixing check takes up to
  // ~1 % of the chamfer's flank, where the error was largest: STD sigma 0.60 -> 0.50 um.)
  for (const char* specimen : {"wedge", "chamfer"}) {
    for (const IlluminationMode mode : {IlluminationMode::kStd, IlluminationMode::kHfAdapt}) {
      auto off = Scan(specimen, mode, {}, 9, 0, nullptr, false, false);
      auto on = Scan(specimen, mode, {}, 9, 0, nullptr, false, true);
      ASSERT_TRUE(off.ok() && on.ok());
      EXPECT_GT(on->error.valid_percent, off->error.valid_percent - 1.5) << specimen;
      EXPECT_LT(on->error.stddev_error_um, 1.1 * off->error.stddev_error_um) << specimen;
      // (Two scans differ by the stage's +-0.1 um repeatability, so the bias is held to its bound.)
      EXPECT_LE(std::abs(on->error.mean_error_um), 0.1) << specimen;
    }
  }
  // The saturating cutter under STD: the pixels it takes away were the wrong ones.
  auto off = Scan("cutter", IlluminationMode::kStd, {}, 9, 0, nullptr, false, false);
  auto on = Scan("cutter", IlluminationMode::kStd, {}, 9, 0, nullptr, false, true);
  ASSERT_TRUE(off.ok() && on.ok());
  EXPECT_LT(on->error.valid_percent, off->error.valid_percent - 5.0);
  EXPECT_LT(on->error.rmse_um, 0.6 * off->error.rmse_um);
  // The coin under the default's HF+ADAPT: beside the relief's dark 80 degree flanks the focus
  // window is dominated by the bright field's edge, and the pixels got the field's height (a
  // smooth ramp the plane check passes; bias about -0.6 um). The window-mixing check
  // (core/sff/depth_consistency.h) takes them off.
  auto coin_off = Scan("coin", IlluminationMode::kHfAdapt, {}, 9, 0, nullptr, false, false);
  auto coin_on = Scan("coin", IlluminationMode::kHfAdapt, {}, 9, 0, nullptr, false, true);
  ASSERT_TRUE(coin_off.ok() && coin_on.ok());
  std::printf("coin HF+ADAPT: without bias %+.3f RMSE %.3f valid %.1f %%; with bias %+.3f RMSE %.3f valid %.1f %%\n",
              coin_off->error.mean_error_um, coin_off->error.rmse_um, coin_off->error.valid_percent,
              coin_on->error.mean_error_um, coin_on->error.rmse_um, coin_on->error.valid_percent);
  EXPECT_GT(std::abs(coin_off->error.mean_error_um), 0.3);
  EXPECT_LE(std::abs(coin_on->error.mean_error_um), 0.1);
  EXPECT_LT(coin_on->error.rmse_um, 0.5 * coin_off->error.rmse_um);
  EXPECT_GT(coin_on->error.valid_percent, 80.0);
}

// The coin under the default (AUTO runs HF+ADAPT) against TEXTURE, with the default
// post-processing, on the pixels both measure. The compensation changes the light from frame to
// frame (the polished field's window mean swings between ~110 and ~175 grey through focus), and
// Tenengrad grows with the light squared, so the field's depth moves (-1 um in its corners).
// The illumination-invariant focus measure (SffOptions::illumination_invariant) removes most of
// it: 1.36x TEXTURE's RMSE where both measure -> 1.00x with this test's coarser calibration
// (inspect-evaluate, seed 5: 1.34 -> 1.00). It stays off by default because on
// glinting parts the window mean is not the light (cutter bias -0.12 um, docs/illumination.md).
TEST_F(ScanModesTest, IlluminationInvariantFocusBringsHfAdaptToTextureOnTheCoin) {
  ASSERT_NE(bundle_, nullptr);
  auto texture = Scan("coin", IlluminationMode::kTexture, {}, 9, 0, nullptr, false, true);
  auto plain = Scan("coin", IlluminationMode::kHfAdapt, {}, 9, 0, nullptr, false, true);
  auto invariant = Scan("coin", IlluminationMode::kHfAdapt, {}, 9, 0, nullptr, false, true, true);
  ASSERT_TRUE(texture.ok() && plain.ok() && invariant.ok());
  const double plain_common = ErrorOnCommonPixels(*plain, *texture).rmse_um;
  const double texture_vs_plain = ErrorOnCommonPixels(*texture, *plain).rmse_um;
  const double invariant_common = ErrorOnCommonPixels(*invariant, *texture).rmse_um;
  const double texture_vs_invariant = ErrorOnCommonPixels(*texture, *invariant).rmse_um;
  std::printf("coin, common pixels with TEXTURE: HF+ADAPT %.3f against %.3f um (ratio %.2f); illumination-invariant "
              "%.3f against %.3f um (ratio %.2f)\n",
              plain_common, texture_vs_plain, plain_common / texture_vs_plain, invariant_common, texture_vs_invariant,
              invariant_common / texture_vs_invariant);
  EXPECT_LT(invariant_common, 0.85 * plain_common);
  EXPECT_LE(invariant_common, 1.15 * texture_vs_invariant);
  EXPECT_GT(invariant->error.valid_percent, texture->error.valid_percent);
  EXPECT_LE(std::abs(invariant->error.mean_error_um), BiasBoundUm(invariant->z_step_um));
}

TEST_F(ScanModesTest, IterativeAdaptCompensatesPerZ) {
  ASSERT_NE(bundle_, nullptr);
  auto std_run = Scan("cutter", IlluminationMode::kStd);
  IlluminationParams p;
  p.max_iterations = 3;
  std::vector<ScanFrameEvent> events;
  auto it = Scan("cutter", IlluminationMode::kAdaptIterative, p, 9, 0, &events);
  ASSERT_TRUE(std_run.ok() && it.ok());
  // Every capture is reported once, in order; per z exactly one (the last) is the stack frame.
  ASSERT_EQ(int(events.size()), it->images);
  int kept = 0;
  for (size_t k = 0; k < events.size(); ++k) {
    EXPECT_EQ(events[k].acquisition, int(k));
    const bool last_of_z = k + 1 == events.size() || events[k + 1].index != events[k].index;
    EXPECT_EQ(events[k].stack_frame, last_of_z) << "capture " << k << " at z index " << events[k].index;
    kept += events[k].stack_frame;
  }
  EXPECT_EQ(kept, std_run->images);
  // At least one frame per z, at most max_iterations; the iteration must have run somewhere.
  EXPECT_GT(it->images, std_run->images);
  EXPECT_LE(it->images, 3 * std_run->images);
  EXPECT_LT(it->error.stddev_error_um, std_run->error.stddev_error_um);
  EXPECT_GT(it->error.valid_percent, std_run->error.valid_percent);
}

TEST_F(ScanModesTest, AdaptedHfHasFewerOutliersThanStdOnCoin) {
  ASSERT_NE(bundle_, nullptr);
  auto std_run = Scan("coin", IlluminationMode::kStd);
  auto ahf = Scan("coin", IlluminationMode::kAdaptedHf);
  ASSERT_TRUE(std_run.ok()) << std_run.status().ToString();
  ASSERT_TRUE(ahf.ok()) << ahf.status().ToString();
  EXPECT_LT(ahf->error.outlier_percent, std_run->error.outlier_percent);
  EXPECT_LE(ahf->images, std_run->images + 3);
}

TEST_F(ScanModesTest, MissingCalibrationIsNamed) {
  CalibrationBundle partial;
  partial.camera_response = bundle_->camera_response;
  Status s = CheckCalibrationFor(IlluminationMode::kAdapt, &partial);
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(s.message().find("projector_response"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("scatter_matrix"), std::string::npos);
  EXPECT_EQ(s.message().find("camera_response"), std::string::npos);
  EXPECT_TRUE(CheckCalibrationFor(IlluminationMode::kHdr, &partial).ok());
  Status t = CheckCalibrationFor(IlluminationMode::kTexture, nullptr);
  EXPECT_EQ(t.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(t.message().find("psf"), std::string::npos);
  EXPECT_TRUE(CheckCalibrationFor(IlluminationMode::kStd, nullptr).ok());
  EXPECT_EQ(HdrRelativeExposures(3).value(), (std::vector<double>{0.5, 1.0, 2.0}));
  EXPECT_FALSE(HdrRelativeExposures(6).ok());
}

}  // namespace
}  // namespace inspection
