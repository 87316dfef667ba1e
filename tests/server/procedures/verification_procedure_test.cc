// Verification on the simulated rig (server/procedures/verification_procedure.h) against the
// simulator's truth: with instrument errors injected into the optics (devices/sim/simulated_rig.h:
// z scale, lateral scale x/y, extra depth noise, field curvature) each ISO 25178-600
// characteristic is recovered within its own expanded uncertainty U = 2u of the injected value;
// without them alpha_z, alpha_x, alpha_y ~ 1 within U. Small images (256x192) and 2 um steps keep
// a full verification (15 scans) to a few seconds.
#include "server/procedures/verification_procedure.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgproc.hpp>

#include "devices/sim/simulated_rig.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

SimulatedRigOptions SmallRig() {
  SimulatedRigOptions o;
  o.specimen = "plane";
  o.camera_size = {256, 192};
  o.projector_size = {96, 72};
  o.seed = 7;
  return o;
}

fs::path WorkDir(const std::string& name) {
  return fs::temp_directory_path() / ("verification_test_" + name + "_" + std::to_string(getpid()));
}

StatusOr<VerificationRecord> Verify(const SimulatedRigOptions& o, VerificationMode mode, const std::string& name) {
  auto rig = CreateSimulatedRig(o);
  if (!rig.ok()) return rig.status();
  VerificationPlan plan;
  plan.mode = mode;
  plan.sff.threads = 2;
  std::atomic<bool> cancel{false};
  return RunVerification(**rig, plan, WorkDir(name), nullptr,
                         [](const VerificationProgress& p) { std::printf("  %s: %s\n", p.specimen.c_str(), p.message.c_str()); },
                         cancel);
}

void Print(const char* label, const VerificationRecord& r) {
  std::printf("%s: N_M %.4f +- %.4f, z_FLT %.4f +- %.4f, alpha_z %.5f +- %.5f, l_z %.4f +- %.4f, "
              "alpha_x %.5f +- %.5f, alpha_y %.5f +- %.5f, W_R %.3f +- %.3f (U = 2u)\n",
              label, r.noise_um.value, 2 * r.noise_um.standard_uncertainty, r.flatness_um.value,
              2 * r.flatness_um.standard_uncertainty, r.alpha_z.value, 2 * r.alpha_z.standard_uncertainty,
              r.l_z_um.value, 2 * r.l_z_um.standard_uncertainty, r.alpha_x.value, 2 * r.alpha_x.standard_uncertainty,
              r.alpha_y.value, 2 * r.alpha_y.standard_uncertainty, r.w_r_um.value, 2 * r.w_r_um.standard_uncertainty);
  for (const VerificationStep& s : r.steps) {
    std::printf("  %s: %.4f +- %.4f um\n", s.specimen.c_str(), s.point.measured_um, 2 * s.point.measured_u_um);
  }
  for (const VerificationSinusoid& s : r.sinusoids) {
    std::printf("  %s: amplitude %.4f +- %.4f um\n", s.specimen.c_str(), s.point.measured_amplitude_um,
                2 * s.point.measured_amplitude_u_um);
  }
}

TEST(VerificationProcedure, PerfectInstrumentHasUnitAmplification) {
  auto r = Verify(SmallRig(), VerificationMode::kFull, "clean");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  Print("no injection", *r);
  EXPECT_EQ(r->scans, 2 + 4 + 1 + 8);
  EXPECT_NEAR(r->alpha_z.value, 1.0, 2 * r->alpha_z.standard_uncertainty);
  EXPECT_NEAR(r->alpha_x.value, 1.0, 2 * r->alpha_x.standard_uncertainty);
  EXPECT_NEAR(r->alpha_y.value, 1.0, 2 * r->alpha_y.standard_uncertainty);
}

// z_FLT a flat shows under a bow alone, evaluated as FlatnessDeviation evaluates (block means of
// 4 x 4 focus windows): the truth of the injected flatness error.
double BowFlatnessTruth(const SimulatedRigOptions& o, int window_px) {
  SimulatedRigOptions bow_only = SmallRig();
  bow_only.flatness_bow_um = o.flatness_bow_um;
  bow_only.specimen = "afl";
  bow_only.stage_repeatability_um = 0.0;
  auto rig = CreateSimulatedRig(bow_only);
  EXPECT_TRUE(rig.ok());
  // The renderer's surface is the seen one; rebuild it from the bow formula instead.
  const cv::Size size = o.camera_size;
  cv::Mat m(size, CV_32FC1);
  const double cx = (size.width - 1) / 2.0, cy = (size.height - 1) / 2.0;
  for (int r = 0; r < size.height; ++r) {
    for (int c = 0; c < size.width; ++c) {
      m.at<float>(r, c) = float(o.flatness_bow_um * ((c - cx) * (c - cx) + (r - cy) * (r - cy)) / (cx * cx + cy * cy));
    }
  }
  auto f = FlatnessDeviation(m, m, window_px);
  EXPECT_TRUE(f.ok());
  return f.ok() ? f->value : 0.0;
}

