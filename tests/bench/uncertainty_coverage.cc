// Uncertainty coverage on the simulated rig: does the expanded uncertainty (k = 2) of
// every measurement cover >= 95 % of its deviations from the truth over repeated scans?
// Scans each specimen with different seeds (texture, camera noise, stage errors differ), measures
// it through core/metrology/measurement.h with the error model of core/metrology/depth_noise_model.h, and compares
// with the same measurement on the ground-truth depth map. The rig's z linearity is characterised
// first, once, on a scan of the SKEW10 plane with a seed no test scan uses (as a real rig would be
// on a tilted optical flat). Prints per specimen and measurement: bias and sigma of the
// deviations, mean U, coverage; then the coverage per parameter and overall, also with the
// uncharacterised linearity bound for comparison.
//
//   uncertainty-coverage [--seeds N] [--camera WxH] [--samples N] [--first-seed N] [--z-step UM] [--cal-step UM]
//                        [--scenes tuning|heldout|all] [--components] [--only NAME] [--residual-profile]
//                        [--na NA] [--window PX] [--gaussian] [--prior-lz SHARE] [--z-offset UM] [--dump FILE]
// --dump writes one line per measured value (tab-separated: camera, z step, seed, specimen, label,
// deviation, U, uncharacterised deviation, U; U = 2u) for pooling runs (tests/bench/pool_coverage.py).
// --na, --window and --gaussian change the instrument (objective NA: the focus curve's width per um;
// the SFF focus window; the Gaussian three-point fit instead of the defocus parabola), for checking
// the uncharacterised linearity prior on instruments whose interpolation error is larger.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>
#include <vector>

#include "core/metrology/measurement.h"
#include "core/metrology/z_linearity.h"
#include "devices/sim/simulated_rig.h"
#include "server/procedures/scan_procedure.h"
#include "tests/lib/user_scene.h"

namespace fs = std::filesystem;
using namespace inspection;

