// Evaluation of the illumination modes on the simulated specimens (thesis 6.2): calibrates a
// simulated rig once, scans each specimen with each mode and prints the thesis's tables with the
// depth error against ground truth as sigma (the thesis's figure), bias (mean signed error) and
// RMSE: Table 6.3 (and #images), Table 6.5 (STD vs TEXTURE on textureless specimens), Table 6.6
// (outlier %), Fig. 6.3 (image mean / sd of the first frames), and every built-in specimen with
// every mode at its default scan against the bias bound of docs/illumination.md.
// Then integral SFF (thesis 6.4, tests/bench/isff_tables.h): Table 6.8, Table 6.9, Fig. 6.17 and
// the calibration and reconstruction times, on their own rig (default camera 512x384).
// Usage: inspect-evaluate [--camera WxH] [--projector WxH] [--seed N] [--bias-only] [--specimens a,b]
//        [--modes STD,ADAPT,...] [--isff-only | --no-isff] [--no-consistency] [--dump DIR] [--repeats N]
//        (default 256x192, 96x72, seed 5, all tables, every specimen and mode)
//        inspect-evaluate --natural [natural-evaluate's options]: the natural-scene evaluation
// --repeats N scans every specimen and mode N times and reports the mean bias (the systematic part)
// beside its scan-to-scan spread; --dump DIR writes each scan's error map (PNG and text), its
// all-in-focus image, its middle row (truth, measured, grey) and keeps its stack folder.
// --user-scenes runs the bias tables on four scene.json user scenes instead of the built-ins
// (WriteEvaluationScenes below). --illumination-invariant scans with
// SffOptions::illumination_invariant (the focus measure divided by the window mean squared).
//        (tests/bench/natural_tables.h) instead
// --bias-only prints only the bias table; --specimens / --modes restrict it (for quick checks).
// --isff-only prints only the integral SFF part (--camera and --seed apply to it when given),
// --no-isff leaves it out. --no-consistency turns the depth consistency check of the post-processing
// off (core/sff/depth_postprocess.h), for comparing the default with and without it. Exit status 3
// when a mode exceeds the bias bound, 1 on a failure.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "core/metrology/depth_metrics.h"
#include "devices/sim/simulated_rig.h"
#include "devices/sim/specimen.h"
#include "server/procedures/calibration_procedure.h"
#include "server/procedures/scan_procedure.h"
#include "tests/bench/isff_tables.h"
#include "tests/bench/natural_tables.h"
#include "tests/lib/user_scene.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

constexpr int kWindowPx = 9;  // Tenengrad window; also the border left out of the comparison

struct Run {
  DepthErrorStats error;
  int images = 0;
  std::vector<FrameStatistics> captures;
  cv::Mat depth_um, truth_um, all_in_focus;
  double outlier_threshold_um = 0;
  double z_step_um = 0;
  bool ok = false;
  std::string decision;  // AUTO: the mode it chose and why
  std::string chosen;    // the mode that ran
  // Over repeated scans (--repeats): error holds the means of the per-scan figures; these the
  // scan-to-scan spread of the bias and the largest single-scan |bias|.
  int scans = 1;
  std::vector<cv::Mat> scan_depths_um;  // each scan's depth map (for comparisons on common pixels)
  double bias_sd_um = 0.0;
  double worst_scan_bias_um = 0.0;
};

// Repeated scans of one specimen and mode as one row: the bias that stays over the repeats is
// the systematic error (what a mode's calibration would have to remove); the spread is the
// scan-to-scan repeatability (the stage's +-0.1 um per move, camera noise).
Run Aggregate(std::vector<Run> runs) {
  std::vector<Run> ok;
  for (Run& r : runs)
    if (r.ok) ok.push_back(std::move(r));
  if (ok.empty()) return Run{};
  Run out = ok.front();
  for (const Run& r : ok) out.scan_depths_um.push_back(r.depth_um);
  const double n = double(ok.size());
  DepthErrorStats mean{};
  double images = 0, bias2 = 0, worst = 0;
  for (const Run& r : ok) {
    mean.valid_percent += r.error.valid_percent / n;
    mean.mean_error_um += r.error.mean_error_um / n;
    mean.stddev_error_um += r.error.stddev_error_um / n;
    mean.rmse_um += r.error.rmse_um / n;
    mean.outlier_percent += r.error.outlier_percent / n;
    images += r.images / n;
    bias2 += r.error.mean_error_um * r.error.mean_error_um;
    if (std::abs(r.error.mean_error_um) > std::abs(worst)) worst = r.error.mean_error_um;
  }
  out.error = mean;
  out.images = int(std::lround(images));
  out.scans = int(ok.size());
  out.bias_sd_um =
      ok.size() > 1 ? std::sqrt(std::max(0.0, (bias2 - n * mean.mean_error_um * mean.mean_error_um) / (n - 1))) : 0.0;
  out.worst_scan_bias_um = worst;
  return out;
}

