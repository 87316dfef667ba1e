// Lateral alignment evaluated against ground truth: specimen x focus breathing / drift
// -> RMSE, bias and sigma unperturbed, unaligned, aligned by the calibrated model (rig scans) and
// by an estimate from the stack, plus what alignment costs: scan wall time and the reconstruction
// of the stored stack, each as a ratio against the unaligned run measured in the same process.
// Rig specimens on the simulated rig (devices/sim, LateralOptics); the natural scene
// (devices/sim/natural_scene.h) with its frames moved by the same model (frame k at z = 5 k um).
// Ground truth is in the middle frame's grid (the alignment's reference).
//
// Usage: alignment-evaluate [--size WxH] [--quick] [--focus-rail]
// --focus-rail: only the natural scene at 14 % scale change over the stack (9.7 %/100 um), as
// frames from a camera on a focus rail, without and with drift.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "core/metrology/depth_metrics.h"
#include "core/sff/stack_reconstruct.h"
#include "core/sff/depth_postprocess.h"
#include "devices/sim/natural_scene.h"
#include "devices/sim/simulated_rig.h"
#include "server/procedures/calibration_procedure.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

constexpr int kBorderPx = 4;

struct Perturbation {
  double breathing_percent = 0, drift_x_px = 0, drift_y_px = 0;  // per 100 um
};

struct Row {
  std::string specimen;
  Perturbation p;
  DepthErrorStats plain, none, calibrated, estimated;
  std::string estimate_error;  // set when the estimate refused the stack (the job would fail)
  bool has_calibrated = false;
  double seen_percent = 100, scan_time_ratio = 0, recon_calibrated_ratio = 0, recon_estimate_ratio = 0;
  double cal_breathing_percent = 0, est_breathing_percent = 0;  // per 100 um, as measured
};

void Die(const Status& s, const char* what) {
  std::fprintf(stderr, "%s: %s\n", what, s.ToString().c_str());
  std::exit(1);
}
template <typename T>
T Must(StatusOr<T> v, const char* what) {
  if (!v.ok()) Die(v.status(), what);
  return std::move(v).value();
}

StatusOr<ScanOutcome> Scan(Rig& rig, std::optional<FrameAlignment> a, const CalibrationBundle* b, const fs::path& dir,
                           double* seconds) {
  const ScanDefaults d = rig.scan_defaults();
  INSPECT_ASSIGN_OR_RETURN(ScanPlan plan,
                           MakeScanPlan(d.z_start_um, d.z_end_um, d.z_step_um, d.exposure_us, rig.stage()));
  plan.alignment = a;
  std::atomic<bool> cancel{false};
  const auto t0 = Clock::now();
  auto out = RunScan(rig, plan, dir, nullptr, cancel, b);
  *seconds = Seconds(t0);
  return out;
}

// Reconstruction of a stored stack (decode, [estimate,] warp, engine), the best of 2 runs.
StatusOr<std::pair<DepthResult, double>> Reconstruct(const fs::path& dir, const StackFolderAlignment& a,
                                                     AlignmentFigures* figures) {
  INSPECT_ASSIGN_OR_RETURN(StackManifest m, ReadStackManifest(dir));
  std::atomic<bool> cancel{false};
  double best = 1e9;
  DepthResult r;
  for (int k = 0; k < 2; ++k) {
    const auto t0 = Clock::now();
    INSPECT_ASSIGN_OR_RETURN(r, ReconstructStackFolder(dir, m, SffOptions{}, nullptr, cancel, a, figures));
    best = std::min(best, Seconds(t0));
  }
  return std::make_pair(r, best);
}