namespace {

constexpr double kPi = 3.14159265358979323846;

struct Args {
  int seeds = 20;
  int first_seed = 1;  // held-out sets start elsewhere (tuning used 1..)
  cv::Size camera{256, 192};
  int samples = 32;
  std::string only;          // run only specimens whose short name contains this
  bool residual_profile = false;  // print the mean depth error against the true height per specimen
  bool components = false;        // print the mean budget components per specimen and measurement
  double z_step_um = 0.0;         // scans' z step (0 = the rig's default)
  double cal_step_um = 0.0;       // z step of the linearity characterisation (0 = the rig's default)
  // "tuning": the six specimens the model was tuned on; "heldout": other scenes (steps of several
  // heights on tilted planes, sinusoids of other amplitudes and periods, other sphere and
  // cylinder radii, random rough surfaces), never looked at while tuning; "all": both.
  std::string scene_set = "tuning";
  double numerical_aperture = 0.0;  // 0 = the rig's default
  int window_px = 0;                // 0 = the SFF default
  bool gaussian = false;            // DepthInterpolation::kGaussian instead of the default
  // > 0: the uncharacterised runs bound the linearity by +-this share of the scan's step (as a
  // verified l_z does), to see whether a narrower prior than the analytic one would still cover.
  double prior_lz_of_step = 0.0;
  // Test scans' specimen height offset (um): moves the specimens' heights against the z grid, i.e.
  // the phase of the z linearity (the calibration scan keeps 0).
  double z_offset_um = 0.0;
  std::string dump;  // per-value rows (see the header)
};

struct Case {
  std::string specimen;                                        // built-in or file: scene
  std::vector<std::pair<std::string, MeasurementSpec>> specs;  // label, spec
};

struct Scan {
  cv::Mat depth_um, truth_um;
  std::vector<double> z_um;
  int window_px = 7;
};

// z_step_um 0 = the rig's default step.
StatusOr<Scan> ScanOnce(Rig& rig, const std::string& specimen, const fs::path& work, const Args& a,
                        double z_step_um = 0.0) {
  INSPECT_RETURN_IF_ERROR(rig.simulation()->SetSpecimen(specimen));
  const ScanDefaults d = rig.scan_defaults();
  const double step = z_step_um > 0.0 ? z_step_um : d.z_step_um;
  INSPECT_ASSIGN_OR_RETURN(ScanPlan plan, MakeScanPlan(d.z_start_um, d.z_end_um, step, d.exposure_us, rig.stage()));
  if (a.window_px > 0) plan.sff.window_px = a.window_px;
  if (a.gaussian) plan.sff.interpolation = DepthInterpolation::kGaussian;
  std::atomic<bool> cancel{false};
  const fs::path dir = work / "stack";
  std::error_code ec;
  fs::remove_all(dir, ec);
  INSPECT_ASSIGN_OR_RETURN(ScanOutcome out, RunScan(rig, plan, dir, nullptr, cancel));
  fs::remove_all(dir, ec);
  return Scan{out.depth.depth_um, out.ground_truth_um, plan.z_um, plan.sff.window_px};
}

MeasurementSpec Spec(MeasurementKind kind, RegionOfInterest roi) {
  MeasurementSpec s;
  s.kind = kind;
  s.roi = roi;
  return s;
}

std::vector<Case> TuningCases(const Args& a, const fs::path& work, double px, int border) {
  const int w = a.camera.width, h = a.camera.height, b = border;
  const RegionOfInterest inner = RegionOfInterest::Rectangle(b, b, w - 2 * b, h - 2 * b);
  std::vector<Case> cases;
  {
    Case c{"plane", {}};
    for (MeasurementKind k : {MeasurementKind::kSa, MeasurementKind::kSq, MeasurementKind::kSp, MeasurementKind::kSv,
                              MeasurementKind::kSz, MeasurementKind::kFlatness, MeasurementKind::kTilt}) {
      c.specs.push_back({MeasurementKindName(k), Spec(k, inner)});
    }
    cases.push_back(c);
  }
  {
    Case c{"skew5", {}};
    for (MeasurementKind k : {MeasurementKind::kTilt, MeasurementKind::kFlatness, MeasurementKind::kSq}) {
      c.specs.push_back({MeasurementKindName(k), Spec(k, inner)});
    }
    cases.push_back(c);
  }
  {
    // The 1 um step runs down the image centre; 12 px either side are left out (the focus window
    // straddles the edge there), as ISO 5436-1 leaves out the edge zones.
    Case c{"step1um", {}};
    const RegionOfInterest left = RegionOfInterest::Rectangle(b, b, w / 2 - 12 - b, h - 2 * b);
    const RegionOfInterest right = RegionOfInterest::Rectangle(w / 2 + 12, b, w / 2 - 12 - b, h - 2 * b);
    MeasurementSpec step = Spec(MeasurementKind::kStepHeight, right);
    step.reference_roi = left;
    c.specs.push_back({"step_height", step});
    MeasurementSpec sep = step;
    sep.step.fit = StepHeightFit::kSeparatePlanes;
    c.specs.push_back({"step_height(sep)", sep});
    c.specs.push_back({"Sa", Spec(MeasurementKind::kSa, left)});
    cases.push_back(c);
  }
  {
    // 2 um cosine, 4 periods across the field, along x; the region holds 3 whole periods.
    const double lambda_px = w / 4.0;
    const std::string scene = test_scenes::WriteUserScene(
        work / "scenes", "cosine", a.camera, px,
        [&](double x, double) { return 210.0 + 2.0 * std::cos(2 * kPi * x / (lambda_px * px)); }, 101);
    Case c{scene, {}};
    const RegionOfInterest periods = RegionOfInterest::Rectangle(lambda_px / 2, b, 3 * lambda_px, h - 2 * b);
    for (MeasurementKind k : {MeasurementKind::kSa, MeasurementKind::kSq, MeasurementKind::kSp, MeasurementKind::kSv,
                              MeasurementKind::kSz, MeasurementKind::kSsk, MeasurementKind::kSku}) {
      c.specs.push_back({MeasurementKindName(k), Spec(k, periods)});
    }
    cases.push_back(c);
  }
  {
    // Convex sphere cap (lens), R = 8 fields, and a cylinder (axis along y), R = 4 fields.
    const double field = w * px, rs = 8 * field, cx = 0.5 * w * px, cy = 0.5 * h * px;
    const std::string sphere = test_scenes::WriteUserScene(
        work / "scenes", "sphere", a.camera, px,
        [&](double x, double y) {
          return 200.0 + std::sqrt(rs * rs - (x - cx) * (x - cx) - (y - cy) * (y - cy)) - (rs - 12.0);
        },
        102);
    Case c{sphere, {}};
    c.specs.push_back({"radius", Spec(MeasurementKind::kRadius, inner)});
    MeasurementSpec vol = Spec(MeasurementKind::kVolumeAbove, inner);
    vol.volume.reference = VolumeReference::kHeight;
    vol.volume.reference_height_um = 209.0;  // the cap's top 3 um
    c.specs.push_back({"volume_above", vol});
    cases.push_back(c);
    const double rc = 4 * field;
    const std::string cyl = test_scenes::WriteUserScene(
        work / "scenes", "cylinder", a.camera, px,
        [&](double x, double) { return 200.0 + std::sqrt(rc * rc - (x - cx) * (x - cx)) - (rc - 12.0); }, 103);
    Case k{cyl, {}};
    MeasurementSpec r = Spec(MeasurementKind::kRadius, inner);
    r.form.model = FormModel::kCylinder;
    k.specs.push_back({"radius", r});
    cases.push_back(k);
  }
  return cases;
}

// Scenes of the held-out set (not used while tuning the model).
std::vector<Case> HeldOutCases(const Args& a, const fs::path& work, double px, int border) {
  const int w = a.camera.width, h = a.camera.height, b = border;
  const double field = w * px, cx = 0.5 * w * px, cy = 0.5 * h * px;
  const RegionOfInterest inner = RegionOfInterest::Rectangle(b, b, w - 2 * b, h - 2 * b);
  std::vector<Case> cases;
  // Steps of 0.5 and 3 um on planes tilted 0.2 deg along x and 0.15 deg along y.
  for (const double height : {0.5, 3.0}) {
    const double sx = std::tan(0.2 * kPi / 180.0), sy = std::tan(0.15 * kPi / 180.0);
    char name[32];
    std::snprintf(name, sizeof name, "tstep%02d", int(std::lround(height * 10)));
    const std::string scene = test_scenes::WriteUserScene(
        work / "scenes", name, a.camera, px,
        [&](double x, double y) { return 204.0 + sx * (x - cx) + sy * (y - cy) + (x > cx ? height : 0.0); },
        201 + unsigned(height * 10));
    Case c{scene, {}};
    const RegionOfInterest left = RegionOfInterest::Rectangle(b, b, w / 2 - 12 - b, h - 2 * b);
    const RegionOfInterest right = RegionOfInterest::Rectangle(w / 2 + 12, b, w / 2 - 12 - b, h - 2 * b);
    MeasurementSpec step = Spec(MeasurementKind::kStepHeight, right);
    step.reference_roi = left;
    c.specs.push_back({"step_height", step});
    MeasurementSpec sep = step;
    sep.step.fit = StepHeightFit::kSeparatePlanes;
    c.specs.push_back({"step_height(sep)", sep});
    c.specs.push_back({"Sa", Spec(MeasurementKind::kSa, right)});
    c.specs.push_back({"Sq", Spec(MeasurementKind::kSq, left)});
    c.specs.push_back({"tilt", Spec(MeasurementKind::kTilt, left)});
    cases.push_back(c);
  }
  // Sinusoids: 0.7 um amplitude, 3 periods along y; 3 um amplitude, 6 periods along x.
  struct Sine {
    const char* name;
    double amplitude_um, periods;
    bool along_x;
  };
  for (const Sine& sine : {Sine{"sine07y", 0.7, 3.0, false}, Sine{"sine3x", 3.0, 6.0, true}}) {
    const double lambda_px = (sine.along_x ? w : h) / sine.periods;
    const std::string scene = test_scenes::WriteUserScene(
        work / "scenes", sine.name, a.camera, px,
        [&](double x, double y) {
          return 206.0 + sine.amplitude_um * std::sin(2 * kPi * (sine.along_x ? x : y) / (lambda_px * px));
        },
        211 + unsigned(sine.periods));
    Case c{scene, {}};
    const int whole = int(std::floor((sine.along_x ? w - 2 * b : h - 2 * b) / lambda_px)) * int(std::lround(lambda_px));
    const RegionOfInterest periods = sine.along_x ? RegionOfInterest::Rectangle(b, b, whole, h - 2 * b)
                                                  : RegionOfInterest::Rectangle(b, b, w - 2 * b, whole);
    for (MeasurementKind k : {MeasurementKind::kSa, MeasurementKind::kSq, MeasurementKind::kSz, MeasurementKind::kSsk,
                              MeasurementKind::kSku}) {
      c.specs.push_back({MeasurementKindName(k), Spec(k, periods)});
    }
    cases.push_back(c);
  }
  // Sphere R = 5 fields (concave: a bowl), cylinder R = 6 fields with its axis along x.
  {
    const double rs = 5 * field;
    const std::string sphere = test_scenes::WriteUserScene(
        work / "scenes", "bowl", a.camera, px,
        [&](double x, double y) {
          return 200.0 - std::sqrt(rs * rs - (x - cx) * (x - cx) - (y - cy) * (y - cy)) + rs;
        },
        221);
    Case c{sphere, {}};
    c.specs.push_back({"radius", Spec(MeasurementKind::kRadius, inner)});
    cases.push_back(c);
    const double rc = 6 * field;
    const std::string cyl = test_scenes::WriteUserScene(
        work / "scenes", "cylx", a.camera, px,
        [&](double, double y) { return 200.0 + std::sqrt(rc * rc - (y - cy) * (y - cy)) - (rc - 10.0); }, 222);
    Case k{cyl, {}};
    MeasurementSpec r = Spec(MeasurementKind::kRadius, inner);
    r.form.model = FormModel::kCylinder;
    k.specs.push_back({"radius", r});
    cases.push_back(k);
  }
  // Random rough surfaces: 24 cosines of random direction, wavelength 20..90 px and phase, Sq
  // ~0.6 and ~1.5 um; Sa..Sku against the same measurement on the truth over the same region.
  for (const double sq_um : {0.6, 1.5}) {
    std::mt19937_64 rng(unsigned(1000 * sq_um) + 77);
    std::uniform_real_distribution<double> angle(0.0, kPi), wl(20.0, 90.0), phase(0.0, 2 * kPi);
    struct Wave {
      double kx, ky, ph, amp;
    };
    std::vector<Wave> waves;
    for (int i = 0; i < 24; ++i) {
      const double t = angle(rng), l = wl(rng) * px;
      waves.push_back({2 * kPi * std::cos(t) / l, 2 * kPi * std::sin(t) / l, phase(rng), sq_um * std::sqrt(2.0 / 24.0)});
    }
    char name[32];
    std::snprintf(name, sizeof name, "rough%02d", int(std::lround(sq_um * 10)));
    const std::string scene = test_scenes::WriteUserScene(
        work / "scenes", name, a.camera, px,
        [&](double x, double y) {
          double z = 206.0;
          for (const Wave& v : waves) z += v.amp * std::cos(v.kx * x + v.ky * y + v.ph);
          return z;
        },
        231 + unsigned(sq_um * 10));
    Case c{scene, {}};
    for (MeasurementKind k : {MeasurementKind::kSa, MeasurementKind::kSq, MeasurementKind::kSsk, MeasurementKind::kSku,
                              MeasurementKind::kSz}) {
      c.specs.push_back({MeasurementKindName(k), Spec(k, inner)});
    }
    cases.push_back(c);
  }
  return cases;
}

std::vector<Case> Cases(const Args& a, const fs::path& work, double px, int border) {
  std::vector<Case> out;
  if (a.scene_set == "tuning" || a.scene_set == "all") out = TuningCases(a, work, px, border);
  if (a.scene_set == "heldout" || a.scene_set == "all") {
    std::vector<Case> h = HeldOutCases(a, work, px, border);
    out.insert(out.end(), h.begin(), h.end());
  }
  return out;
}

struct Tally {
  std::vector<double> dev, u;
  void Add(double d, double uu) {
    dev.push_back(d);
    u.push_back(uu);
  }
  int Covered() const {
    int n = 0;
    for (size_t i = 0; i < dev.size(); ++i) n += std::abs(dev[i]) <= 2.0 * u[i];
    return n;
  }
};

std::string Short(const std::string& specimen) {
  const size_t slash = specimen.find_last_of('/');
  if (slash == std::string::npos) return specimen;
  std::string s = specimen.substr(slash + 1);
  return s.substr(0, s.find('.'));
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--seeds" && i + 1 < argc)
      a.seeds = std::atoi(argv[++i]);
    else if (arg == "--samples" && i + 1 < argc)
      a.samples = std::atoi(argv[++i]);
    else if (arg == "--only" && i + 1 < argc)
      a.only = argv[++i];
    else if (arg == "--first-seed" && i + 1 < argc)
      a.first_seed = std::atoi(argv[++i]);
    else if (arg == "--z-step" && i + 1 < argc)
      a.z_step_um = std::atof(argv[++i]);
    else if (arg == "--cal-step" && i + 1 < argc)
      a.cal_step_um = std::atof(argv[++i]);
    else if (arg == "--residual-profile")
      a.residual_profile = true;
    else if (arg == "--scenes" && i + 1 < argc)
      a.scene_set = argv[++i];
    else if (arg == "--components")
      a.components = true;
    else if (arg == "--na" && i + 1 < argc)
      a.numerical_aperture = std::atof(argv[++i]);
    else if (arg == "--window" && i + 1 < argc)
      a.window_px = std::atoi(argv[++i]);
    else if (arg == "--gaussian")
      a.gaussian = true;
    else if (arg == "--z-offset" && i + 1 < argc)
      a.z_offset_um = std::atof(argv[++i]);
    else if (arg == "--dump" && i + 1 < argc)
      a.dump = argv[++i];
    else if (arg == "--prior-lz" && i + 1 < argc)
      a.prior_lz_of_step = std::atof(argv[++i]);
    else if (arg == "--camera" && i + 1 < argc &&
             std::sscanf(argv[++i], "%dx%d", &a.camera.width, &a.camera.height) == 2) {
    } else {
      std::fprintf(stderr, "usage: uncertainty-coverage [--seeds N] [--camera WxH] [--samples N] [--first-seed N] [--z-step UM] [--cal-step UM] [--scenes tuning|heldout|all] [--components] [--only NAME] [--residual-profile] [--na NA] [--window PX] [--gaussian] [--prior-lz SHARE] [--z-offset UM] [--dump FILE]\n");
      return 2;
    }
  }
  const fs::path work = fs::temp_directory_path() / ("uncertainty_coverage_" + std::to_string(::getpid()));
  fs::create_directories(work);
  SimulatedRigOptions rig_options;
  rig_options.camera_size = a.camera;
  if (a.numerical_aperture > 0.0) rig_options.numerical_aperture = a.numerical_aperture;
  const double px = rig_options.pixel_size_um;