// "sigma bias RMSE" of a comparison, um.
std::string ErrorCells(const DepthErrorStats& e) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%6.3f %+7.3f %6.3f", e.stddev_error_um, e.mean_error_um, e.rmse_um);
  return buf;
}

// The bias bound of docs/illumination.md: 0.1 um or 0.02 z steps, whichever is larger.
double BiasBoundUm(double z_step_um) { return std::max(0.1, 0.02 * z_step_um); }

// "file:/dir/name.json" -> "name"; built-in ids unchanged.
std::string SpecimenLabel(const std::string& specimen) {
  return specimen.rfind("file:", 0) == 0 ? fs::path(specimen.substr(5)).stem().string() : specimen;
}

// User scenes (scene.json, as a customer would load them) of the kinds a fixed default gets
// wrong: a polished plane with a few pits and almost no texture, a well-textured terraced part
// that never saturates, a shiny weld bead (~500:1 reflectance), a textured dome and solder bumps
// glinting on a dark board. Heights
// around 200 um like the built-ins; the rig derives its default scan range from each scene.
std::vector<std::string> WriteEvaluationScenes(const fs::path& dir, cv::Size size, double px) {
  const double w = size.width * px, h = size.height * px, base = 200.0;
  std::vector<std::string> out;
  test_scenes::UserSceneSpec pits;
  pits.height_um = [=](double x, double y) {
    double z = base;
    const double cx[] = {0.25, 0.7, 0.45, 0.8}, cy[] = {0.3, 0.25, 0.7, 0.75};
    for (int k = 0; k < 4; ++k) {
      const double r = std::hypot(x - cx[k] * w, y - cy[k] * h) / (0.08 * std::min(w, h));
      if (r < 1.0) z -= 3.0 * 0.5 * (1.0 + std::cos(M_PI * r));
    }
    return z;
  };
  pits.reflectance = [](double, double) { return 0.6; };
  pits.texture_contrast = 0.03;
  pits.texture_seed = 31;
  out.push_back(test_scenes::WriteUserScene(dir, "pitted_polish", size, px, pits));
  test_scenes::UserSceneSpec terraces;
  terraces.height_um = [=](double x, double) {
    const double t = x / w * 3.0;  // three terraces 8 um apart, joined by smooth ramps
    const double k = std::floor(t), f = t - k, ramp = std::clamp((f - 0.85) / 0.15, 0.0, 1.0);
    return base + 8.0 * (k + 0.5 * (1.0 - std::cos(M_PI * ramp)));
  };
  terraces.reflectance = [](double, double) { return 0.35; };
  terraces.texture_seed = 32;
  out.push_back(test_scenes::WriteUserScene(dir, "terraces", size, px, terraces));
  // A weld bead: glints along the crest, ~500:1 against its dark flanks.
  out.push_back(test_scenes::WriteUserScene(dir, "weld_bead", size, px, test_scenes::WeldBeadScene(size, px)));
  test_scenes::UserSceneSpec dome;
  dome.height_um = [=](double x, double y) {
    const double r = std::hypot(x - 0.5 * w, y - 0.5 * h), rd = 0.4 * std::min(w, h), R = 300.0;
    return base + (r < rd ? std::sqrt(R * R - r * r) - std::sqrt(R * R - rd * rd) : 0.0);
  };
  dome.reflectance = [](double, double) { return 0.4; };
  dome.texture_seed = 34;
  out.push_back(test_scenes::WriteUserScene(dir, "dome", size, px, dome));
  // Solder bumps on a dark board: six 15 um caps of shiny tin (glints ~300:1 against the board at
  // their tops) on a dark solder mask (reflectance 0.015).
  test_scenes::UserSceneSpec bumps;
  const double bump_r = 0.16 * std::min(w, h), cap_h = 15.0;
  const double bx[] = {0.2, 0.5, 0.8, 0.2, 0.5, 0.8}, by[] = {0.3, 0.3, 0.3, 0.72, 0.72, 0.72};
  auto bump_at = [=](double x, double y) {  // (distance / radius) to the nearest bump centre
    double best = 1e9;
    for (int k = 0; k < 6; ++k) best = std::min(best, std::hypot(x - bx[k] * w, y - by[k] * h) / bump_r);
    return best;
  };
  bumps.height_um = [=](double x, double y) {
    const double r = bump_at(x, y);
    if (r >= 1.0) return base;
    const double R = (bump_r * bump_r + cap_h * cap_h) / (2.0 * cap_h);  // sphere through the rim
    const double d = r * bump_r;
    return base + std::sqrt(R * R - d * d) - (R - cap_h);
  };
  bumps.reflectance = [=](double x, double y) {
    const double r = bump_at(x, y);
    return r < 1.0 ? 0.3 + 4.5 * std::exp(-r * r / 0.03) : 0.015;
  };
  bumps.texture_contrast = 0.6;
  bumps.texture_seed = 35;
  out.push_back(test_scenes::WriteUserScene(dir, "solder_bumps", size, px, bumps));
  return out;
}

