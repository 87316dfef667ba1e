// Integral shape from focus (thesis 6.4) on the simulated rig, the tables shared by isff-evaluate
// and inspect-evaluate: calibrates the integral PSF with each regulariser (the INTEGRAL_PSF step
// of the calibration procedure), scans PLANE-NORM, SKEW5 and SKEW10 under STD illumination and
// prints
//   Table 6.8: sigma, bias and RMSE of the depth error for STD, ISFF-GT and ISFF, at the rig's
//              default noise and at twice its read noise;
//   Table 6.9: ISFF-FAST on SKEW5 for thresholds 0.5..0.95: wrong maxima against ISFF, sigma,
//              and computation against ISFF's global maximum search (tiles processed, time);
//   Fig. 6.17: restored-image error against white noise sigma_w = 0..0.02 on a synthetic CHESS
//              stack, for the IPSF of every regulariser, plain (eq. 5.23) and noise-adaptive;
// and the time each calibration step and reconstruction took.
#include "tests/bench/isff_tables.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>

#include "core/metrology/depth_metrics.h"
#include "core/sff/integral_sff.h"
#include "core/sff/sff_engine.h"
#include "core/io/stack.h"
#include "devices/sim/defocus.h"
#include "devices/sim/simulated_rig.h"
#include "server/procedures/calibration_procedure.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr int kWindowPx = 7;  // thesis 6 / 6.4: Tenengrad 7 x 7, NCC 7 x 7
constexpr int kBorderPx = 7;  // left out of the comparison: the windows see the image border

