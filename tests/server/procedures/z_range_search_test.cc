// Automatic z range on the simulated rig (server/procedures/z_range_search.h): built-in
// specimens placed at random heights (drawn from the seed) inside the search window; the chosen
// range must hold the true heights of >= 99 % of the pixels with at most 3 fine steps to spare on
// either side of the truth's P0.5 .. P99.5 range (parts flatter than the engine's shortest stack,
// kMinFineFrames, get that stack centred on them). The coarse frames are stored, recorded and
// reported before the scan's own. Figures for every specimen and several seeds:
// autorange-evaluate (tests/bench/autorange_evaluate.cc).
#include "server/procedures/z_range_search.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <random>

#include "devices/sim/simulated_rig.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

constexpr double kFineStepUm = 5.0;
constexpr double kWindowLowUm = 100.0, kWindowHighUm = 600.0;

double Percentile(std::vector<float> v, double p) {
  const size_t k = std::min(v.size() - 1, size_t(std::floor(p / 100.0 * double(v.size() - 1) + 0.5)));
  std::nth_element(v.begin(), v.begin() + long(k), v.end());
  return v[k];
}

struct Placed {
  std::unique_ptr<Rig> rig;
  std::vector<float> heights;
};

// A 512x384 simulated rig with the specimen moved by offset_um.
std::unique_ptr<Rig> RigWithSpecimenAt(const std::string& specimen, uint64_t seed, double offset_um) {
  SimulatedRigOptions o;
  o.specimen = specimen;
  o.seed = seed;
  o.camera_size = {512, 384};
  auto rig = CreateSimulatedRig(o);
  EXPECT_TRUE(rig.ok()) << rig.status().ToString();
  if (!rig.ok()) return nullptr;
  EXPECT_TRUE((*rig)->simulation()->SetSpecimenZOffsetUm(offset_um).ok());
  return std::move(*rig);
}

// The specimen at a random height with its whole range 10 um inside the window.
Placed PlaceAtRandomHeight(const std::string& specimen, uint64_t seed) {
  Placed p{RigWithSpecimenAt(specimen, seed, 0.0), {}};
  if (!p.rig) return p;
  SimulationControl* sim = p.rig->simulation();
  const auto [lo, hi] = sim->SpecimenZRangeUm();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> offset(kWindowLowUm + 10.0 - lo, kWindowHighUm - 10.0 - hi);
  EXPECT_TRUE(sim->SetSpecimenZOffsetUm(offset(rng)).ok());
  const cv::Mat truth = sim->GroundTruthDepthUm();
  p.heights.assign(truth.begin<float>(), truth.end<float>());
  return p;
}

ScanPlan SearchPlan(Rig& rig) {
  ScanPlan plan;
  plan.exposure_us = rig.scan_defaults().exposure_us;
  plan.z_step_um = kFineStepUm;
  auto s = ResolveZRangeSearch({kWindowLowUm, kWindowHighUm, 0.0, 0.0}, kFineStepUm, rig.scan_defaults(), rig.stage());
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  plan.z_range_search = *s;
  return plan;
}