  // 1. Characterise the z linearity on SKEW10 (seed 100000: not a test seed).
  rig_options.seed = 100000;
  rig_options.specimen = "skew10";
  auto cal_rig = CreateSimulatedRig(rig_options);
  if (!cal_rig.ok()) {
    std::fprintf(stderr, "%s\n", cal_rig.status().ToString().c_str());
    return 1;
  }
  auto cal = ScanOnce(**cal_rig, "skew10", work, a, a.cal_step_um);
  if (!cal.ok()) {
    std::fprintf(stderr, "calibration scan: %s\n", cal.status().ToString().c_str());
    return 1;
  }
  const int border = cal->window_px + 1;
  cv::Mat inner(a.camera, CV_8UC1, cv::Scalar(0));
  inner(cv::Rect(border, border, a.camera.width - 2 * border, a.camera.height - 2 * border)).setTo(255);
  auto linearity = CharacteriseZLinearity(cal->depth_um, inner, px, *ZGrid::Create(cal->z_um));
  if (!linearity.ok()) {
    std::fprintf(stderr, "z linearity: %s\n", linearity.status().ToString().c_str());
    return 1;
  }
  std::printf(
      "z linearity (SKEW10, seed 100000, %dx%d): max %.4f, rms %.4f of the step (%.3f / %.3f um at %.1f um)\n  table:",
      a.camera.width, a.camera.height, linearity->MaxAbs(), linearity->Rms(),
      linearity->MaxAbs() * linearity->characterised_step_um, linearity->Rms() * linearity->characterised_step_um,
      linearity->characterised_step_um);
  for (double v : linearity->bias_of_step) std::printf(" %+.3f", v);
  std::printf("\n\n");

