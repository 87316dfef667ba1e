// The measurement uncertainties (core/metrology/measurement.h) against repeated simulated scans: the small
// version of tests/bench/uncertainty_coverage.cc (160x120 camera, 3 seeds, four specimens).
// The k = 2 interval must hold the deviation from the ground-truth measurement for >= 90 % of
// all (specimen, measurement, seed) triples and for at least 2 of 3 seeds of each pair, while
// staying informative; and without the z-linearity term the step height is not covered, which
// is why the model has it (core/shape_parameter_uncertainty_test.cc shows the same for the
// height-dependent term of Ssk).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include "core/metrology/measurement.h"
#include "core/metrology/z_linearity.h"
#include "devices/sim/simulated_rig.h"
#include "server/procedures/scan_procedure.h"
#include "tests/lib/user_scene.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

struct ScanData {
  cv::Mat depth_um, truth_um;
  std::vector<double> z_um;
  int window_px = 7;
};

class UncertaintyCoverageTest : public ::testing::Test {
 protected:
  static constexpr int kSeeds = 3;
  const cv::Size camera_{160, 120};

  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("uncertainty_coverage_test_" + std::to_string(::getpid()));
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  // z_step_um 0 = the rig's default step (the characterisation's).
  StatusOr<ScanData> Scan(const std::string& specimen, uint64_t seed, double z_step_um = 0.0) {
    SimulatedRigOptions o;
    o.camera_size = camera_;
    o.seed = seed;
    o.specimen = specimen;
    INSPECT_ASSIGN_OR_RETURN(std::unique_ptr<Rig> rig, CreateSimulatedRig(o));
    const ScanDefaults d = rig->scan_defaults();
    INSPECT_ASSIGN_OR_RETURN(ScanPlan plan,
                             MakeScanPlan(d.z_start_um, d.z_end_um, z_step_um > 0.0 ? z_step_um : d.z_step_um,
                                          d.exposure_us, rig->stage()));
    std::atomic<bool> cancel{false};
    INSPECT_ASSIGN_OR_RETURN(ScanOutcome out,
                             RunScan(*rig, plan, dir_ / (specimen + std::to_string(seed)), nullptr, cancel));
    return ScanData{out.depth.depth_um, out.ground_truth_um, plan.z_um, plan.sff.window_px};
  }

  MeasurementSpec Spec(MeasurementKind kind, RegionOfInterest roi) {
    MeasurementSpec s;
    s.kind = kind;
    s.roi = roi;
    return s;
  }

  fs::path dir_;
};