double Seconds(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
// Process CPU time (all threads): on a shared machine the wall time also counts other jobs.
double CpuSeconds() { return double(std::clock()) / CLOCKS_PER_SEC; }

// One STD scan of a specimen: its frames, z, ground truth and STD depth map.
struct Scanned {
  std::string specimen;
  std::vector<cv::Mat> frames;
  std::vector<double> z_um;
  cv::Mat truth_um;
  cv::Mat gt_texture;  // noise-free in-focus image of the specimen (ISFF-GT's template)
  DepthResult std_depth;
  double z_step_um = 5.0;
  double scan_seconds = 0.0;
  double std_finish_seconds = 0.0;
};

bool Scan(Rig& rig, const std::string& specimen, const fs::path& dir, Scanned* out) {
  if (!rig.simulation()->SetSpecimen(specimen).ok()) return false;
  const ScanDefaults d = rig.scan_defaults();
  auto plan = MakeScanPlan(d.z_start_um, d.z_end_um, d.z_step_um, d.exposure_us, rig.stage());
  if (!plan.ok()) return false;
  plan->sff.window_px = kWindowPx;
  std::atomic<bool> cancel{false};
  const fs::path stack = dir / specimen;
  const auto t0 = Clock::now();
  auto o = RunScan(rig, *plan, stack, nullptr, cancel);
  out->scan_seconds = Seconds(t0);
  if (!o.ok()) {
    std::fprintf(stderr, "%s: %s\n", specimen.c_str(), o.status().ToString().c_str());
    return false;
  }
  out->specimen = specimen;
  out->std_depth = o->depth;
  out->std_finish_seconds = o->engine_finish_seconds;
  out->truth_um = o->ground_truth_um;
  out->z_step_um = d.z_step_um;
  out->frames.clear();
  out->z_um.clear();
  for (size_t i = 0; i < o->manifest.frames.size(); ++i) {
    auto f = LoadStackFrame(stack, o->manifest, i);
    if (!f.ok()) return false;
    out->frames.push_back(*f);
    out->z_um.push_back(o->manifest.frames[i].z_um);
  }
  std::error_code ec;
  fs::remove_all(stack, ec);
  // ISFF-GT's template as the server gets it: the specimen in focus everywhere, noise-free, under
  // the scan's uniform grey and exposure.
  auto gt = rig.simulation()->GroundTruthTexture(cv::Mat(rig.projector().resolution(), CV_8UC1, cv::Scalar(128)),
                                                 d.exposure_us);
  if (!gt.ok()) {
    std::fprintf(stderr, "%s: ground-truth texture: %s\n", specimen.c_str(), gt.status().ToString().c_str());
    return false;
  }
  out->gt_texture = *gt;
  return true;
}

DepthErrorStats Error(const cv::Mat& depth, const Scanned& s) {
  return CompareDepth(depth, s.truth_um, 2.0 * s.z_step_um, kBorderPx);
}

std::string Cell(const DepthErrorStats& e) {
  char buf[96];
  std::snprintf(buf, sizeof(buf), "%6.3f %+7.3f %6.3f %5.1f%%", e.stddev_error_um, e.mean_error_um, e.rmse_um,
                e.valid_percent);
  return buf;
}

StatusOr<CalibrationBundle> CalibrateIpsf(Rig& rig, IpsfRegularisation reg, double* seconds, double* cpu_seconds) {
  CalibrationOptions co;
  co.steps = {CalibrationStep::kIntegralPsf};
  co.ipsf_regularisation = reg;
  std::atomic<bool> cancel{false};
  const auto t0 = Clock::now();
  const double c0 = CpuSeconds();
  auto b = RunCalibration(rig, co, nullptr, nullptr, cancel);
  *seconds = Seconds(t0);
  *cpu_seconds = CpuSeconds() - c0;
  return b;
}

IsffOptions DefaultIsff() {
  IsffOptions o;
  o.ncc.correlation_window_px = kWindowPx;
  o.ncc.summation_window_px = kWindowPx;
  return o;
}

// ---------------------------------------------------------------------------------------------
// Table 6.8 at one noise level.
void Table68(const IntegralPsf& ipsf, const std::vector<Scanned>& scans, const char* title) {
  std::printf("%s\n", title);
  const char* head = " sigma    bias   RMSE  valid";
  std::printf("%-8s | %-30s | %-30s | %-30s | %-30s | %s\n", "Specimen", "STD", "ISFF-GT", "ISFF",
              "ISFF, thesis eq. 5.26 sum", "ISFF/STD sigma");
  std::printf("%-8s | %-30s | %-30s | %-30s | %-30s |\n", "", head, head, head, head);
  for (const Scanned& s : scans) {
    const DepthErrorStats e_std = Error(s.std_depth.depth_um, s);
    const IsffOptions o = DefaultIsff();
    IsffOptions thesis = o;
    thesis.ncc.focus_value = CorrelationFocusValue::kShiftedSum;
    auto gt = ReconstructIntegralSffWithTemplate(s.frames, s.z_um, s.gt_texture, o);
    auto is = ReconstructIntegralSff(s.frames, s.z_um, &ipsf, o);
    auto th = ReconstructIntegralSff(s.frames, s.z_um, &ipsf, thesis);
    if (!gt.ok() || !is.ok() || !th.ok()) {
      std::printf("%-8s | failed: %s %s\n", s.specimen.c_str(), gt.status().ToString().c_str(),
                  is.status().ToString().c_str());
      continue;
    }
    const DepthErrorStats e_gt = Error(gt->depth.depth_um, s), e_is = Error(is->depth.depth_um, s),
                          e_th = Error(th->depth.depth_um, s);
    std::printf("%-8s | %-30s | %-30s | %-30s | %-30s | %5.2f\n", s.specimen.c_str(), Cell(e_std).c_str(),
                Cell(e_gt).c_str(), Cell(e_is).c_str(), Cell(e_th).c_str(),
                e_is.stddev_error_um / e_std.stddev_error_um);
  }
  std::printf(
      "Reconstruction times [ms] on the stack in memory, same run: STD = SffEngine::ReconstructInMemory "
      "(Tenengrad 7x7, fused kernels); ISFF = pass 1 (integral image + noise) + restoration (eq. 5.23 + "
      "Wiener) + pass 2 (NCC, maximum, interpolation); wall / process CPU; the scan's STD streaming engine "
      "finished %s\n",
      "at the last frame (time after it below)");
  for (const Scanned& s : scans) {
    SffOptions so;
    so.window_px = kWindowPx;
    auto t0 = Clock::now();
    double c0 = CpuSeconds();
    auto st = SffEngine::ReconstructInMemory(so, s.frames, s.z_um);
    const double std_wall = Seconds(t0), std_cpu = CpuSeconds() - c0;
    c0 = CpuSeconds();
    auto is = ReconstructIntegralSff(s.frames, s.z_um, &ipsf, DefaultIsff());
    const double isff_cpu = CpuSeconds() - c0;
    if (!is.ok() || !st.ok()) continue;
    std::printf(
        "  %-7s STD %6.1f / %6.1f   ISFF %6.1f + %6.1f + %6.1f = %6.1f / %6.1f   (streaming STD after the "
        "last frame %5.1f)   %2d frames of %dx%d, noise %.2f grey\n",
        s.specimen.c_str(), 1e3 * std_wall, 1e3 * std_cpu, 1e3 * is->integral_seconds, 1e3 * is->restore_seconds,
        1e3 * is->focus_seconds, 1e3 * (is->integral_seconds + is->restore_seconds + is->focus_seconds), 1e3 * isff_cpu,
        1e3 * s.std_finish_seconds, int(s.frames.size()), s.frames[0].cols, s.frames[0].rows, is->frame_noise_sigma);
  }
  std::fflush(stdout);
}

// ---------------------------------------------------------------------------------------------
// Table 6.9 on one scan.
void Table69(const IntegralPsf& ipsf, const Scanned& s, int repeats) {
  std::printf(
      "\nTable 6.9: ISFF-FAST on %s (%d frames): wrong maxima (discrete maximum differs from ISFF's), "
      "sigma and bias of the depth error [um], computation against ISFF's global maximum search\n",
      s.specimen.c_str(), int(s.frames.size()));
  IsffOptions full = DefaultIsff();
  auto base = ReconstructIntegralSff(s.frames, s.z_um, &ipsf, full);
  if (!base.ok()) {
    std::printf("failed: %s\n", base.status().ToString().c_str());
    return;
  }
  // The template is the same for every threshold: time only pass 2, and within it the search
  // over the frames (set-up and the final interpolation are the same for both).
  const cv::Mat templ = base->focused_template;
  struct Times {
    double search_cpu = NAN, search = NAN, total_cpu = NAN;
  };
  auto time_pass2 = [&](const IsffOptions& o, IsffResult* keep) {
    const double c0 = CpuSeconds();
    auto r = ReconstructIntegralSffWithTemplate(s.frames, s.z_um, templ, o);
    const double total_cpu = CpuSeconds() - c0;
    if (r.ok() && keep) *keep = *r;
    return r.ok() ? Times{r->search_cpu_seconds, r->search_seconds, total_cpu} : Times{};
  };
  const DepthErrorStats e_base = Error(base->depth.depth_um, s);
  std::printf(
      "computed %% = pixels whose NCC was computed (bounding boxes of the searching pixels per tile) against "
      "ISFF's pixels x frames; search CPU %% / wall %% = the search over the frames (process CPU time, all "
      "threads / wall time) against ISFF's; pass 2 CPU %% = with the engine's set-up and the final "
      "interpolation (medians of %d alternating runs); stopped %% = pixels that stopped at a local maximum "
      "above the threshold\n",
      repeats);
  std::printf("%-9s %12s %9s %9s %11s %8s %17s %12s %10s\n", "threshold", "wrong max %", "sigma", "bias", "computed %",
              "tiles %", "search CPU/wall%", "pass2 CPU %", "stopped %");
  std::printf("%-9s %12s %9.3f %+9.3f %11.1f %8.1f %17.1f %12.1f %10s   (search %.1f ms CPU, %.1f ms wall)\n", "ISFF",
              "-", e_base.stddev_error_um, e_base.mean_error_um, 100.0, 100.0, 100.0, 100.0, "-",
              1e3 * base->search_cpu_seconds, 1e3 * base->search_seconds);
  for (double thr : {0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.875, 0.9, 0.925, 0.95, 0.975}) {
    IsffOptions fast = full;
    fast.ncc.stop_at_first_maximum = true;
    fast.ncc.stop_threshold = thr;
    std::vector<double> cpu_full, cpu_fast, wall_full, wall_fast, total_full, total_fast;
    IsffResult fr;
    for (int k = 0; k < repeats; ++k) {
      const Times a = time_pass2(full, nullptr), b = time_pass2(fast, k == 0 ? &fr : nullptr);
      cpu_full.push_back(a.search_cpu);
      cpu_fast.push_back(b.search_cpu);
      wall_full.push_back(a.search);
      wall_fast.push_back(b.search);
      total_full.push_back(a.total_cpu);
      total_fast.push_back(b.total_cpu);
    }
    auto median = [](std::vector<double> v) {
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      return v[v.size() / 2];
    };
    const cv::Mat wrong = fr.max_index != base->max_index;
    const double wrong_pct = 100.0 * cv::countNonZero(wrong) / double(wrong.total());
    const DepthErrorStats e = Error(fr.depth.depth_um, s);
    std::printf(
        "%-9.3f %12.2f %9.3f %+9.3f %11.1f %8.1f %11.1f / %3.0f %12.1f %10.1f\n", thr, wrong_pct, e.stddev_error_um,
        e.mean_error_um, 100.0 * fr.work.computed_pixel_frames / double(fr.work.computed_pixel_frames_full),
        100.0 * fr.work.tile_frames / double(fr.work.tile_frames_full), 100.0 * median(cpu_fast) / median(cpu_full),
        100.0 * median(wall_fast) / median(wall_full), 100.0 * median(total_fast) / median(total_full),
        100.0 * fr.work.stopped_pixels / double(s.frames[0].total()));
  }
  std::fflush(stdout);
}

// ---------------------------------------------------------------------------------------------
// Fig. 6.17: the synthetic CHESS specimen (thesis 6.4.1): a chessboard texture with fine grain
// on a smooth relief, 25 frames blurred by the rig's defocus model, values in [0, 1].
struct Chess {
  cv::Mat texture;  // CV_32FC1 ground-truth texture
  std::vector<cv::Mat> frames;
};

Chess MakeChess(cv::Size size, uint64_t seed) {
  Chess c;
  cv::RNG rng(seed);
  cv::Mat grain(size, CV_32FC1);
  rng.fill(grain, cv::RNG::NORMAL, 0.0, 1.0);
  cv::GaussianBlur(grain, grain, {0, 0}, 1.0);
  cv::Mat t(size, CV_32FC1), h(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const bool black = ((x / 16) + (y / 16)) % 2;
      t.at<float>(y, x) = float(std::clamp((black ? 0.3 : 0.7) + 0.12 * grain.at<float>(y, x), 0.0, 1.0));
      // A smooth relief spanning 30 um (bump on a slope).
      const double u = (x - size.width / 2.0) / size.width, v = (y - size.height / 2.0) / size.height;
      h.at<float>(y, x) = float(100.0 + 12.0 * u + 18.0 * std::exp(-(u * u + v * v) / 0.05));
    }
  c.texture = t;
  DefocusModel model;
  SpatiallyVaryingBlur blur(model);
  for (int i = 0; i < 25; ++i) {
    const double z = 85.0 + 2.5 * i;
    cv::Mat sigma(size, CV_32FC1);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) sigma.at<float>(y, x) = float(model.SigmaPx(h.at<float>(y, x) - z));
    cv::Mat f;
    blur.Apply(t, sigma, &f);
    c.frames.push_back(f);
  }
  return c;
}