// Error map as a picture: blue = measured too high, red = too low, saturating at 2 z steps;
// grey = no depth. For looking at where a bias comes from.
void DumpErrorMap(const Run& r, const fs::path& dir, const std::string& name) {
  const float full = static_cast<float>(r.outlier_threshold_um);
  cv::Mat out(r.depth_um.size(), CV_8UC3, cv::Scalar(128, 128, 128));
  for (int y = 0; y < out.rows; ++y)
    for (int x = 0; x < out.cols; ++x) {
      const float e = r.depth_um.at<float>(y, x) - r.truth_um.at<float>(y, x);
      if (!std::isfinite(e)) continue;
      const float t = std::clamp(e / full, -1.0f, 1.0f);
      const auto hi = static_cast<uchar>(255), lo = static_cast<uchar>(255 * (1 - std::abs(t)));
      out.at<cv::Vec3b>(y, x) = t >= 0 ? cv::Vec3b(hi, lo, lo) : cv::Vec3b(lo, lo, hi);
    }
  cv::imwrite((dir / (name + "_error.png")).string(), out);
  if (!r.all_in_focus.empty()) cv::imwrite((dir / (name + "_all_in_focus.png")).string(), r.all_in_focus);
  // The whole map as text, one image row per line: measured - truth (um), nan = no depth.
  if (FILE* f = std::fopen((dir / (name + "_error.txt")).string().c_str(), "w")) {
    for (int y = 0; y < r.depth_um.rows; ++y) {
      for (int x = 0; x < r.depth_um.cols; ++x)
        std::fprintf(f, x ? " %.4g" : "%.4g", double(r.depth_um.at<float>(y, x) - r.truth_um.at<float>(y, x)));
      std::fputc('\n', f);
    }
    std::fclose(f);
  }
  // The middle row as text: column, truth, measured (um).
  if (FILE* f = std::fopen((dir / (name + "_row.txt")).string().c_str(), "w")) {
    const int y = r.depth_um.rows / 2;
    for (int x = 0; x < r.depth_um.cols; ++x)
      std::fprintf(f, "%d %.3f %.3f %d\n", x, r.truth_um.at<float>(y, x), r.depth_um.at<float>(y, x),
                   r.all_in_focus.empty() ? -1 : int(r.all_in_focus.at<uchar>(y, x)));
    std::fclose(f);
  }
}

struct Evaluator {
  Rig* rig;
  const CalibrationBundle* bundle;
  fs::path dir;
  bool consistency = true;  // the depth consistency check of the post-processing (--no-consistency: off)
  fs::path dump_dir;        // --dump: error maps written here (empty: none)
  bool illumination_invariant = false;  // --illumination-invariant: SffOptions::illumination_invariant

  Run Scan(const std::string& specimen, IlluminationMode mode, IlluminationParams params, double z_step_um = 0) {
    Run r;
    r.z_step_um = z_step_um;
    if (!rig->simulation()->SetSpecimen(specimen).ok()) return r;
    const ScanDefaults d = rig->scan_defaults();
    auto plan =
        MakeScanPlan(d.z_start_um, d.z_end_um, z_step_um > 0 ? z_step_um : d.z_step_um, d.exposure_us, rig->stage());
    if (!plan.ok()) return r;
    plan->mode = mode;
    plan->params = params;
    plan->sff.window_px = kWindowPx;
    plan->postprocess.consistency = consistency;
    plan->sff.illumination_invariant = illumination_invariant;
    std::atomic<bool> cancel{false};
    const fs::path stack =
        dir / (specimen + "_" + std::to_string(int(mode)) + "_" + std::to_string(params.hdr_exposures));
    auto o = RunScan(*rig, *plan, stack, nullptr, cancel, bundle);
    std::error_code ec;
    if (!dump_dir.empty()) {  // keep the stack beside the error maps
      const fs::path kept = dump_dir / (SpecimenLabel(specimen) + "_" + IlluminationModeName(mode, params.hdr_exposures));
      fs::remove_all(kept, ec);
      fs::rename(stack, kept, ec);
    }
    fs::remove_all(stack, ec);
    if (!o.ok()) {
      std::fprintf(stderr, "%s %s: %s\n", specimen.c_str(), IlluminationModeName(mode, params.hdr_exposures).c_str(),
                   o.status().ToString().c_str());
      return r;
    }
    if (!(r.z_step_um > 0)) r.z_step_um = d.z_step_um;
    r.outlier_threshold_um = 2.0 * d.z_step_um;
    r.error = CompareDepth(o->depth.depth_um, o->ground_truth_um, r.outlier_threshold_um, kWindowPx);
    r.images = o->images_acquired;
    r.depth_um = o->depth.depth_um;
    r.truth_um = o->ground_truth_um;
    r.all_in_focus = o->depth.all_in_focus;
    r.captures = o->capture_statistics;
    r.decision = o->illumination_decision;
    r.chosen = IlluminationModeName(o->illumination, params.hdr_exposures);
    r.ok = true;
    if (!dump_dir.empty()) DumpErrorMap(r, dump_dir, SpecimenLabel(specimen) + "_" + IlluminationModeName(mode, params.hdr_exposures));
    return r;
  }
};