TEST_F(UncertaintyCoverageTest, ExpandedUncertaintyCoversTheDeviationsFromTruth) {
  // The rig's z linearity, characterised on SKEW10 with a seed no test scan uses.
  auto cal = Scan("skew10", 100000);
  ASSERT_TRUE(cal.ok()) << cal.status().ToString();
  const int b = cal->window_px + 1, w = camera_.width, h = camera_.height;
  const RegionOfInterest inner = RegionOfInterest::Rectangle(b, b, w - 2 * b, h - 2 * b);
  auto inner_mask = RasteriseRegion(inner, camera_, 0.74);
  ASSERT_TRUE(inner_mask.ok());
  auto linearity = CharacteriseZLinearity(cal->depth_um, *inner_mask, 0.74, *ZGrid::Create(cal->z_um));
  ASSERT_TRUE(linearity.ok()) << linearity.status().ToString();

  struct Case {
    std::string specimen;
    std::vector<std::pair<std::string, MeasurementSpec>> specs;
  };
  std::vector<Case> cases(4);
  cases[0].specimen = "plane";
  for (MeasurementKind k : {MeasurementKind::kSa, MeasurementKind::kSq, MeasurementKind::kSz, MeasurementKind::kTilt,
                            MeasurementKind::kFlatness}) {
    cases[0].specs.push_back({MeasurementKindName(k), Spec(k, inner)});
  }
  cases[1].specimen = "skew5";
  for (MeasurementKind k : {MeasurementKind::kTilt, MeasurementKind::kSq}) {
    cases[1].specs.push_back({MeasurementKindName(k), Spec(k, inner)});
  }
  cases[2].specimen = "step1um";
  MeasurementSpec step =
      Spec(MeasurementKind::kStepHeight, RegionOfInterest::Rectangle(w / 2 + 12, b, w / 2 - 12 - b, h - 2 * b));
  step.reference_roi = RegionOfInterest::Rectangle(b, b, w / 2 - 12 - b, h - 2 * b);
  cases[2].specs.push_back({"step_height", step});
  // A 2 um cosine, 4 periods across the field; the region holds 3 whole periods. Its shape
  // parameters are where the SFF's height-dependent error shows (Ssk +0.05 against 0).
  const double period_px = w / 4.0;
  cases[3].specimen = test_scenes::WriteUserScene(
      dir_ / "scenes", "cosine", camera_, 0.74,
      [&](double x, double) { return 210.0 + 2.0 * std::cos(2 * M_PI * x / (period_px * 0.74)); }, 101);
  for (MeasurementKind k : {MeasurementKind::kSq, MeasurementKind::kSsk, MeasurementKind::kSku}) {
    cases[3].specs.push_back(
        {MeasurementKindName(k), Spec(k, RegionOfInterest::Rectangle(period_px / 2, b, 3 * period_px, h - 2 * b))});
  }

  int covered = 0, total = 0, step_covered_without_linearity = 0, step_count = 0;
  int ssk_covered_without_height_term = 0, ssk_count = 0;
  double worst_step_dev_um = 0.0;
  std::map<std::string, int> pair_covered;
  for (uint64_t seed = 1; seed <= kSeeds; ++seed) {
    for (const Case& c : cases) {
      auto scan = Scan(c.specimen, seed);
      ASSERT_TRUE(scan.ok()) << scan.status().ToString();
      std::vector<MeasurementSpec> specs;
      for (const auto& s : c.specs) specs.push_back(s.second);
      MeasurementContext ctx;
      ctx.depth_um = scan->depth_um;
      ctx.pixel_size_um = 0.74;
      ctx.noise.window_px = scan->window_px;
      ctx.noise.z_positions_um = scan->z_um;
      ctx.noise.linearity = *linearity;
      ctx.noise.stage_repeatability_um = SimulatedRigOptions{}.stage_repeatability_um;
      MeasurementContext truth_ctx = ctx;
      truth_ctx.depth_um = scan->truth_um;
      truth_ctx.with_uncertainty = false;
      const auto measured = MeasureAll(specs, ctx);
      const auto truth = MeasureAll(specs, truth_ctx);
      for (size_t i = 0; i < specs.size(); ++i) {
        ASSERT_TRUE(measured[i].ok()) << c.specimen << " " << c.specs[i].first << ": "
                                      << measured[i].status().ToString();
        ASSERT_TRUE(truth[i].ok()) << truth[i].status().ToString();
        const double dev = measured[i]->value - truth[i]->value;
        const double big_u = 2.0 * measured[i]->uncertainty.standard_uncertainty;
        const bool ok = std::abs(dev) <= big_u;
        std::printf("%-8s %-12s seed %d: value %9.4f truth %9.4f dev %+8.4f U %8.4f %s\n", c.specimen.c_str(),
                    c.specs[i].first.c_str(), int(seed), measured[i]->value, truth[i]->value, dev, big_u,
                    ok ? "covered" : "NOT covered");
        covered += ok;
        ++total;
        pair_covered[c.specimen + " " + c.specs[i].first] += ok;
        // Informative, not just large: bounds far above what these measurements need.
        if (measured[i]->kind == MeasurementKind::kStepHeight) {
          EXPECT_LT(big_u, 0.5) << "step height U";
          // The same with the z-linearity term left out.
          MeasurementContext no_lin = ctx;
          no_lin.noise.linearity.bias_of_step = {0.0, 0.0};
          no_lin.noise.linearity.characterised_step_um = 0.0;
          auto bare = Measure(specs[i], no_lin);
          ASSERT_TRUE(bare.ok());
          step_covered_without_linearity += std::abs(dev) <= 2.0 * bare->uncertainty.standard_uncertainty;
          worst_step_dev_um = std::max(worst_step_dev_um, std::abs(dev));
          ++step_count;
        }
        if (measured[i]->kind == MeasurementKind::kSsk) {
          const UncertaintyBudget& u = measured[i]->uncertainty;
          ASSERT_TRUE(std::isfinite(u.height_dependent));
          const double without = std::sqrt(
              std::max(0.0, u.standard_uncertainty * u.standard_uncertainty - u.height_dependent * u.height_dependent));
          ssk_covered_without_height_term += std::abs(dev) <= 2.0 * without;
          ++ssk_count;
          // The flattening grows as 1 / period^2: 0.1 um at this 40 px period, U ~0.29.
          EXPECT_LT(big_u, 0.4) << "Ssk U";
        }
        if (measured[i]->kind == MeasurementKind::kTilt) {
          EXPECT_LT(big_u, 0.2) << "tilt U (deg)";
        }
      }
    }
  }
  std::printf("covered %d / %d\n", covered, total);
  EXPECT_GE(covered, int(std::ceil(0.9 * total)));
  for (const auto& [pair, n] : pair_covered) EXPECT_GE(n, 2) << pair;
  // Peak locking: with the thesis's three-point Gaussian the 1 um step came out ~0.2 um short on
  // every seed, which random noise alone (u ~ 0.01 um) did not cover. The default defocus
  // parabola (core/sff/depth_interpolation.h) removes most of it (measured 0.005-0.086 um); the
  // z-linearity term still carries what is left.
  std::printf("step height: worst |deviation| %.4f um; covered without the z-linearity term %d / %d\n",
              worst_step_dev_um, step_covered_without_linearity, step_count);
  EXPECT_GT(step_count, 0);
  std::printf("cosine Ssk: covered without the height-dependent term %d / %d\n", ssk_covered_without_height_term,
              ssk_count);
  EXPECT_EQ(ssk_count, kSeeds);  // (on the 256x192 bench the Monte Carlo alone covered 3 / 20)
  EXPECT_LT(worst_step_dev_um, 0.12);
}

