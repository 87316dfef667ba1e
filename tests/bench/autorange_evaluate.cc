// Automatic z range (server/procedures/z_range_search.h) on the simulated rig: every
// built-in specimen placed at a random height (drawn from the seed) inside the search window,
// scanned with the coarse sweep and the fine scan; the chosen range against the ground truth.
//
// Columns: the truth's range of 99 % of the pixels (P0.5 .. P99.5 of GroundTruthDepthUm), the
// chosen fine range, the margins below / above that truth range in fine steps (negative: the
// range cuts into it), coverage (% of all pixels whose true height lies in the chosen range),
// the share of the field with a resolved coarse peak, the sweep's frames, the frames refining
// the range's ends, (sweep + refinement) / fine frames and the search's wall time over the fine
// scan's acquisition time (same run, same rig).
//
// Usage: autorange-evaluate [--seeds 5,11,23] [--specimens all|a,b,...] [--camera WxH]
//                           [--window A:B] [--fine-step UM] [--coarse-step UM] [--margin UM]
//                           [--keep DIR]   (keep each run's stack, coarse frames included, in DIR)
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "devices/sim/simulated_rig.h"
#include "devices/sim/specimen.h"
#include "server/procedures/z_range_search.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

struct Row {
  std::string specimen;
  uint64_t seed = 0;
  double offset_um = 0, true_lo = 0, true_hi = 0, chosen_lo = 0, chosen_hi = 0;
  double margin_lo_steps = 0, margin_hi_steps = 0, coverage = 0, resolved = 0, time_ratio = 0, valid = 0;
  int coarse = 0, refine = 0, fine = 0;
  std::string error;
};

double Percentile(std::vector<float> v, double p) {
  const size_t k = std::min(v.size() - 1, size_t(std::floor(p / 100.0 * double(v.size() - 1) + 0.5)));
  std::nth_element(v.begin(), v.begin() + long(k), v.end());
  return v[k];
}

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, sep);) out.push_back(item);
  return out;
}

Row RunOne(const std::string& specimen, uint64_t seed, cv::Size camera, double w0, double w1, double fine_step,
           double coarse_step, double margin, const fs::path& work, bool keep) {
  Row row;
  row.specimen = specimen;
  row.seed = seed;
  SimulatedRigOptions o;
  o.specimen = specimen;
  o.seed = seed;
  o.camera_size = camera;
  auto rig_or = CreateSimulatedRig(o);
  if (!rig_or.ok()) {
    row.error = rig_or.status().ToString();
    return row;
  }
  Rig& rig = **rig_or;
  SimulationControl* sim = rig.simulation();
  // Random placement: the whole specimen inside the window, 10 um from its ends.
  const auto [lo, hi] = sim->SpecimenZRangeUm();
  std::mt19937_64 rng(seed * 7919 + std::hash<std::string>()(specimen));
  std::uniform_real_distribution<double> place(w0 + 10.0 - lo, std::max(w0 + 10.0 - lo, w1 - 10.0 - hi));
  row.offset_um = place(rng);
  if (Status st = sim->SetSpecimenZOffsetUm(row.offset_um); !st.ok()) {
    row.error = st.ToString();
    return row;
  }
  const cv::Mat truth = sim->GroundTruthDepthUm();
  std::vector<float> heights(truth.begin<float>(), truth.end<float>());
  row.true_lo = Percentile(heights, 0.5);
  row.true_hi = Percentile(heights, 99.5);

  ScanPlan plan;
  plan.exposure_us = rig.scan_defaults().exposure_us;
  plan.z_step_um = fine_step;
  plan.z_range_search = ZRangeSearchSettings{w0, w1, coarse_step, margin};
  auto resolved = ResolveZRangeSearch(*plan.z_range_search, fine_step, rig.scan_defaults(), rig.stage());
  if (!resolved.ok()) {
    row.error = resolved.status().ToString();
    return row;
  }
  plan.z_range_search = *resolved;
  std::atomic<bool> cancel{false};
  const fs::path dir = work / (specimen + "-" + std::to_string(seed));
  auto out = RunScanWithZRangeSearch(rig, plan, dir, nullptr, cancel, nullptr);
  if (!keep) {
    fs::remove_all(dir);
  } else if (out.ok()) {
    cv::imwrite((dir / "truth_um.tiff").string(), truth);  // CV_32FC1 ground truth, for analysis
  }
  if (!out.ok()) {
    row.error = out.status().ToString();
    return row;
  }
  const ZRangeSearchRecord& r = *out->manifest.z_range_search;
  row.chosen_lo = r.z_start_um;
  row.chosen_hi = r.z_end_um;
  row.margin_lo_steps = (row.true_lo - r.z_start_um) / fine_step;
  row.margin_hi_steps = (r.z_end_um - row.true_hi) / fine_step;
  long inside = 0;
  for (float h : heights) inside += (h >= r.z_start_um && h <= r.z_end_um) ? 1 : 0;
  row.coverage = 100.0 * double(inside) / double(heights.size());
  row.resolved = r.resolved_percent;
  row.coarse = int(r.coarse_frames.size());
  row.refine = int(r.refine_frames.size());
  row.valid = 100.0 * out->depth.valid_fraction;
  row.fine = int(out->manifest.frames.size());
  // The fine scan's acquisition includes its reconstruction setup; both sides are wall time.
  row.time_ratio = r.search_seconds / std::max(1e-9, out->acquisition_seconds);
  return row;
}