struct RestorationError {
  double mean_diff = 0, std_diff = 0, rmse = 0;
};

RestorationError CompareRestored(const cv::Mat& restored, const cv::Mat& truth, int border) {
  const cv::Rect inner(border, border, truth.cols - 2 * border, truth.rows - 2 * border);
  cv::Scalar m1, s1, m2, s2;
  cv::meanStdDev(restored(inner), m1, s1);
  cv::meanStdDev(truth(inner), m2, s2);
  RestorationError e;
  e.mean_diff = std::abs(m1[0] - m2[0]);
  e.std_diff = std::abs(s1[0] - s2[0]);
  e.rmse = std::sqrt(cv::norm(restored(inner), truth(inner), cv::NORM_L2SQR) / inner.area());
  return e;
}

void Fig617(const CalibrationBundle* rig_bundles[3], double* estimate_seconds) {
  const Chess chess = MakeChess({256, 192}, 17);
  auto integral = IntegralImage(chess.frames);
  if (!integral.ok()) return;
  const IpsfRegularisation regs[] = {IpsfRegularisation::kGradientL2, IpsfRegularisation::kTotalVariation,
                                     IpsfRegularisation::kTotalVariationL1};
  const char* names[] = {"grad-L2", "TV-L2", "TV-L1"};
  IntegralPsf chess_ipsf[3];
  for (int r = 0; r < 3; ++r) {
    IntegralPsfOptions io;
    io.radius_px = 8;
    io.regularisation = regs[r];
    io.regularisation_weight = 1e-4;
    const auto t0 = Clock::now();
    auto k = EstimateIntegralPsf(*integral, chess.texture, io);
    estimate_seconds[r] = Seconds(t0);
    if (!k.ok()) {
      std::printf("IPSF %s: %s\n", names[r], k.status().ToString().c_str());
      return;
    }
    chess_ipsf[r] = *k;
  }
  std::printf(
      "\nFig. 6.17: restored all-in-focus image against the ground-truth texture on the synthetic CHESS stack "
      "(256x192, 25 frames, 2.5 um steps, values 0..1) with white noise sigma_w on every frame.\n"
      "Error = |difference of means| / |difference of standard deviations| (the thesis's two curves) / RMSE, "
      "for the IPSF of each regulariser, (a) estimated on the noise-free CHESS stack, (b) calibrated on the "
      "rig's PLANE-NORM; plain = eq. 5.23 alone, adaptive = with the noise-weighted Wiener shrinkage; "
      "0.05 and 0.1 go beyond the thesis's range\n");
  std::printf("%-6s %-9s", "", "");
  for (const char* n : names) std::printf(" | %-28s", n);
  std::printf("\n%-6s %-9s", "sigma_w", "restore");
  for (int r = 0; r < 3; ++r) std::printf(" | %-28s", "  dmean    dstd    RMSE");
  std::printf("\n");
  const cv::Mat no_noise_integral = *integral;
  for (const char* which : {"a", "b"}) {
    for (double sw : {0.0, 0.005, 0.01, 0.015, 0.02, 0.05, 0.1}) {
      std::vector<cv::Mat> noisy;
      cv::RNG rng(1000 + uint64_t(sw * 1e4));
      IntegralImageAccumulator acc;
      for (const cv::Mat& f : chess.frames) {
        cv::Mat n(f.size(), CV_32FC1);
        rng.fill(n, cv::RNG::NORMAL, 0.0, sw);
        cv::Mat g = f + n;
        if (!acc.Add(g).ok()) return;
      }
      auto ii = acc.IntegralImage();
      const double noise = acc.FrameNoiseSigma();
      for (IpsfRestoration method : {IpsfRestoration::kPlain, IpsfRestoration::kNoiseAdaptive}) {
        std::printf("%s %-5.3f %-9s", which, sw, method == IpsfRestoration::kPlain ? "plain" : "adaptive");
        for (int r = 0; r < 3; ++r) {
          const IntegralPsf* k = which[0] == 'a'                                    ? &chess_ipsf[r]
                                 : (rig_bundles[r] && rig_bundles[r]->integral_psf) ? &*rig_bundles[r]->integral_psf
                                                                                    : nullptr;
          if (k == nullptr) {
            std::printf(" | %-28s", "no IPSF");
            continue;
          }
          IpsfRestorationOptions ro;
          ro.method = method;
          auto restored = RestoreFocusedImage(*ii, acc.frame_count(), noise, *k, ro);
          if (!restored.ok()) {
            std::printf(" | %-28s", "failed");
            continue;
          }
          const RestorationError e = CompareRestored(*restored, chess.texture, 10);
          std::printf(" | %7.4f %7.4f %7.4f    ", e.mean_diff, e.std_diff, e.rmse);
        }
        std::printf("   (estimated noise %.4f)\n", noise);
      }
    }
  }
  const RestorationError blur = CompareRestored(no_noise_integral, chess.texture, 10);
  std::printf("(the integral image itself, no restoration: %.4f %.4f %.4f)\n", blur.mean_diff, blur.std_diff,
              blur.rmse);
  std::fflush(stdout);
}

}  // namespace