std::vector<std::string> SplitCommas(const std::string& s) {
  std::vector<std::string> out;
  for (size_t a = 0; a <= s.size();) {
    const size_t b = std::min(s.find(',', a), s.size());
    if (b > a) out.push_back(s.substr(a, b - a));
    a = b + 1;
  }
  return out;
}

cv::Size ParseSize(const char* s) {
  int w = 0, h = 0;
  if (std::sscanf(s, "%dx%d", &w, &h) != 2 || w <= 0 || h <= 0) {
    std::fprintf(stderr, "bad size %s (want WxH)\n", s);
    std::exit(2);
  }
  return {w, h};
}

void PrintThesisTables(Evaluator& ev);
int PrintBiasTable(Evaluator& ev, const std::vector<std::string>& specimens,
                   const std::vector<IlluminationMode>& modes, int repeats);

int Main(int argc, char** argv) {
  SimulatedRigOptions ro;
  ro.camera_size = {256, 192};
  ro.projector_size = {96, 72};
  ro.seed = 5;
  bool bias_only = false;
  bool no_consistency = false;
  bool user_scenes = false;
  bool illumination_invariant = false;
  fs::path dump_dir;
  int repeats = 1;
  bool isff_only = false, no_isff = false, camera_given = false;
  std::vector<std::string> specimens = BuiltinSpecimenNames();
  const IlluminationMode all_modes[] = {
      IlluminationMode::kStd,       IlluminationMode::kHdr,     IlluminationMode::kAdaptIterative,
      IlluminationMode::kAdapt,     IlluminationMode::kTexture, IlluminationMode::kHfAdapt,
      IlluminationMode::kAdaptedHf, IlluminationMode::kAuto};
  std::vector<IlluminationMode> modes(std::begin(all_modes), std::end(all_modes));
  const char* usage =
      "usage: inspect-evaluate [--camera WxH] [--projector WxH] [--seed N] [--bias-only] [--specimens a,b] "
      "[--modes STD,ADAPT,...] [--isff-only | --no-isff] [--no-consistency] [--dump DIR] [--repeats N] [--user-scenes] "
      "[--illumination-invariant]\n";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--dump" && i + 1 < argc) {
      dump_dir = argv[++i];
      continue;
    }
    if (a == "--no-consistency") {
      no_consistency = true;
      continue;
    }
    if (a == "--illumination-invariant") {
      illumination_invariant = true;
      continue;
    }
    if (a == "--user-scenes") {
      user_scenes = true;
      continue;
    }
    if (a == "--bias-only" || a == "--isff-only" || a == "--no-isff") {
      bias_only |= a == "--bias-only";
      isff_only |= a == "--isff-only";
      no_isff |= a == "--no-isff";
      continue;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s", usage);
      return 2;
    }
    const std::string v = argv[++i];
    if (a == "--camera") {
      ro.camera_size = ParseSize(v.c_str());
      camera_given = true;
    } else if (a == "--projector")
      ro.projector_size = ParseSize(v.c_str());
    else if (a == "--seed")
      ro.seed = std::strtoull(v.c_str(), nullptr, 10);
    else if (a == "--repeats") {
      repeats = std::atoi(v.c_str());
      if (repeats < 1 || repeats > 50) {
        std::fprintf(stderr, "--repeats must be 1..50\n");
        return 2;
      }
    } else if (a == "--specimens")
      specimens = SplitCommas(v);
    else if (a == "--modes") {
      modes.clear();
      for (const std::string& name : SplitCommas(v)) {
        const auto* m = std::find_if(std::begin(all_modes), std::end(all_modes),
                                     [&](IlluminationMode x) { return IlluminationModeName(x) == name; });
        if (m == std::end(all_modes)) {
          std::fprintf(stderr, "--modes: unknown mode %s\n", name.c_str());
          return 2;
        }
        modes.push_back(*m);
      }
    } else {
      std::fprintf(stderr, "%s", usage);
      return 2;
    }
  }
  if (isff_only && (no_isff || bias_only)) {
    std::fprintf(stderr, "--isff-only excludes --no-isff and --bias-only\n%s", usage);
    return 2;
  }
  IsffTablesOptions isff;
  if (camera_given) isff.camera_size = ro.camera_size;
  isff.seed = ro.seed;
  if (isff_only) return PrintIsffTables(isff) ? 0 : 1;
  auto rig = CreateSimulatedRig(ro);
  if (!rig.ok()) {
    std::fprintf(stderr, "%s\n", rig.status().ToString().c_str());
    return 1;
  }
  CalibrationOptions co;
  co.steps = {CalibrationStep::kCameraResponse, CalibrationStep::kProjectorResponse, CalibrationStep::kGeometry,
              CalibrationStep::kPsf, CalibrationStep::kScatterMatrix};
  co.crf_exposure_count = 16;
  co.prf_level_step = 15;
  co.geometry_grid_spacing_px = 6;
  co.psf_defocus_um = {-10.0, 0.0, 10.0};
  co.psf_grid_spacing_px = 12;
  co.scatter_grid_spacing_px = 6;
  std::atomic<bool> cancel{false};
  auto bundle = RunCalibration(**rig, co, nullptr, nullptr, cancel);
  if (!bundle.ok()) {
    std::fprintf(stderr, "calibration: %s\n", bundle.status().ToString().c_str());
    return 1;
  }
  Evaluator ev{rig->get(), &*bundle, fs::temp_directory_path() / ("inspect_evaluate_" + std::to_string(::getpid())),
               !no_consistency, dump_dir, illumination_invariant};
  std::printf(
      "Simulated rig: camera %dx%d, projector %dx%d, seed %llu; sigma_p %.2f px; Tenengrad 9x9; "
      "outlier = |error| > 2 z steps or no depth counted apart (valid %%)\n\n",
      ro.camera_size.width, ro.camera_size.height, ro.projector_size.width, ro.projector_size.height,
      (unsigned long long)ro.seed, bundle->psf->influence_radius_px);

  if (user_scenes) {
    specimens = WriteEvaluationScenes(ev.dir / "scenes", ro.camera_size, ro.pixel_size_um);
    bias_only = true;
    std::printf("User scenes (--user-scenes): pitted_polish, terraces, weld_bead, dome in %s\n",
                (ev.dir / "scenes").c_str());
  }
  if (!bias_only) PrintThesisTables(ev);
  const int violations = PrintBiasTable(ev, specimens, modes, repeats);
  std::error_code ec;
  fs::remove_all(ev.dir, ec);
  bool isff_ok = true;
  if (!bias_only && !no_isff) {
    std::printf("\nIntegral SFF (thesis 6.4)\n");
    isff_ok = PrintIsffTables(isff);
  }
  return violations > 0 ? 3 : isff_ok ? 0 : 1;
}