  // 2. Repeated scans of each specimen.
  std::vector<Case> cases = Cases(a, work, px, border);
  if (!a.only.empty()) {
    std::erase_if(cases, [&](const Case& c) { return Short(c.specimen).find(a.only) == std::string::npos; });
  }
  // Mean depth error per bin of the true height (relative to the specimen's inner range): the
  // signature of the SFF's systematic errors (e.g. peaks against valleys of a cosine).
  constexpr int kProfileBins = 16;
  std::map<std::string, std::vector<std::pair<double, int>>> profile;  // specimen -> (sum, n) per bin
  std::map<std::string, std::pair<double, double>> profile_range;
  std::map<std::string, Tally> by_case, by_case_unchar;  // "specimen|label"
  std::map<std::string, std::string> truth_of;
  // Mean of each budget component (k = 1) per case: random, linearity, stage, other, MC spread,
  // |noise bias|, height-dependent, |estimated systematic| (NaN components count as 0).
  std::map<std::string, std::array<double, 8>> components;
  std::FILE* dump = a.dump.empty() ? nullptr : std::fopen(a.dump.c_str(), "w");
  if (!a.dump.empty() && dump == nullptr) {
    std::fprintf(stderr, "cannot write %s\n", a.dump.c_str());
    return 2;
  }
  double scan_s = 0, measure_s = 0;
  int scans = 0, failures = 0;
  for (int seed = a.first_seed; seed < a.first_seed + a.seeds; ++seed) {
    rig_options.seed = uint64_t(seed);
    rig_options.specimen = "plane";
    auto rig = CreateSimulatedRig(rig_options);
    if (!rig.ok()) return 1;
    if (a.z_offset_um != 0.0 && !(*rig)->simulation()->SetSpecimenZOffsetUm(a.z_offset_um).ok()) return 1;
    for (const Case& c : cases) {
      const auto t0 = std::chrono::steady_clock::now();
      auto scan = ScanOnce(**rig, c.specimen, work, a, a.z_step_um);
      const auto t1 = std::chrono::steady_clock::now();
      if (!scan.ok()) {
        std::fprintf(stderr, "%s seed %d: %s\n", Short(c.specimen).c_str(), seed, scan.status().ToString().c_str());
        return 1;
      }
      ++scans;
      scan_s += std::chrono::duration<double>(t1 - t0).count();
      if (a.residual_profile) {
        const cv::Rect in(border, border, a.camera.width - 2 * border, a.camera.height - 2 * border);
        double lo, hi;
        cv::minMaxLoc(scan->truth_um(in), &lo, &hi);
        auto& bins = profile[Short(c.specimen)];
        bins.resize(kProfileBins);
        profile_range[Short(c.specimen)] = {lo, hi};
        for (int r = in.y; r < in.y + in.height; ++r)
          for (int col = in.x; col < in.x + in.width; ++col) {
            const double d = scan->depth_um.at<float>(r, col), t = scan->truth_um.at<float>(r, col);
            if (!std::isfinite(d) || !std::isfinite(t) || !(hi > lo)) continue;
            const int b = std::clamp(int((t - lo) / (hi - lo) * kProfileBins), 0, kProfileBins - 1);
            bins[b].first += d - t;
            bins[b].second += 1;
          }
      }
      std::vector<MeasurementSpec> specs;
      for (const auto& s : c.specs) specs.push_back(s.second);
      MeasurementContext ctx;
      ctx.depth_um = scan->depth_um;
      ctx.pixel_size_um = px;
      ctx.noise.window_px = scan->window_px;
      ctx.noise.z_positions_um = scan->z_um;
      ctx.noise.linearity = *linearity;
      ctx.noise.stage_repeatability_um = rig_options.stage_repeatability_um;
      ctx.monte_carlo.samples = a.samples;
      const auto t2 = std::chrono::steady_clock::now();
      const auto measured = MeasureAll(specs, ctx);
      measure_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t2).count();
      MeasurementContext unchar = ctx;
      unchar.noise.linearity = ZLinearity::Uncharacterised();
      if (a.prior_lz_of_step > 0.0 && scan->z_um.size() >= 2) {
        unchar.noise.verified.linearity_deviation_um = a.prior_lz_of_step * std::abs(scan->z_um[1] - scan->z_um[0]);
      }
      const auto measured_unchar = MeasureAll(specs, unchar);
      MeasurementContext truth_ctx = ctx;
      truth_ctx.depth_um = scan->truth_um;
      truth_ctx.with_uncertainty = false;
      const auto truth = MeasureAll(specs, truth_ctx);
      for (size_t i = 0; i < specs.size(); ++i) {
        const std::string key = Short(c.specimen) + "|" + c.specs[i].first;
        if (!measured[i].ok() || !truth[i].ok() || !measured_unchar[i].ok()) {
          ++failures;
          std::fprintf(stderr, "%s seed %d: %s\n", key.c_str(), seed,
                       (!measured[i].ok() ? measured[i].status()
                        : !truth[i].ok()  ? truth[i].status()
                                          : measured_unchar[i].status())
                           .ToString()
                           .c_str());
          continue;
        }
        if (!std::isfinite(truth[i]->value)) continue;  // e.g. Ssk of a perfect plane (Sq = 0)
        const double dev = measured[i]->value - truth[i]->value;
        by_case[key].Add(dev, measured[i]->uncertainty.standard_uncertainty);
        {
          const UncertaintyBudget& b = measured[i]->uncertainty;
          const double parts[8] = {b.random, b.linearity, b.stage, b.other, b.monte_carlo_spread,
                                   std::abs(b.noise_bias), b.height_dependent, std::abs(b.estimated_systematic)};
          auto& acc = components[key];
          for (int j = 0; j < 8; ++j) acc[j] += std::isfinite(parts[j]) ? parts[j] : 0.0;
        }
        by_case_unchar[key].Add(measured_unchar[i]->value - truth[i]->value,
                                measured_unchar[i]->uncertainty.standard_uncertainty);
        if (dump) {
          std::fprintf(dump, "%dx%d\t%g\t%d\t%s\t%s\t%.9g\t%.9g\t%.9g\t%.9g\n", a.camera.width, a.camera.height,
                       scan->z_um.size() >= 2 ? std::abs(scan->z_um[1] - scan->z_um[0]) : 0.0, seed,
                       Short(c.specimen).c_str(), c.specs[i].first.c_str(), dev,
                       2.0 * measured[i]->uncertainty.standard_uncertainty,
                       measured_unchar[i]->value - truth[i]->value,
                       2.0 * measured_unchar[i]->uncertainty.standard_uncertainty);
          std::fflush(dump);
        }
        char buf[64];
        std::snprintf(buf, sizeof buf, "%.5g %s", truth[i]->value, measured[i]->unit.c_str());
        truth_of[key] = buf;
      }
    }
    std::fprintf(stderr, "seed %d/%d done\n", seed, a.seeds);
  }

  // 3. Report.
  std::printf(
      "%d seeds x %zu specimens (%dx%d camera, STD, %d Monte Carlo samples): scan %.2f s, measurements %.2f s per "
      "scan\n\n",
      a.seeds, cases.size(), a.camera.width, a.camera.height, a.samples, scan_s / scans, measure_s / scans);
  std::printf("%-10s %-17s %14s %11s %11s %11s %8s %9s | %10s %8s\n", "specimen", "measurement", "truth", "bias",
              "sigma", "mean U", "covered", "max|d|/U", "U uncharac", "covered");
  std::map<std::string, std::pair<int, int>> by_param, by_param_unchar;
  int all_cov = 0, all_n = 0, all_cov_u = 0;
  for (const auto& [key, t] : by_case) {
    const Tally& tu = by_case_unchar[key];
    const size_t bar = key.find('|');
    const std::string specimen = key.substr(0, bar), label = key.substr(bar + 1);
    double m = 0, s2 = 0, um = 0, umu = 0, worst = 0;
    const int n = int(t.dev.size());
    for (int i = 0; i < n; ++i) {
      m += t.dev[i] / n;
      um += 2.0 * t.u[i] / n;
      umu += 2.0 * tu.u[i] / n;
      worst = std::max(worst, std::abs(t.dev[i]) / (2.0 * t.u[i]));
    }
    for (int i = 0; i < n; ++i) s2 += (t.dev[i] - m) * (t.dev[i] - m);
    const double sd = n > 1 ? std::sqrt(s2 / (n - 1)) : 0.0;
    std::printf("%-10s %-17s %14s %+11.4g %11.4g %11.4g %3d/%-3d %9.2f | %10.4g %3d/%-3d\n", specimen.c_str(),
                label.c_str(), truth_of[key].c_str(), m, sd, um, t.Covered(), n, worst, umu, tu.Covered(), n);
    const std::string param = label.substr(0, label.find('('));
    by_param[param].first += t.Covered();
    by_param[param].second += n;
    by_param_unchar[param].first += tu.Covered();
    by_param_unchar[param].second += n;
    all_cov += t.Covered();
    all_cov_u += tu.Covered();
    all_n += n;
  }
  std::printf("\ncoverage of |deviation| <= U (k = 2) per parameter, all specimens:\n");
  for (const auto& [param, c] : by_param) {
    std::printf("  %-14s %5.1f %%  (%d/%d)   uncharacterised linearity: %5.1f %%\n", param.c_str(),
                100.0 * c.first / c.second, c.first, c.second,
                100.0 * by_param_unchar[param].first / by_param_unchar[param].second);
  }
  std::printf("  %-14s %5.1f %%  (%d/%d)   uncharacterised linearity: %5.1f %%\n", "all", 100.0 * all_cov / all_n,
              all_cov, all_n, 100.0 * all_cov_u / all_n);
  // Sharpness beside coverage: a U much wider than the deviations covers them and decides nothing.
  // For a Gaussian error with U = 2u the median |dev| / U is ~0.34.
  auto print_pooled = [](const std::map<std::string, Tally>& cases, const char* title) {
    std::map<std::string, Tally> pooled;
    for (const auto& [key, t] : cases) {
      const std::string label = key.substr(key.find('|') + 1);
      Tally& p = pooled[label.substr(0, label.find('('))];
      for (size_t i = 0; i < t.dev.size(); ++i) p.Add(t.dev[i], t.u[i]);
    }
    std::printf("\nper parameter, all specimens, %s (U = 2u):\n  %-14s %5s %9s %14s %11s %11s %11s\n", title,
                "parameter", "n", "coverage", "median|d|/U", "mean U", "RMS dev", "bias");
    for (const auto& [param, t] : pooled) {
      const int n = int(t.dev.size());
      std::vector<double> ratio;
      double mean_u = 0, rms = 0, bias = 0;
      for (int i = 0; i < n; ++i) {
        ratio.push_back(std::abs(t.dev[i]) / (2.0 * t.u[i]));
        mean_u += 2.0 * t.u[i] / n;
        rms += t.dev[i] * t.dev[i] / n;
        bias += t.dev[i] / n;
      }
      std::sort(ratio.begin(), ratio.end());
      const double median = n % 2 ? ratio[n / 2] : 0.5 * (ratio[n / 2 - 1] + ratio[n / 2]);
      std::printf("  %-14s %5d %8.1f%% %14.3f %11.4g %11.4g %+11.4g\n", param.c_str(), n, 100.0 * t.Covered() / n,
                  median, mean_u, std::sqrt(rms), bias);
    }
  };
  print_pooled(by_case, "characterised linearity");
  print_pooled(by_case_unchar, "uncharacterised linearity");
  if (a.components) {
    std::printf("\nmean budget components (k = 1) per specimen and measurement:\n  %-10s %-17s %10s %10s %10s %10s %10s %10s %10s %10s\n",
                "specimen", "measurement", "random", "linearity", "stage", "other", "MC spread", "|MC bias|",
                "height-dep", "|flatten|");
    for (const auto& [key, acc] : components) {
      const double n = double(by_case[key].dev.size());
      const size_t bar = key.find('|');
      std::printf("  %-10s %-17s", key.substr(0, bar).c_str(), key.substr(bar + 1).c_str());
      for (double v : acc) std::printf(" %10.4g", v / n);
      std::printf("\n");
    }
  }
  if (failures) std::printf("measurement failures: %d\n", failures);
  for (const auto& [specimen, bins] : profile) {
    const auto [lo, hi] = profile_range[specimen];
    std::printf("\nmean depth error by true height, %s (%.3f..%.3f um, %d bins, all seeds):\n", specimen.c_str(), lo,
                hi, kProfileBins);
    for (int b = 0; b < kProfileBins; ++b) {
      std::printf("  %9.3f um  %+8.4f um  (%d px)\n", lo + (b + 0.5) * (hi - lo) / kProfileBins,
                  bins[b].second ? bins[b].first / bins[b].second : std::nan(""), bins[b].second);
    }
  }
  if (dump) std::fclose(dump);
  std::error_code ec;
  fs::remove_all(work, ec);
  return 0;
}