Row RigRow(const std::string& specimen, const Perturbation& p, cv::Size size, const fs::path& dir) {
  Row row;
  row.specimen = specimen;
  row.p = p;
  SimulatedRigOptions o;
  o.specimen = specimen;
  o.camera_size = size;
  o.seed = 7;
  auto plain_rig = Must(CreateSimulatedRig(o), "rig");
  double t_plain = 0, t_none = 0, t_cal = 0;
  ScanOutcome plain = Must(Scan(*plain_rig, FrameAlignment::kNone, nullptr, dir / "plain", &t_plain), "scan");
  row.plain = CompareDepth(plain.depth.depth_um, plain.ground_truth_um, 1e9, kBorderPx);
  o.focus_breathing_percent_per_100um = p.breathing_percent;
  o.lateral_drift_x_px_per_100um = p.drift_x_px;
  o.lateral_drift_y_px_per_100um = p.drift_y_px;
  auto rig = Must(CreateSimulatedRig(o), "rig");
  CalibrationOptions co;
  co.steps = {CalibrationStep::kFocusBreathing};
  std::atomic<bool> cancel{false};
  CalibrationBundle bundle = Must(RunCalibration(*rig, co, nullptr, nullptr, cancel), "calibration");
  // Alternate none / calibrated twice; the faster of each (the machine is shared).
  double best_none = 1e9, best_cal = 1e9;
  ScanOutcome none, cal;
  for (int k = 0; k < 2; ++k) {
    fs::remove_all(dir / "none");
    fs::remove_all(dir / "cal");
    none = Must(Scan(*rig, FrameAlignment::kNone, &bundle, dir / "none", &t_none), "scan");
    cal = Must(Scan(*rig, std::nullopt, &bundle, dir / "cal", &t_cal), "scan");
    best_none = std::min(best_none, t_none);
    best_cal = std::min(best_cal, t_cal);
  }
  row.none = CompareDepth(none.depth.depth_um, none.ground_truth_um, 1e9, kBorderPx);
  row.calibrated = CompareDepth(cal.depth.depth_um, cal.ground_truth_um, 1e9, kBorderPx);
  row.has_calibrated = true;
  row.seen_percent = cal.alignment.seen_by_every_frame_percent;
  row.scan_time_ratio = best_cal / best_none;
  StackFolderAlignment a_none, a_cal, a_est;
  a_cal.alignment = FrameAlignment::kCalibrated;
  a_cal.calibrated = &*bundle.focus_breathing;
  a_est.alignment = FrameAlignment::kEstimate;
  AlignmentFigures f;
  auto [r_none, s_none] = Must(Reconstruct(dir / "none", a_none, &f), "reconstruct");
  auto [r_cal, s_cal] = Must(Reconstruct(dir / "none", a_cal, &f), "reconstruct");
  row.recon_calibrated_ratio = s_cal / s_none;
  row.cal_breathing_percent = 100 * bundle.focus_breathing->scale_change_per_100um;
  auto est_run = Reconstruct(dir / "none", a_est, &f);
  if (est_run.ok()) {
    row.estimated = CompareDepth(est_run->first.depth_um, none.ground_truth_um, 1e9, kBorderPx);
    row.recon_estimate_ratio = est_run->second / s_none;
    const StackManifest m = Must(ReadStackManifest(dir / "none"), "manifest");
    std::vector<double> z;
    for (const auto& fr : m.frames) z.push_back(fr.z_um);
    const FocusBreathingModel est = Must(
        EstimateFocusBreathing([&](int i) { return LoadStackFrame(dir / "none", m, size_t(i)); }, z, {}), "estimate");
    row.est_breathing_percent = 100 * est.scale_change_per_100um;
  } else {
    row.estimate_error = est_run.status().ToString();
  }
  fs::remove_all(dir);
  return row;
}

// The natural scene's frames seen through breathing optics: frame k (at z = 5 k um) warped by the
// model, the truth (frame units -> um) moved into the middle frame's grid.
Row NaturalRow(const Perturbation& p, cv::Size size) {
  Row row;
  row.specimen = "natural";
  row.p = p;
  NaturalSceneOptions no;
  no.size = size;
  no.frames = 30;
  no.seed = 3;
  no.colour = false;
  NaturalScene scene = Must(RenderNaturalScene(no), "natural scene");
  const int n = int(scene.frames.size());
  std::vector<double> z;
  for (int k = 0; k < n; ++k) z.push_back(5.0 * k);
  FocusBreathingModel truth;
  truth.frame_size = size;
  truth.scale_change_per_100um = p.breathing_percent / 100.0;
  truth.shift_x_px_per_100um = p.drift_x_px;
  truth.shift_y_px_per_100um = p.drift_y_px;
  std::vector<cv::Mat> moved;
  for (int k = 0; k < n; ++k) {
    cv::Mat f;
    cv::warpAffine(scene.frames[size_t(k)], f, truth.FrameFromReference(z[size_t(k)], 0.0), size, cv::INTER_CUBIC,
                   cv::BORDER_REFLECT_101);
    moved.push_back(f);
  }
  const cv::Mat truth_um = scene.depth_frames * 5.0;
  cv::Mat truth_ref;
  cv::warpAffine(truth_um, truth_ref, truth.FrameFromReference(z[size_t((n - 1) / 2)], 0.0), size, cv::INTER_NEAREST,
                 cv::BORDER_REFLECT_101);
  // The product's output: the engine without a threshold, then the default post-processing
  // (confidence, depth consistency: core/sff/depth_postprocess.h), as a reconstruction does.
  SffOptions so;
  so.min_confidence = 0.0;
  auto post = [&](const DepthResult& raw) { return Must(PostProcessDepth(raw, z, so.window_px, {}), "post"); };
  const DepthResult plain = post(Must(SffEngine::ReconstructInMemory(so, scene.frames, z), "sff"));
  row.plain = CompareDepth(plain.depth_um, truth_um, 1e9, kBorderPx);
  auto t0 = Clock::now();
  const DepthResult none = post(Must(SffEngine::ReconstructInMemory(so, moved, z), "sff"));
  const double s_none = Seconds(t0);
  row.none = CompareDepth(none.depth_um, truth_ref, 1e9, kBorderPx);
  t0 = Clock::now();
  FocusBreathingModel est =
      Must(EstimateFocusBreathing([&](int i) -> StatusOr<cv::Mat> { return moved[size_t(i)]; }, z, {}), "estimate");
  StackAligner aligner = Must(StackAligner::Create(est, FrameAlignment::kEstimate, z, size), "aligner");
  auto engine = Must(SffEngine::Create(so, size, CV_8UC1), "engine");
  for (int k = 0; k < n; ++k) {
    const cv::Mat w = Must(aligner.Warp(moved[size_t(k)], k), "warp");
    if (Status s = engine->PushFrame(w, z[size_t(k)]); !s.ok()) Die(s, "push");
  }
  DepthResult aligned = post(Must(engine->Finish(), "finish"));
  MaskUnseenPixels(aligner, &aligned);
  const double s_est = Seconds(t0);
  row.estimated = CompareDepth(aligned.depth_um, truth_ref, 1e9, kBorderPx);
  row.seen_percent = aligner.figures().seen_by_every_frame_percent;
  row.recon_estimate_ratio = s_est / s_none;
  row.est_breathing_percent = 100 * est.scale_change_per_100um;
  return row;
}