// Tables 6.3, 6.5, 6.6 and Fig. 6.3.
void PrintThesisTables(Evaluator& ev) {
  // Table 6.3
  const char* t63[] = {"wedge", "chamfer", "cutter"};
  struct M {
    IlluminationMode mode;
    int hdr;
  };
  const M methods[] = {{IlluminationMode::kStd, 3},     {IlluminationMode::kHdr, 2},
                       {IlluminationMode::kHdr, 3},     {IlluminationMode::kHdr, 4},
                       {IlluminationMode::kHdr, 5},     {IlluminationMode::kAdaptIterative, 3},
                       {IlluminationMode::kAdapt, 3},   {IlluminationMode::kTexture, 3},
                       {IlluminationMode::kHfAdapt, 3}, {IlluminationMode::kAdaptedHf, 3}};
  std::vector<std::vector<Run>> runs(std::size(methods), std::vector<Run>(std::size(t63)));
  for (size_t mi = 0; mi < std::size(methods); ++mi) {
    IlluminationParams p;
    p.hdr_exposures = methods[mi].hdr;
    for (size_t k = 0; k < std::size(t63); ++k) runs[mi][k] = ev.Scan(t63[k], methods[mi].mode, p);
  }
  // Common footprint: a method that leaves the hard pixels without depth is not rewarded for it.
  // The footprint is that of the thesis's methods HDR-n, ADAPT-IT and ADAPT; STD is left out:
  // it fails where the specimen saturates, which its own sigma shows.
  std::vector<cv::Mat> common(std::size(t63));
  for (size_t k = 0; k < std::size(t63); ++k) {
    for (size_t mi = 0; mi < std::size(methods); ++mi) {
      const Run& r = runs[mi][k];
      const IlluminationMode m = methods[mi].mode;
      if (!r.ok ||
          !(m == IlluminationMode::kHdr || m == IlluminationMode::kAdapt || m == IlluminationMode::kAdaptIterative)) {
        continue;
      }
      const cv::Mat finite = r.depth_um == r.depth_um;
      common[k] = common[k].empty() ? finite : (common[k] & finite);
    }
  }
  std::printf(
      "Table 6.3: depth error against ground truth [um] as sigma, bias (mean signed error) and RMSE, over the "
      "method's own measured pixels and over the pixels every HDR and ADAPT method measured (common); "
      "number of images; valid %% of pixels\n");
  for (size_t k = 0; k < std::size(t63); ++k) {
    std::printf("%-10s | own:  sigma    bias   RMSE | common: sigma    bias   RMSE | #imgs  valid\n", t63[k]);
    for (size_t mi = 0; mi < std::size(methods); ++mi) {
      if (methods[mi].mode == IlluminationMode::kTexture) {
        std::printf("(beyond the thesis's table: the texture modes on the same specimen)\n");
      }
      std::printf("%-10s", IlluminationModeName(methods[mi].mode, methods[mi].hdr).c_str());
      const Run& r = runs[mi][k];
      if (!r.ok || common[k].empty()) {
        std::printf(" | failed\n");
        continue;
      }
      const DepthErrorStats c = CompareDepth(r.depth_um, r.truth_um, common[k], r.outlier_threshold_um, kWindowPx);
      std::printf(" | %s | %s | %5d %5.1f%%\n", ErrorCells(r.error).c_str(), ErrorCells(c).c_str(), r.images,
                  r.error.valid_percent);
    }
    std::printf("\n");
  }
  std::fflush(stdout);

  // Table 6.5
  std::printf(
      "Table 6.5: STD vs TEXTURE on low-texture specimens, sigma, bias, RMSE [um] (valid %%), 2.5 um steps; "
      "n.m. = not measurable (< 50 %% valid)\n");
  std::printf("%-10s | %-31s | %-31s\n", "Specimen", "STD", "TEXTURE");
  for (const char* s : {"lens", "mirror"}) {
    Run a = ev.Scan(s, IlluminationMode::kStd, {}, 2.5);
    Run b = ev.Scan(s, IlluminationMode::kTexture, {}, 2.5);
    auto cell = [](const Run& r) {
      char buf[64];
      if (!r.ok) return std::string("failed");
      if (r.error.valid_percent < 50)
        std::snprintf(buf, sizeof(buf), "n.m.                   (%5.1f%%)", r.error.valid_percent);
      else
        std::snprintf(buf, sizeof(buf), "%s (%5.1f%%)", ErrorCells(r.error).c_str(), r.error.valid_percent);
      return std::string(buf);
    };
    std::printf("%-10s | %-31s | %-31s\n", s, cell(a).c_str(), cell(b).c_str());
  }

  // Table 6.6
  std::printf(
      "\nTable 6.6: outliers on the coin [%% of measured pixels]: |error| > 2 z steps against the truth, "
      "and the thesis's reference-free measure (depth > 2 z steps off the median of the 8 neighbours); "
      "valid %%, images; depth error sigma, bias, RMSE [um]\n");
  std::printf("%-10s %9s %9s %7s %6s  %6s %7s %6s\n", "Method", "vs truth", "local", "valid", "#imgs", "sigma", "bias",
              "RMSE");
  for (IlluminationMode m : {IlluminationMode::kStd, IlluminationMode::kAdapt, IlluminationMode::kTexture,
                             IlluminationMode::kHfAdapt, IlluminationMode::kAdaptedHf}) {
    Run r = ev.Scan("coin", m, {});
    if (r.ok) {
      std::printf("%-10s %7.2f %% %7.2f %% %6.1f%% %6d  %s\n", IlluminationModeName(m).c_str(), r.error.outlier_percent,
                  LocalOutlierPercent(r.depth_um, r.outlier_threshold_um, kWindowPx), r.error.valid_percent, r.images,
                  ErrorCells(r.error).c_str());
    } else {
      std::printf("%-10s failed\n", IlluminationModeName(m).c_str());
    }
  }

  // Fig. 6.3
  std::printf(
      "\nFig. 6.3: cutter, mean / standard deviation of the grey image (8-bit units) and saturated %% "
      "over the first captures (ADAPT: 2 initialisation frames first; ADAPT-IT: every iteration)\n");
  Run s = ev.Scan("cutter", IlluminationMode::kStd, {});
  Run it = ev.Scan("cutter", IlluminationMode::kAdaptIterative, {});
  Run ad = ev.Scan("cutter", IlluminationMode::kAdapt, {});
  std::printf("%-7s | %-22s | %-22s | %-22s\n", "capture", "STD", "ADAPT-IT", "ADAPT");
  for (size_t k = 0; k < 8; ++k) {
    auto cell = [&](const Run& r) {
      char buf[64];
      if (k >= r.captures.size()) return std::string("-");
      const FrameStatistics& f = r.captures[k];
      std::snprintf(buf, sizeof(buf), "%6.1f %5.1f %5.1f%%", f.mean_grey, f.stddev_grey, f.saturated_percent);
      return std::string(buf);
    };
    std::printf("%-7zu | %-22s | %-22s | %-22s\n", k, cell(s).c_str(), cell(it).c_str(), cell(ad).c_str());
  }
}