int Main(int argc, char** argv) {
  std::vector<uint64_t> seeds = {5, 11, 23};
  std::vector<std::string> specimens = BuiltinSpecimenNames();
  cv::Size camera{1024, 768};
  double w0 = 100.0, w1 = 600.0, fine_step = 5.0, coarse_step = 0.0, margin = 0.0;
  fs::path keep_dir;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      std::fprintf(stderr, "autorange-evaluate: %s needs a value\n", a.c_str());
      return 2;
    }
    const std::string v = argv[++i];
    if (a == "--seeds") {
      seeds.clear();
      for (const auto& s : Split(v, ',')) seeds.push_back(std::stoull(s));
    } else if (a == "--specimens") {
      if (v != "all") specimens = Split(v, ',');
    } else if (a == "--camera") {
      if (std::sscanf(v.c_str(), "%dx%d", &camera.width, &camera.height) != 2) return 2;
    } else if (a == "--window") {
      if (std::sscanf(v.c_str(), "%lf:%lf", &w0, &w1) != 2) return 2;
    } else if (a == "--fine-step") {
      fine_step = std::stod(v);
    } else if (a == "--coarse-step") {
      coarse_step = std::stod(v);
    } else if (a == "--margin") {
      margin = std::stod(v);
    } else if (a == "--keep") {
      keep_dir = v;
    } else {
      std::fprintf(stderr, "autorange-evaluate: unknown option %s\n", a.c_str());
      return 2;
    }
  }
  const fs::path work =
      keep_dir.empty() ? fs::temp_directory_path() / ("autorange-evaluate-" + std::to_string(::getpid())) : keep_dir;
  std::printf("automatic z range: window %.1f .. %.1f um, fine step %.2f um, camera %dx%d\n", w0, w1, fine_step,
              camera.width, camera.height);
  std::printf("%-8s %4s %7s | %-17s | %-17s | %6s %6s | %7s %7s | %6s %3s %4s %5s | %5s | %6s\n", "specimen", "seed",
              "offset", "true P0.5..P99.5", "chosen", "m_lo", "m_hi", "cover%", "resolv%", "coarse", "ref", "fine",
              "c/f", "t s/f", "valid%");
  int failures = 0, rows = 0;
  double worst_cover = 100.0, worst_margin = -1e9, worst_inner = 1e9, max_cf = 0.0, sum_t = 0.0;
  long sum_search = 0, sum_fine = 0;
  for (const auto& specimen : specimens) {
    for (uint64_t seed : seeds) {
      const Row r = RunOne(specimen, seed, camera, w0, w1, fine_step, coarse_step, margin, work, !keep_dir.empty());
      if (!r.error.empty()) {
        std::printf("%-8s %4llu %7.1f | %s\n", r.specimen.c_str(), (unsigned long long)r.seed, r.offset_um,
                    r.error.c_str());
        ++failures;
        continue;
      }
      ++rows;
      const double cf = double(r.coarse + r.refine) / double(r.fine);
      sum_search += r.coarse + r.refine;
      sum_fine += r.fine;
      std::printf(
          "%-8s %4llu %7.1f | %7.1f .. %7.1f | %7.1f .. %7.1f | %6.2f %6.2f | %7.2f %7.1f | %6d %3d %4d %5.2f | %5.2f | "
          "%6.1f\n",
          r.specimen.c_str(), (unsigned long long)r.seed, r.offset_um, r.true_lo, r.true_hi, r.chosen_lo, r.chosen_hi,
          r.margin_lo_steps, r.margin_hi_steps, r.coverage, r.resolved, r.coarse, r.refine, r.fine, cf, r.time_ratio,
          r.valid);
      worst_cover = std::min(worst_cover, r.coverage);
      worst_margin = std::max({worst_margin, r.margin_lo_steps, r.margin_hi_steps});
      worst_inner = std::min({worst_inner, r.margin_lo_steps, r.margin_hi_steps});
      max_cf = std::max(max_cf, cf);
      sum_t += r.time_ratio;
    }
  }
  std::printf(
      "rows %d, failed %d; worst coverage %.2f %%, margins %.2f .. %.2f steps, (coarse + ref) / fine <= %.2f "
      "(summed: %.2f), search time / fine scan time mean %.2f\n",
      rows, failures, worst_cover, worst_inner, worst_margin, max_cf,
      sum_fine ? double(sum_search) / double(sum_fine) : 0.0, rows ? sum_t / rows : 0.0);
  std::error_code ec;
  if (keep_dir.empty()) fs::remove_all(work, ec);
  return failures == 0 ? 0 : 1;
}

}  // namespace
}  // namespace inspection

int main(int argc, char** argv) { return inspection::Main(argc, argv); }