std::string Cell(const DepthErrorStats& e) {
  char b[64];
  std::snprintf(b, sizeof(b), "%.3f / %+.3f / %.3f (%.0f %%)", e.rmse_um, e.mean_error_um, e.stddev_error_um,
                e.valid_percent);
  return b;
}

}  // namespace
}  // namespace inspection

int main(int argc, char** argv) {
  using namespace inspection;
  cv::Size size{640, 480};
  bool quick = false, focus_rail = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--size") && i + 1 < argc) {
      if (std::sscanf(argv[++i], "%dx%d", &size.width, &size.height) != 2) return 2;
    } else if (!std::strcmp(argv[i], "--quick")) {
      quick = true;
    } else if (!std::strcmp(argv[i], "--focus-rail")) {
      focus_rail = true;
    } else {
      std::fprintf(stderr, "usage: alignment-evaluate [--size WxH] [--quick] [--focus-rail]\n");
      return 2;
    }
  }
  const fs::path dir = fs::temp_directory_path() / ("alignment_evaluate_" + std::to_string(::getpid()));
  const std::vector<Perturbation> perturbations = quick ? std::vector<Perturbation>{{2.0, 4.0, -3.0}}
                                                        : std::vector<Perturbation>{{1.0, 3.0, 2.0}, {3.0, 6.0, -4.0}};
  const std::vector<std::string> specimens =
      quick ? std::vector<std::string>{"skew5"} : std::vector<std::string>{"skew5", "wedge", "cutter"};
  std::vector<Row> rows;
  if (focus_rail) {
    // A camera on a focus rail (focus-stack's PCB example grows ~14 % in scale from its first to
    // its last frame): the natural scene's 30 frames span 145 um, so 9.7 %/100 um is 14 %.
    rows.push_back(NaturalRow({9.7, 0.0, 0.0}, size));
    rows.push_back(NaturalRow({9.7, 8.0, -5.0}, size));
  } else {
    for (const auto& s : specimens)
      for (const auto& p : perturbations) rows.push_back(RigRow(s, p, size, dir / s));
    for (const auto& p : perturbations) rows.push_back(NaturalRow(p, size));
  }

  std::printf(
      "Lateral alignment, %dx%d px; RMSE / bias / sigma in um (valid %%) against ground truth in the middle "
      "frame's grid; natural rows after the default post-processing\n",
      size.width, size.height);
  std::printf(
      "| specimen | breathing %%/100um | drift px/100um | unperturbed | unaligned | calibrated | estimated | "
      "breathing cal / est | seen %% | scan time cal/none | recon time cal/none | recon time est/none |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Row& r : rows) {
    char measured[48];
    if (r.has_calibrated) {
      std::snprintf(measured, sizeof(measured), "%.2f / %.2f", r.cal_breathing_percent, r.est_breathing_percent);
    } else {
      std::snprintf(measured, sizeof(measured), "- / %.2f", r.est_breathing_percent);
    }
    std::printf("| %s | %.1f | (%.0f, %.0f) | %s | %s | %s | %s | %s | %.1f | %s | %s | %.2f |\n", r.specimen.c_str(),
                r.p.breathing_percent, r.p.drift_x_px, r.p.drift_y_px, Cell(r.plain).c_str(), Cell(r.none).c_str(),
                r.has_calibrated ? Cell(r.calibrated).c_str() : "-",
                r.estimate_error.empty() ? Cell(r.estimated).c_str() : "refused (see below)", measured, r.seen_percent,
                r.has_calibrated ? std::to_string(r.scan_time_ratio).substr(0, 4).c_str() : "-",
                r.has_calibrated ? std::to_string(r.recon_calibrated_ratio).substr(0, 4).c_str() : "-",
                r.recon_estimate_ratio);
  }
  for (const Row& r : rows) {
    if (!r.estimate_error.empty())
      std::printf("%s: estimate refused: %s\n", r.specimen.c_str(), r.estimate_error.c_str());
  }
  std::printf("Times: best of 2 alternated runs; natural rows: estimate + warp + engine vs engine alone in memory.\n");
  return 0;
}