// Every built-in specimen (or those given) with every mode (or those given) at its default scan,
// as a user would start it. Returns the number of bias bound violations.
int PrintBiasTable(Evaluator& ev, const std::vector<std::string>& specimens,
                   const std::vector<IlluminationMode>& modes, int repeats) {
  std::printf(
      "\nBias: every specimen with every mode at its default scan (5 um steps); sigma, bias, RMSE "
      "[um]; the bound |bias| <= max(0.1 um, 0.02 z steps) applies where the mode measures >= 95 %% of pixels\n");
  if (repeats > 1) {
    std::printf(
        "%d scans per row (consecutive, the rig's noise and stage repeatability drawn anew): sigma, bias, RMSE, "
        "valid are means over the scans; bias sd = scan-to-scan spread of the bias; worst = largest single-scan "
        "|bias|; the bound applies to the mean bias (the systematic part)\n",
        repeats);
  }
  std::printf("%-13s %-10s  %6s %7s %6s %7s %6s %s %s\n", "Specimen", "Method", "sigma", "bias", "RMSE", "valid",
              "#imgs", repeats > 1 ? "bias-sd  worst " : "", "bound");
  int violations = 0;
  std::vector<std::string> auto_rows, default_rows;
  for (const std::string& specimen_id : specimens) {
    const std::string specimen = SpecimenLabel(specimen_id);
    // AUTO against the best single mode: the lowest RMSE among modes measuring >= 95 % (else the
    // highest coverage), and its frames against STD's.
    const Run* best = nullptr;
    std::string best_name;
    int std_images = 0;
    std::vector<Run> runs;
    runs.reserve(modes.size());
    for (IlluminationMode m : modes) {
      std::vector<Run> repeated;
      for (int k = 0; k < repeats; ++k) repeated.push_back(ev.Scan(specimen_id, m, {}));
      runs.push_back(Aggregate(std::move(repeated)));
      Run& r = runs.back();
      if (!r.ok) {
        std::printf("%-13s %-10s  failed\n", specimen.c_str(), IlluminationModeName(m).c_str());
        continue;
      }
      if (m == IlluminationMode::kStd) std_images = r.images;
      if (m != IlluminationMode::kAuto) {
        const bool full = r.error.valid_percent >= 95.0;
        const bool best_full = best && best->error.valid_percent >= 95.0;
        if (!best || (full && (!best_full || r.error.rmse_um < best->error.rmse_um)) ||
            (!full && !best_full && r.error.valid_percent > best->error.valid_percent)) {
          best = &r;
          best_name = IlluminationModeName(m);
        }
      } else if (best) {
        char row[400];
        std::snprintf(row, sizeof(row),
                      "%-13s %-10s RMSE %6.3f valid %5.1f%% | best %-10s RMSE %6.3f valid %5.1f%% | "
                      "ratio %.2f | frames %d (STD %d) | %s",
                      specimen.c_str(), r.chosen.c_str(), r.error.rmse_um, r.error.valid_percent, best_name.c_str(),
                      best->error.rmse_um, best->error.valid_percent, r.error.rmse_um / best->error.rmse_um, r.images,
                      std_images, r.decision.c_str());
        auto_rows.push_back(row);
      }
      const char* verdict = "-";
      if (r.error.valid_percent >= 95.0) {
        const bool within = std::abs(r.error.mean_error_um) <= BiasBoundUm(r.z_step_um);
        verdict = within ? "ok" : "EXCEEDED";
        violations += !within;
      }
      char spread[48] = "";
      if (repeats > 1) std::snprintf(spread, sizeof(spread), " %6.3f %+7.3f", r.bias_sd_um, r.worst_scan_bias_um);
      std::printf("%-13s %-10s  %s %6.1f%% %6d%s  %s%s\n", specimen.c_str(), IlluminationModeName(m).c_str(),
                  ErrorCells(r.error).c_str(), r.error.valid_percent, r.images, spread, verdict,
                  m == IlluminationMode::kAuto ? (" (ran " + r.chosen + ")").c_str() : "");
    }
    // The default (AUTO) against STD and TEXTURE, the two modes without compensation: RMSE on each
    // one's own pixels and on the pixels both measured (scan k against scan k), which is what
    // makes a mode that measures more (e.g. the coin's dark relief) comparable.
    const Run *std_run = nullptr, *tex_run = nullptr, *auto_run = nullptr;
    for (size_t i = 0; i < runs.size(); ++i) {
      if (!runs[i].ok) continue;
      if (modes[i] == IlluminationMode::kStd) std_run = &runs[i];
      if (modes[i] == IlluminationMode::kTexture) tex_run = &runs[i];
      if (modes[i] == IlluminationMode::kAuto) auto_run = &runs[i];
    }
    if (auto_run && std_run && tex_run) {
      auto common_rmse = [&](const Run& a, const Run& b, double* a_rmse, double* b_rmse, double* share) {
        *a_rmse = *b_rmse = *share = 0;
        const size_t n = std::min(a.scan_depths_um.size(), b.scan_depths_um.size());
        for (size_t k = 0; k < n; ++k) {
          const cv::Mat both = (a.scan_depths_um[k] == a.scan_depths_um[k]) & (b.scan_depths_um[k] == b.scan_depths_um[k]);
          *a_rmse += CompareDepth(a.scan_depths_um[k], a.truth_um, both, a.outlier_threshold_um, kWindowPx).rmse_um / n;
          *b_rmse += CompareDepth(b.scan_depths_um[k], b.truth_um, both, b.outlier_threshold_um, kWindowPx).rmse_um / n;
          *share += 100.0 * cv::countNonZero(both) / double(both.total()) / n;
        }
      };
      char row[400];
      double a1, s1, c1, a2, t2, c2;
      common_rmse(*auto_run, *std_run, &a1, &s1, &c1);
      common_rmse(*auto_run, *tex_run, &a2, &t2, &c2);
      const double own_better = std::min(std_run->error.rmse_um, tex_run->error.rmse_um);
      std::snprintf(row, sizeof(row),
                    "%-13s AUTO(%s) %6.3f | own: STD %6.3f (%5.1f%%) TEXTURE %6.3f (%5.1f%%) ratio %.2f | "
                    "common with STD (%5.1f%%): %6.3f vs %6.3f ratio %.2f | with TEXTURE (%5.1f%%): %6.3f vs %6.3f "
                    "ratio %.2f",
                    specimen.c_str(), auto_run->chosen.c_str(), auto_run->error.rmse_um, std_run->error.rmse_um,
                    std_run->error.valid_percent, tex_run->error.rmse_um, tex_run->error.valid_percent,
                    auto_run->error.rmse_um / own_better, c1, a1, s1, a1 / s1, c2, a2, t2, a2 / t2);
      default_rows.push_back(row);
    }
  }
  std::printf("bias bound exceeded: %d\n", violations);
  if (!auto_rows.empty()) {
    std::printf(
        "\nAUTO against the best single mode per specimen (lowest RMSE among modes measuring >= 95 %%, AUTO run "
        "last), frames against STD's\n");
    for (const std::string& row : auto_rows) std::printf("%s\n", row.c_str());
  }
  if (!default_rows.empty()) {
    std::printf(
        "\nThe default (AUTO) against STD and TEXTURE: RMSE [um] on each mode's own pixels (valid %%), and on the "
        "pixels both measured (share of the image); target: ratio <= 1.10 against the better of the two, and on "
        "saturating specimens clearly below STD\n");
    for (const std::string& row : default_rows) std::printf("%s\n", row.c_str());
  }
  std::fflush(stdout);
  return violations;
}

}  // namespace
}  // namespace inspection

int main(int argc, char** argv) {
  // The natural-scene evaluation has its own options; argv[1] stands in for the program name.
  if (argc >= 2 && std::string(argv[1]) == "--natural") return inspection::RunNaturalEvaluation(argc - 1, argv + 1);
  return inspection::Main(argc, argv);
}