TEST_F(UncertaintyCoverageTest, StepHeightAtAFinerStepThanCharacterisedIsSharpAndCovered) {
  // Characterised at the rig's 5 um step, scanned at 2 um: the table applies in um. With the
  // +-step/2 sawtooth bound instead, U was 1.8 um on a 1 um step measured within 0.05 um.
  auto cal = Scan("skew10", 100000);
  ASSERT_TRUE(cal.ok()) << cal.status().ToString();
  const int b = cal->window_px + 1, w = camera_.width, h = camera_.height;
  auto inner_mask = RasteriseRegion(RegionOfInterest::Rectangle(b, b, w - 2 * b, h - 2 * b), camera_, 0.74);
  ASSERT_TRUE(inner_mask.ok());
  auto linearity = CharacteriseZLinearity(cal->depth_um, *inner_mask, 0.74, *ZGrid::Create(cal->z_um));
  ASSERT_TRUE(linearity.ok()) << linearity.status().ToString();
  ASSERT_NEAR(linearity->characterised_step_um, 5.0, 1e-9);
  MeasurementSpec step =
      Spec(MeasurementKind::kStepHeight, RegionOfInterest::Rectangle(w / 2 + 12, b, w / 2 - 12 - b, h - 2 * b));
  step.reference_roi = RegionOfInterest::Rectangle(b, b, w / 2 - 12 - b, h - 2 * b);
  int covered = 0;
  for (uint64_t seed = 11; seed <= 13; ++seed) {
    auto scan = Scan("step1um", seed, 2.0);
    ASSERT_TRUE(scan.ok()) << scan.status().ToString();
    MeasurementContext ctx;
    ctx.depth_um = scan->depth_um;
    ctx.pixel_size_um = 0.74;
    ctx.noise.window_px = scan->window_px;
    ctx.noise.z_positions_um = scan->z_um;
    ctx.noise.linearity = *linearity;
    ctx.noise.stage_repeatability_um = SimulatedRigOptions{}.stage_repeatability_um;
    MeasurementContext truth_ctx = ctx;
    truth_ctx.depth_um = scan->truth_um;
    truth_ctx.with_uncertainty = false;
    const auto measured = MeasureAll({step}, ctx);
    const auto truth = MeasureAll({step}, truth_ctx);
    ASSERT_TRUE(measured[0].ok()) << measured[0].status().ToString();
    ASSERT_TRUE(truth[0].ok()) << truth[0].status().ToString();
    const double dev = measured[0]->value - truth[0]->value;
    const double big_u = 2.0 * measured[0]->uncertainty.standard_uncertainty;
    std::printf("step at 2 um z steps, seed %d: dev %+.4f um, U %.4f um, |dev|/U %.2f\n", int(seed), dev, big_u,
                std::abs(dev) / big_u);
    covered += std::abs(dev) <= big_u;
    EXPECT_LT(big_u, 0.3) << "seed " << seed;  // 1.8 um with the sawtooth bound
  }
  EXPECT_EQ(covered, 3);
}

}  // namespace
}  // namespace inspection