class ZRangeSearchTest : public ::testing::TestWithParam<std::pair<const char*, uint64_t>> {
 protected:
  void SetUp() override { dir_ = fs::temp_directory_path() / ("zrange-" + std::to_string(::getpid())); }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_P(ZRangeSearchTest, RangeHoldsTheTrueHeightsWithAtMostThreeStepsToSpare) {
  const auto [specimen, seed] = GetParam();
  Placed p = PlaceAtRandomHeight(specimen, seed);
  ASSERT_TRUE(p.rig);
  const ScanPlan plan = SearchPlan(*p.rig);
  std::vector<ScanFrameEvent> events;
  std::atomic<bool> cancel{false};
  auto out = RunScanWithZRangeSearch(
      *p.rig, plan, dir_, [&](const ScanFrameEvent& e) { events.push_back(e); }, cancel, nullptr);
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  ASSERT_TRUE(out->manifest.z_range_search.has_value());
  const ZRangeSearchRecord& r = *out->manifest.z_range_search;

  const double true_lo = Percentile(p.heights, 0.5), true_hi = Percentile(p.heights, 99.5);
  long inside = 0;
  for (float h : p.heights) inside += (h >= r.z_start_um && h <= r.z_end_um) ? 1 : 0;
  const double coverage = 100.0 * double(inside) / double(p.heights.size());
  EXPECT_GE(coverage, 99.0) << specimen << ": chosen " << r.z_start_um << " .. " << r.z_end_um << ", true " << true_lo
                            << " .. " << true_hi;
  const int fine = int(out->manifest.frames.size());
  if (fine > kMinFineFrames) {
    EXPECT_LE((true_lo - r.z_start_um) / kFineStepUm, 3.0) << specimen << ": start " << r.z_start_um;
    EXPECT_LE((r.z_end_um - true_hi) / kFineStepUm, 3.0) << specimen << ": end " << r.z_end_um;
  } else {
    // Flat parts: the engine's shortest stack (3 steps on each side of the focus frame),
    // centred on the estimate, which the refinement frames bring within a quarter step of the
    // truth (0.1-0.3 steps off without them: autorange-evaluate).
    EXPECT_EQ(fine, kMinFineFrames) << specimen;
    EXPECT_NEAR(0.5 * (r.z_start_um + r.z_end_um), 0.5 * (true_lo + true_hi), 0.25 * kFineStepUm) << specimen;
    EXPECT_LE((true_lo - r.z_start_um) / kFineStepUm, 3.25) << specimen;
    EXPECT_LE((r.z_end_um - true_hi) / kFineStepUm, 3.25) << specimen;
  }
  // Textured under uniform light: the scan over the chosen range measures the whole part.
  if (std::string(specimen) == "skew10" || std::string(specimen) == "step1um") {
    EXPECT_GT(out->depth.valid_fraction, 0.98) << specimen;
  }

  // The stack's frames are the chosen range at the fine step.
  ASSERT_GE(out->manifest.frames.size(), 3u);
  EXPECT_DOUBLE_EQ(out->manifest.frames.front().z_um, r.z_start_um);
  EXPECT_NEAR(out->manifest.frames.back().z_um, r.z_end_um, 1e-9);
  EXPECT_NEAR(out->manifest.frames[1].z_um - out->manifest.frames[0].z_um, kFineStepUm, 1e-9);
  // 100 .. 600 um at the rig's 20 um search step: 26 coarse frames planned, reported first,
  // stored under raw/. The sweep ends early once 98 % of the field has passed its focus
  // (textured parts); then its last frame is at most 3 coarse steps past the part's top (the
  // top's peak frame, two to see its curve fall, one for rounding) and the rest of the window is
  // not captured.
  const int planned = 26;
  const int coarse = int(r.coarse_frames.size());
  EXPECT_DOUBLE_EQ(r.coarse_step_um, 20.0);
  ASSERT_GE(coarse, 3);
  ASSERT_LE(coarse, planned);
  if (r.stopped_early) {
    EXPECT_LT(coarse, planned);
    EXPECT_GE(r.settled_percent, 98.0);
    EXPECT_LE(r.coarse_frames.back().z_um, Percentile(p.heights, 100.0) + 3 * r.coarse_step_um) << specimen;
  } else {
    EXPECT_EQ(coarse, planned);
    EXPECT_LT(r.settled_percent, 98.0);
    EXPECT_NEAR(r.coarse_frames.back().z_um, kWindowHighUm, 1e-9);
  }
  // Textured parts whose top lies 3+ coarse steps below the window's end stop early; parts with
  // large clipped or dark areas (coin, cutter) sweep the whole window.
  if (std::string(specimen) == "skew10" || std::string(specimen) == "mirror") {
    EXPECT_TRUE(r.stopped_early) << specimen << ": " << r.settled_percent << " % settled";
  }
  if (std::string(specimen) == "coin" || std::string(specimen) == "cutter") {
    EXPECT_FALSE(r.stopped_early) << specimen << ": " << r.settled_percent << " % settled";
  }
  // Then 2-4 frames half-way between the coarse frame nearest each end of the found range and
  // its neighbours (ZRangeAccumulator::PlanRefinement; 2 when both ends are nearest one frame).
  const int refine = int(r.refine_frames.size());
  EXPECT_GE(refine, 2) << specimen;
  EXPECT_LE(refine, 4) << specimen;
  for (const StackFrame& f : r.refine_frames) {
    const double from_grid = std::fmod(f.z_um - kWindowLowUm, r.coarse_step_um);
    EXPECT_NEAR(from_grid, 0.5 * r.coarse_step_um, 1e-6) << specimen << ": refinement at " << f.z_um;
    EXPECT_GE(f.z_um, r.z_start_um - r.coarse_step_um) << specimen;
    EXPECT_LE(f.z_um, r.z_end_um + r.coarse_step_um) << specimen;
    EXPECT_TRUE(fs::exists(dir_ / f.file)) << f.file;
  }
  EXPECT_EQ(out->images_acquired, coarse + refine + int(out->manifest.frames.size()));
  ASSERT_EQ(int(events.size()), out->images_acquired);
  for (int k = 0; k < int(events.size()); ++k) {
    EXPECT_EQ(events[size_t(k)].z_range_search, k < coarse + refine) << k;
    if (k < coarse + refine) {
      EXPECT_EQ(events[size_t(k)].index, k) << k;
    }
  }
  EXPECT_EQ(events.front().count, planned + ZRangeAccumulator::kMaxRefinementFrames);
  EXPECT_TRUE(fs::exists(dir_ / r.coarse_frames[2].file)) << r.coarse_frames[2].file;
}

INSTANTIATE_TEST_SUITE_P(Specimens, ZRangeSearchTest,
                         ::testing::Values(std::pair{"skew10", uint64_t(1)}, std::pair{"step1um", uint64_t(2)},
                                           std::pair{"cutter", uint64_t(3)}, std::pair{"coin", uint64_t(4)},
                                           std::pair{"mirror", uint64_t(5)}, std::pair{"lens", uint64_t(6)}),
                         [](const auto& info) { return std::string(info.param.first); });

// The search and the scan in a temporary folder, removed afterwards.
StatusOr<ScanOutcome> SearchAndScan(Rig& rig, const ScanPlan& plan, const std::string& tag) {
  const fs::path dir = fs::temp_directory_path() / ("zrange-" + tag + "-" + std::to_string(::getpid()));
  std::atomic<bool> cancel{false};
  auto out = RunScanWithZRangeSearch(rig, plan, dir, nullptr, cancel, nullptr);
  fs::remove_all(dir);
  return out;
}

// Share of the ground truth's pixels inside the chosen range.
double Coverage(Rig& rig, const ZRangeSearchRecord& r) {
  const cv::Mat truth = rig.simulation()->GroundTruthDepthUm();
  return double(cv::countNonZero((truth >= r.z_start_um) & (truth <= r.z_end_um))) / double(truth.total());
}

// When the search window is a few times the part's height (a fixture that places parts within
// +-40 um) and the fine step is fine, the search (sweep and refinement frames) costs <= 25 % of
// the fine scan's frames: wedge (109 um high at 512x384), 2 um steps, a window of 80 um around
// it, coarse step 20 um. At +-50 um the search took 11 + 4 frames against 58 (0.26).
TEST(ZRangeSearchBudgetTest, CoarseFramesAtMostAQuarterOfTheFineScanNearThePart) {
  std::unique_ptr<Rig> rig = RigWithSpecimenAt("wedge", 9, 83.0);
  ASSERT_TRUE(rig);
  const auto [lo, hi] = rig->simulation()->SpecimenZRangeUm();
  ScanPlan plan;
  plan.exposure_us = rig->scan_defaults().exposure_us;
  plan.z_step_um = 2.0;
  plan.z_range_search = ZRangeSearchSettings{std::floor(lo) - 40.0, std::ceil(hi) + 40.0, 20.0, 3.0};
  auto out = SearchAndScan(*rig, plan, "budget");
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  const ZRangeSearchRecord& r = *out->manifest.z_range_search;
  const size_t search = r.coarse_frames.size() + r.refine_frames.size();
  EXPECT_LE(double(search), 0.25 * double(out->manifest.frames.size()))
      << r.coarse_frames.size() << " coarse + " << r.refine_frames.size() << " refining, "
      << out->manifest.frames.size() << " fine";
  EXPECT_GE(Coverage(*rig, r), 0.99);
}

// At fine steps well below the coarse step the margin is set by the search's own error: the
// cutter's clipped top resolves no coarse peak, and from the coarse frames alone the search
// placed its top ~4 um low, so 1.5 fine steps of margin (3 um at 2 um steps) cut it (93.4 % of
// the pixels inside at seed 23). The refinement frames at the range's ends bring the top within
// 2 um of the truth, and the default margin (1.5 fine steps, at least an eighth coarse step:
// 3 um) keeps the whole part with at most 3 steps to spare.
TEST(ZRangeSearchMarginTest, FineStepsBelowTheSearchErrorKeepTheWholePart) {
  std::unique_ptr<Rig> rig = RigWithSpecimenAt("cutter", 23, 243.6);
  ASSERT_TRUE(rig);
  ScanPlan plan;
  plan.exposure_us = rig->scan_defaults().exposure_us;
  plan.z_step_um = 2.0;
  auto s = ResolveZRangeSearch({kWindowLowUm, kWindowHighUm, 0.0, 0.0}, 2.0, rig->scan_defaults(), rig->stage());
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_DOUBLE_EQ(s->margin_um, 3.0);
  plan.z_range_search = *s;
  auto out = SearchAndScan(*rig, plan, "margin");
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  const ZRangeSearchRecord& r = *out->manifest.z_range_search;
  EXPECT_GE(Coverage(*rig, r), 0.99) << r.z_start_um << " .. " << r.z_end_um;
  EXPECT_GE(r.refine_frames.size(), 2u);
  const cv::Mat truth = rig->simulation()->GroundTruthDepthUm();
  const std::vector<float> heights(truth.begin<float>(), truth.end<float>());
  const double true_lo = Percentile(heights, 0.5), true_hi = Percentile(heights, 99.5);
  EXPECT_NEAR(r.focus_high_um, true_hi, 2.0);
  EXPECT_LE((true_lo - r.z_start_um) / 2.0, 3.0) << r.z_start_um;
  EXPECT_LE((r.z_end_um - true_hi) / 2.0, 3.0) << r.z_end_um;
}

// The coarse step comes from the rig's optics (ScanDefaults.focus_search_step_um: 20 um on the
// simulated thesis rig, whatever the fine step); a rig that does not know it takes 4 fine steps.
TEST(ZRangeSearchDefaultsTest, DefaultsComeFromTheRigsOpticsAndRange) {
  SimulatedRigOptions o;
  o.camera_size = {64, 48};
  auto rig = CreateSimulatedRig(o);
  ASSERT_TRUE(rig.ok());
  ScanDefaults d = (*rig)->scan_defaults();
  EXPECT_DOUBLE_EQ(d.focus_search_step_um, 20.0);
  for (double fine : {1.0, 2.0, 10.0}) {
    auto s = ResolveZRangeSearch({}, fine, d, (*rig)->stage());
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    EXPECT_DOUBLE_EQ(s->window_start_um, d.z_start_um);
    EXPECT_DOUBLE_EQ(s->window_end_um, d.z_end_um);
    EXPECT_DOUBLE_EQ(s->coarse_step_um, 20.0) << fine;
    // 1.5 fine steps, but at least an eighth of the coarse step (the search's own error).
    EXPECT_DOUBLE_EQ(s->margin_um, std::max(1.5 * fine, 2.5)) << fine;
  }
  d.focus_search_step_um = 0.0;
  auto unknown = ResolveZRangeSearch({}, 2.0, d, (*rig)->stage());
  ASSERT_TRUE(unknown.ok());
  EXPECT_DOUBLE_EQ(unknown->coarse_step_um, 8.0);
  EXPECT_DOUBLE_EQ(unknown->margin_um, 3.0);
  // A higher NA blurs faster per um: a shorter step (tan(asin 0.6) / 0.74 = 1.01 px/um: 8 um).
  o.numerical_aperture = 0.6;
  auto high_na = CreateSimulatedRig(o);
  ASSERT_TRUE(high_na.ok());
  EXPECT_DOUBLE_EQ((*high_na)->scan_defaults().focus_search_step_um, 8.0);
  auto bad = ResolveZRangeSearch({100.0, 26000.0, 0.0, 0.0}, 2.0, d, (*rig)->stage());
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("z_range_search.window_end_um"), std::string::npos);
}