TEST(VerificationProcedure, RecoversInjectedErrorsWithinU) {
  const SimulatedRigOptions clean_options = SmallRig();
  auto clean = Verify(clean_options, VerificationMode::kFull, "clean2");
  ASSERT_TRUE(clean.ok()) << clean.status().ToString();
  SimulatedRigOptions o = SmallRig();
  o.z_scale_error = 0.005;
  o.lateral_scale_error_x = 0.01;
  o.lateral_scale_error_y = -0.005;
  o.extra_noise_um = 0.15;
  o.flatness_bow_um = 0.5;
  auto r = Verify(o, VerificationMode::kFull, "injected");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  Print("injected", *r);
  const double bow_truth = BowFlatnessTruth(o, 7);
  std::printf("truth: alpha_z %.5f, alpha_x %.5f, alpha_y %.5f, z_FLT(bow) %.4f, extra noise %.4f\n", 1.005, 1.01,
              0.995, bow_truth, o.extra_noise_um);
  EXPECT_NEAR(r->alpha_z.value, 1.005, 2 * r->alpha_z.standard_uncertainty);
  EXPECT_NEAR(r->alpha_x.value, 1.01, 2 * r->alpha_x.standard_uncertainty);
  EXPECT_NEAR(r->alpha_y.value, 0.995, 2 * r->alpha_y.standard_uncertainty);
  EXPECT_NEAR(r->flatness_um.value, bow_truth, 2 * r->flatness_um.standard_uncertainty);
  // The extra noise adds in quadrature to the rig's own.
  const double extra = std::sqrt(std::max(0.0, r->noise_um.value * r->noise_um.value -
                                                   clean->noise_um.value * clean->noise_um.value));
  const double u_extra = std::hypot(r->noise_um.value * r->noise_um.standard_uncertainty,
                                    clean->noise_um.value * clean->noise_um.standard_uncertainty) / extra;
  std::printf("extra noise recovered %.4f +- %.4f\n", extra, 2 * u_extra);
  EXPECT_NEAR(extra, o.extra_noise_um, 2 * u_extra);
}

TEST(VerificationProcedure, InterimScansTheFlatAndOneStep) {
  SimulatedRigOptions o = SmallRig();
  o.z_scale_error = 0.005;
  auto r = Verify(o, VerificationMode::kInterim, "interim");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->scans, 3);
  ASSERT_EQ(r->steps.size(), 1u);
  EXPECT_EQ(r->steps[0].specimen, "pgr10");
  // One step carries the response line's offset too: within U plus the clean rig's offset
  // (a few 10 nm, see the full verification's steps).
  EXPECT_NEAR(r->alpha_z.value, 1.005, 2 * r->alpha_z.standard_uncertainty + 0.005);
  EXPECT_GT(r->noise_um.value, 0.0);
}

TEST(VerificationProcedure, RigWithoutMaterialMeasuresIsAFailedPrecondition) {
  SimulatedRigOptions o = SmallRig();
  o.material_measures = false;
  auto r = Verify(o, VerificationMode::kFull, "none");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(r.status().message().find("material_measures"), std::string::npos) << r.status().ToString();
}

TEST(VerificationProcedure, CancelledVerificationPutsTheSpecimenBack) {
  auto rig = CreateSimulatedRig(SmallRig());
  ASSERT_TRUE(rig.ok());
  VerificationPlan plan;
  std::atomic<bool> cancel{false};
  int frames = 0;
  const fs::path dir = WorkDir("cancel");
  auto r = RunVerification(
      **rig, plan, dir,
      [&](const ScanFrameEvent&, const VerificationProgress& p) {
        if (p.index == 2 && ++frames == 3) cancel = true;  // inside the first step's scan
      },
      nullptr, cancel);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kCancelled);
  EXPECT_EQ((*rig)->simulation()->specimen(), "plane");
  EXPECT_FALSE(fs::exists(dir));
}

TEST(VerificationProcedure, InterimCheckAgainstTheLastFullVerification) {
  auto full = Verify(SmallRig(), VerificationMode::kFull, "full");
  ASSERT_TRUE(full.ok()) << full.status().ToString();
  SimulatedRigOptions same = SmallRig();
  same.seed = 8;  // other noise, other repeatability draws: the same instrument
  auto ok = Verify(same, VerificationMode::kInterim, "interim_ok");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  InterimCheckResult c = EvaluateInterimCheck(&*full, *ok, 1.0, 30.0);
  EXPECT_EQ(c.state, VerificationState::kVerified) << (c.findings.empty() ? "" : c.findings[0]);
  EXPECT_EQ(EvaluateInterimCheck(&*full, *ok, 31.0, 30.0).state, VerificationState::kDue);
  EXPECT_EQ(EvaluateInterimCheck(nullptr, *ok, 0.0, 30.0).state, VerificationState::kDue);

  SimulatedRigOptions scaled = same;
  // The 10 um step reads 300 nm more; the limit is 2 sqrt(2) u of one step (u ~ 0.06 um with
  // the stage's repeatability), so a 0.5 % change (50 nm) is within what one step can tell.
  scaled.z_scale_error = 0.03;
  auto bad_z = Verify(scaled, VerificationMode::kInterim, "interim_z");
  ASSERT_TRUE(bad_z.ok());
  c = EvaluateInterimCheck(&*full, *bad_z, 1.0, 30.0);
  EXPECT_EQ(c.state, VerificationState::kFailed);
  ASSERT_EQ(c.findings.size(), 1u);
  EXPECT_NE(c.findings[0].find("pgr10"), std::string::npos) << c.findings[0];

  SimulatedRigOptions noisy = same;
  noisy.extra_noise_um = 0.1;
  auto bad_noise = Verify(noisy, VerificationMode::kInterim, "interim_noise");
  ASSERT_TRUE(bad_noise.ok());
  c = EvaluateInterimCheck(&*full, *bad_noise, 1.0, 30.0);
  EXPECT_EQ(c.state, VerificationState::kFailed);
  ASSERT_FALSE(c.findings.empty());
  EXPECT_NE(c.findings[0].find("N_M"), std::string::npos) << c.findings[0];
}

}  // namespace
}  // namespace inspection