bool PrintIsffTables(const IsffTablesOptions& options) {
  SimulatedRigOptions ro;
  ro.camera_size = options.camera_size;
  ro.seed = options.seed;
  const int repeats = std::max(1, options.repeats);
  // The projector lights the whole camera field (3.4 camera px per projector px, projector x
  // along camera y), as on the thesis rig; unlit edge columns would never reach a correlation
  // threshold and keep ISFF-FAST's edge tiles busy for nothing.
  ro.projector_size = {int(ro.camera_size.height / 3.4) + 16, int(ro.camera_size.width / 3.4) + 16};
  const fs::path dir = fs::temp_directory_path() / ("isff_evaluate_" + std::to_string(::getpid()));
  const char* specimens[] = {"plane", "skew5", "skew10"};
  const IpsfRegularisation regs[] = {IpsfRegularisation::kGradientL2, IpsfRegularisation::kTotalVariation,
                                     IpsfRegularisation::kTotalVariationL1};

  std::vector<std::vector<Scanned>> levels;
  CalibrationBundle bundles[2][3];
  double calib_s[2][3] = {}, calib_cpu[2][3] = {};
  for (int level = 0; level < 2; ++level) {
    SimulatedRigOptions r = ro;
    r.read_noise_dn = ro.read_noise_dn * (level + 1);
    auto rig = CreateSimulatedRig(r);
    if (!rig.ok()) {
      std::fprintf(stderr, "%s\n", rig.status().ToString().c_str());
      return false;
    }
    for (int k = 0; k < 3; ++k) {
      auto b = CalibrateIpsf(**rig, regs[k], &calib_s[level][k], &calib_cpu[level][k]);
      if (!b.ok()) {
        std::fprintf(stderr, "calibration: %s\n", b.status().ToString().c_str());
        return false;
      }
      bundles[level][k] = *b;
    }
    std::vector<Scanned> scans;
    for (const char* s : specimens) {
      Scanned sc;
      if (!Scan(**rig, s, dir, &sc)) return false;
      scans.push_back(std::move(sc));
    }
    levels.push_back(std::move(scans));
  }
  std::printf(
      "Simulated rig: camera %dx%d, seed %llu, STD illumination, 5 um steps; Tenengrad %dx%d and NCC %dx%d "
      "(summed over %dx%d); %s interpolation; IPSF: the INTEGRAL_PSF calibration step with its default "
      "regulariser (gradient_l2) unless noted\n",
      ro.camera_size.width, ro.camera_size.height, (unsigned long long)ro.seed, kWindowPx, kWindowPx, kWindowPx,
      kWindowPx, kWindowPx, kWindowPx, DepthInterpolationName(SffOptions().interpolation));
  std::printf(
      "Calibration (INTEGRAL_PSF step: 17 frames at +-40 um, central %d px, kernel radius 8), seconds wall / "
      "process CPU:\n",
      std::min(512, std::min(ro.camera_size.width, ro.camera_size.height)));
  for (int level = 0; level < 2; ++level) {
    std::printf("  read noise %.1f: ", ro.read_noise_dn * (level + 1));
    for (int k = 0; k < 3; ++k) {
      const IntegralPsf& p = *bundles[level][k].integral_psf;
      std::printf("%s %.1f / %.1f s (restored/integral RMS %.3f)  ", IpsfRegularisationName(regs[k]), calib_s[level][k],
                  calib_cpu[level][k], p.restored_rms_error / p.integral_rms_error);
    }
    std::printf("\n");
  }
  std::printf("Scans (acquisition + STD engine), seconds:");
  for (const Scanned& s : levels[0]) std::printf(" %s %.2f", s.specimen.c_str(), s.scan_seconds);
  std::printf("\n\n");

  Table68(*bundles[0][0].integral_psf, levels[0],
          "Table 6.8: depth error [um] against the ground truth: sigma, bias (mean signed), RMSE, valid %; "
          "default read noise (0.8 grey)");
  Table68(*bundles[1][0].integral_psf, levels[1],
          "\nTable 6.8 at twice the read noise (1.6 grey; IPSF calibrated on that rig)");
  std::printf(
      "\nIPSF regulariser ablation, default noise: ISFF sigma [um] with the plain / noise-adaptive "
      "restoration, and ISFF-FAST (0.9): computed %% and stopped %% (how often the template's NCC reaches the "
      "threshold at the maximum)\n");
  for (const Scanned& s : levels[0]) {
    std::printf("  %-7s", s.specimen.c_str());
    for (int k = 0; k < 3; ++k) {
      double sigma[2] = {};
      for (int m = 0; m < 2; ++m) {
        IsffOptions o = DefaultIsff();
        o.restoration.method = m == 0 ? IpsfRestoration::kPlain : IpsfRestoration::kNoiseAdaptive;
        auto r = ReconstructIntegralSff(s.frames, s.z_um, &*bundles[0][k].integral_psf, o);
        sigma[m] = r.ok() ? Error(r->depth.depth_um, s).stddev_error_um : NAN;
      }
      IsffOptions fast = DefaultIsff();
      fast.ncc.stop_at_first_maximum = true;
      auto f = ReconstructIntegralSff(s.frames, s.z_um, &*bundles[0][k].integral_psf, fast);
      if (!f.ok()) continue;
      std::printf("  | %-15s %.3f / %.3f  %5.1f%% %5.1f%%", IpsfRegularisationName(regs[k]), sigma[0], sigma[1],
                  100.0 * f->work.computed_pixel_frames / double(f->work.computed_pixel_frames_full),
                  100.0 * f->work.stopped_pixels / double(s.frames[0].total()));
    }
    std::printf("\n");
  }

  Table69(*bundles[0][0].integral_psf, levels[0][1], repeats);
  std::printf("\n(the same with the TV-L1 IPSF)");
  Table69(*bundles[0][2].integral_psf, levels[0][1], 1);

  const CalibrationBundle* rb[3] = {&bundles[0][0], &bundles[0][1], &bundles[0][2]};
  double est_s[3] = {};
  Fig617(rb, est_s);
  std::printf("IPSF estimation on CHESS (256x192, radius 8), seconds: grad-L2 %.2f, TV-L2 %.2f, TV-L1 %.2f\n", est_s[0],
              est_s[1], est_s[2]);
  std::error_code ec;
  fs::remove_all(dir, ec);
  return true;
}

}  // namespace inspection