// The simulated rig's specimen offset: truth and range move, the rig's default range does not.
TEST(SimulatedSpecimenOffsetTest, MovesTheTruthButNotTheDefaultRange) {
  SimulatedRigOptions o;
  o.camera_size = {64, 48};
  auto rig = CreateSimulatedRig(o);
  ASSERT_TRUE(rig.ok());
  SimulationControl* sim = (*rig)->simulation();
  const cv::Mat before = sim->GroundTruthDepthUm();
  const ScanDefaults d = (*rig)->scan_defaults();
  ASSERT_TRUE(sim->SetSpecimenZOffsetUm(250.0).ok());
  EXPECT_NEAR(cv::norm(sim->GroundTruthDepthUm() - before - 250.0, cv::NORM_INF), 0.0, 1e-3);
  EXPECT_DOUBLE_EQ((*rig)->scan_defaults().z_start_um, d.z_start_um);
  ASSERT_TRUE(sim->SetSpecimen("plane").ok());  // kept across specimens
  EXPECT_NEAR(sim->SpecimenZRangeUm().first, 450.0, 1e-3);
  const Status st = sim->SetSpecimenZOffsetUm(-500.0);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("specimen_z_offset_um"), std::string::npos);
  EXPECT_NEAR(sim->SpecimenZRangeUm().first, 450.0, 1e-3);  // unchanged after the refusal
}

}  // namespace
}  // namespace inspection
