#include "server/procedures/scan_procedure.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

#include <opencv2/imgcodecs.hpp>

#include "core/depth_export.h"
#include "core/texture_pattern.h"

namespace inspection {
namespace fs = std::filesystem;

StatusOr<ScanPlan> MakeScanPlan(double z_start_um, double z_end_um, double z_step_um, double exposure_us,
                                const Stage& stage) {
  if (!std::isfinite(z_start_um)) return Status::InvalidArgument("z_start_um must be finite");
  if (!std::isfinite(z_end_um)) return Status::InvalidArgument("z_end_um must be finite");
  if (!(z_step_um > 0.0) || !std::isfinite(z_step_um)) {
    return Status::InvalidArgument("z_step_um must be > 0 (got " + std::to_string(z_step_um) + ")");
  }
  if (!(exposure_us > 0.0) || !std::isfinite(exposure_us)) {
    return Status::InvalidArgument("exposure_us must be > 0 (got " + std::to_string(exposure_us) + ")");
  }
  for (auto [name, z] : {std::pair{"z_start_um", z_start_um}, std::pair{"z_end_um", z_end_um}}) {
    if (z < stage.min_z_um() || z > stage.max_z_um()) {
      return Status::InvalidArgument(std::string(name) + " " + std::to_string(z) + " is outside the stage travel [" +
                                     std::to_string(stage.min_z_um()) + ", " + std::to_string(stage.max_z_um()) + "]");
    }
  }
  const double span = std::abs(z_end_um - z_start_um);
  // A small tolerance keeps an end that lies on the grid despite rounding.
  const long steps = long(std::floor(span / z_step_um + 1e-6));
  if (steps + 1 < 3) {
    return Status::InvalidArgument("z range [" + std::to_string(z_start_um) + ", " + std::to_string(z_end_um) +
                                   "] with z_step_um " + std::to_string(z_step_um) +
                                   " gives fewer than 3 frames");
  }
  if (steps + 1 > 5000) return Status::InvalidArgument("z range and z_step_um give more than 5000 frames");
  ScanPlan plan;
  plan.exposure_us = exposure_us;
  const double dir = z_end_um >= z_start_um ? 1.0 : -1.0;
  for (long i = 0; i <= steps; ++i) plan.z_um.push_back(z_start_um + dir * double(i) * z_step_um);
  return plan;
}

Status IlluminationParams::Validate() const {
  if (hdr_exposures < 2 || hdr_exposures > 5) return Status::InvalidArgument("hdr_exposures must be in [2, 5]");
  if (!(lambda >= 0 && lambda <= 2)) return Status::InvalidArgument("lambda must be in [0, 2]");
  if (!(gamma >= 0 && gamma <= 0.5)) return Status::InvalidArgument("gamma must be in [0, 0.5]");
  if (!(psi >= 0 && psi <= 1)) return Status::InvalidArgument("psi must be in [0, 1]");
  if (max_iterations < 1 || max_iterations > 20) return Status::InvalidArgument("max_iterations must be in [1, 20]");
  if (!(tolerance_grey > 0)) return Status::InvalidArgument("tolerance_grey must be > 0");
  if (!(min_improvement >= 0 && min_improvement < 1)) return Status::InvalidArgument("min_improvement must be in [0, 1)");
  if (!(target_grey > 0 && target_grey < 255)) return Status::InvalidArgument("target_grey must be in (0, 255)");
  return compensation.Validate();
}

std::string IlluminationModeName(IlluminationMode mode, int hdr_exposures) {
  switch (mode) {
    case IlluminationMode::kStd: return "STD";
    case IlluminationMode::kHdr: return "HDR" + std::to_string(hdr_exposures);
    case IlluminationMode::kAdaptIterative: return "ADAPT-IT";
    case IlluminationMode::kAdapt: return "ADAPT";
    case IlluminationMode::kTexture: return "TEXTURE";
    case IlluminationMode::kHfAdapt: return "HF+ADAPT";
    case IlluminationMode::kAdaptedHf: return "ADAPTED-HF";
  }
  return "?";
}

StatusOr<std::vector<double>> HdrRelativeExposures(int n) {
  switch (n) {  // thesis Table 6.2, in % of the STD exposure
    case 2: return std::vector<double>{0.50, 1.50};
    case 3: return std::vector<double>{0.50, 1.00, 2.00};
    case 4: return std::vector<double>{0.25, 0.75, 1.50, 2.00};
    case 5: return std::vector<double>{0.25, 0.50, 1.00, 2.00, 4.00};
    default: return Status::InvalidArgument("hdr_exposures must be in [2, 5] (thesis Table 6.2)");
  }
}

Status CheckCalibrationFor(IlluminationMode mode, const CalibrationBundle* bundle) {
  std::vector<CalibrationStep> need;
  const bool adapt = mode == IlluminationMode::kAdaptIterative || mode == IlluminationMode::kAdapt ||
                     mode == IlluminationMode::kHfAdapt || mode == IlluminationMode::kAdaptedHf;
  const bool texture = mode == IlluminationMode::kTexture || mode == IlluminationMode::kHfAdapt ||
                       mode == IlluminationMode::kAdaptedHf;
  if (mode == IlluminationMode::kHdr || adapt) need.push_back(CalibrationStep::kCameraResponse);
  if (adapt || texture) need.push_back(CalibrationStep::kProjectorResponse);
  if (texture) need.push_back(CalibrationStep::kGeometry);
  if (texture) need.push_back(CalibrationStep::kPsf);
  if (adapt) need.push_back(CalibrationStep::kScatterMatrix);
  std::string missing;
  for (CalibrationStep s : need) {
    if (bundle == nullptr || !bundle->HasModel(s)) missing += std::string(missing.empty() ? "" : ", ") + CalibrationStepName(s);
  }
  if (!missing.empty()) {
    return Status::FailedPrecondition("illumination " + IlluminationModeName(mode) +
                                      " needs the calibration step(s) " + missing +
                                      (bundle == nullptr ? " (no active calibration)" : " (missing in the active calibration)"));
  }
  return Status::Ok();
}

namespace {

// Merged radiance -> 16 bit for the engine (HDR). The mapping is logarithmic: eq. 3.44 yields
// ln E, and a focus measure on ln E responds to relative contrast, so a glint tens of times the
// surrounding metal and the dark metal beside it both keep their texture. (A linear mapping lets
// the defocused halo of a glint out-gradient the in-focus texture next to it; a sensor that sees
// the scene once cannot do better than the camera's own grey levels.) 0 is the radiance of level
// 1 at the longest exposure, 65535 the radiance that saturates the shortest one.
cv::Mat RadianceTo16(const cv::Mat& radiance, double lo, double hi) {
  cv::Mat log_e;
  cv::log(cv::max(radiance, lo), log_e);
  cv::Mat out;
  const double scale = 65535.0 / (std::log(hi) - std::log(lo));
  log_e.convertTo(out, CV_16UC1, scale, -std::log(lo) * scale);
  return out;
}

}  // namespace

StatusOr<ScanOutcome> RunScan(Rig& rig, const ScanPlan& plan, const fs::path& stack_dir,
                              const std::function<void(const ScanFrameEvent&)>& on_frame,
                              const std::atomic<bool>& cancel) {
  if (plan.mode != IlluminationMode::kStd) {
    return Status::FailedPrecondition("illumination " + IlluminationModeName(plan.mode, plan.params.hdr_exposures) +
                                      " needs a calibration bundle");
  }
  return RunScan(rig, plan, stack_dir, on_frame, cancel, nullptr);
}

StatusOr<ScanOutcome> RunScan(Rig& rig, const ScanPlan& plan, const fs::path& stack_dir,
                              const std::function<void(const ScanFrameEvent&)>& on_frame,
                              const std::atomic<bool>& cancel, const CalibrationBundle* bundle) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  const IlluminationMode mode = plan.mode;
  const IlluminationParams& prm = plan.params;
  INSPECT_RETURN_IF_ERROR(prm.Validate());
  INSPECT_RETURN_IF_ERROR(CheckCalibrationFor(mode, bundle));
  Camera& camera = rig.camera();
  Projector& projector = rig.projector();
  if (bundle != nullptr && mode != IlluminationMode::kStd &&
      (bundle->camera_size != camera.frame_size() || bundle->projector_size != projector.resolution())) {
    return Status::FailedPrecondition("the active calibration was made for another camera/projector size");
  }
  std::error_code ec;
  fs::create_directories(stack_dir / "raw", ec);
  if (ec) return Status::Internal("cannot create " + stack_dir.string() + ": " + ec.message());

  const int bit_depth = camera.bit_depth();
  const int top = (1 << bit_depth) - 1;
  const double level_scale = double(top + 1) / 256.0;  // 8-bit units -> camera levels
  const bool hdr = mode == IlluminationMode::kHdr;
  const int engine_type = (hdr || bit_depth > 8) ? CV_16UC1 : CV_8UC1;
  INSPECT_ASSIGN_OR_RETURN(std::unique_ptr<SffEngine> engine,
                           SffEngine::Create(plan.sff, camera.frame_size(), engine_type));

  ScanOutcome out;
  StackManifest& m = out.manifest;
  m.pixel_size_um = rig.pixel_size_um();
  m.bit_depth = hdr ? 16 : bit_depth;
  m.illumination = IlluminationModeName(mode, prm.hdr_exposures);
  m.calibration_id = plan.calibration_id;
  if (SimulationControl* sim = rig.simulation()) m.specimen = sim->specimen();
  const std::vector<int> png_params = {cv::IMWRITE_PNG_COMPRESSION, 1};
  const int count = int(plan.z_um.size());

  // Texture: the checkerboard period of eq. 5.15 from sigma_p and the focus window.
  const bool textured = mode == IlluminationMode::kTexture || mode == IlluminationMode::kHfAdapt ||
                        mode == IlluminationMode::kAdaptedHf;
  TexturePeriod period;
  cv::Mat cb;
  if (textured) {
    auto p = ChooseTexturePeriod(bundle->psf->influence_radius_px, bundle->geometry->camera_px_per_projector_px,
                                 plan.sff.window_px);
    if (!p.ok()) return p.status().WithContext("sff window_px " + std::to_string(plan.sff.window_px));
    period = *p;
    cb = CheckerboardMask(projector.resolution(), period.cell_projector_px);
  }
  // Compensation (ADAPT family). ADAPTED-HF's desired image holds the checkerboard itself, so
  // its solve runs at full resolution (no low-pass grid, no camera bins).
  const bool adapt = mode == IlluminationMode::kAdaptIterative || mode == IlluminationMode::kAdapt ||
                     mode == IlluminationMode::kHfAdapt || mode == IlluminationMode::kAdaptedHf;
  std::unique_ptr<Compensator> comp;
  cv::Mat desired;
  if (adapt) {
    CompensationOptions co = prm.compensation;
    if (mode == IlluminationMode::kAdaptedHf) {
      co.pattern_cell_px = 1;
      co.camera_bin_px = 1;
    }
    INSPECT_ASSIGN_OR_RETURN(comp, Compensator::Create(*bundle->camera_response, *bundle->projector_response,
                                                       *bundle->scatter, co));
    desired = mode == IlluminationMode::kAdaptedHf
                  ? CameraCheckerboard(camera.frame_size(), period.half_period_camera_px, 60.0 * level_scale,
                                       190.0 * level_scale)
                  : cv::Mat(camera.frame_size(), CV_32FC1, cv::Scalar(prm.target_grey * level_scale));
  }

  int acquisition = 0;
  ScanFrameEvent pending;  // ADAPT-IT: the last capture, reported once its stop test decided
  // Reports a capture (stack_frame: whether it became a stack frame).
  auto report = [&](ScanFrameEvent ev, bool stack_frame) {
    ev.stack_frame = stack_frame;
    out.capture_is_stack_frame[size_t(ev.acquisition)] = stack_frame;
    if (on_frame) on_frame(ev);
  };
  // Shows `pattern` (when not empty), captures at exposure_us, stores the frame (raw/ unless a
  // stack frame) and reports it, or with defer_report leaves the report to the caller (pending).
  auto capture = [&](int i, const cv::Mat& pattern, double exposure_us, bool stack_frame,
                     const std::string& raw_name, bool defer_report = false) -> StatusOr<cv::Mat> {
    if (cancel.load()) {
      return Status::Cancelled("scan cancelled at frame " + std::to_string(i) + " of " + std::to_string(count));
    }
    if (!pattern.empty()) INSPECT_RETURN_IF_ERROR(projector.Show(pattern).WithContext("frame " + std::to_string(i)));
    if (camera.exposure_us() != exposure_us) INSPECT_RETURN_IF_ERROR(camera.SetExposure(exposure_us));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, camera.Capture());
    if (frame.size() != camera.frame_size()) {
      return Status::Internal("frame " + std::to_string(i) + ": camera delivered an unexpected size");
    }
    if (!raw_name.empty() && !cv::imwrite((stack_dir / "raw" / raw_name).string(), frame, png_params)) {
      return Status::Internal("cannot write raw/" + raw_name);
    }
    const FrameStatistics st = ComputeFrameStatistics(frame, bit_depth);
    out.capture_statistics.push_back(st);
    out.capture_is_stack_frame.push_back(stack_frame);
    ScanFrameEvent ev;
    ev.index = i;
    ev.count = count;
    INSPECT_ASSIGN_OR_RETURN(ev.z_um, rig.stage().position_um());
    ev.exposure_us = camera.exposure_us();
    ev.statistics = st;
    ev.acquisition = acquisition;
    if (defer_report) pending = ev;
    else report(ev, stack_frame);
    ++acquisition;
    return frame;
  };
  auto push = [&](int i, const cv::Mat& frame, double exposure_us, const std::string& pattern) -> Status {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%04d.png", i);
    if (!cv::imwrite((stack_dir / name).string(), frame, png_params)) {
      return Status::Internal(std::string("cannot write ") + name);
    }
    // The commanded z is the stack coordinate: repeatability error is what the stage adds, and
    // the thesis evaluates against the nominal step positions.
    INSPECT_RETURN_IF_ERROR(engine->PushFrame(frame, plan.z_um[i]));
    m.frames.push_back({name, plan.z_um[i], exposure_us, pattern});
    return Status::Ok();
  };
  auto raw_name = [](int i, const char* what, int k) {
    char name[48];
    std::snprintf(name, sizeof(name), "frame_%04d_%s%d.png", i, what, k);
    return std::string(name);
  };

  const cv::Mat uniform(projector.resolution(), CV_8UC1, cv::Scalar(plan.uniform_grey));
  double dt = plan.exposure_us;
  std::vector<double> hdr_dt;
  if (hdr) {
    INSPECT_ASSIGN_OR_RETURN(std::vector<double> rel, HdrRelativeExposures(prm.hdr_exposures));
    for (double r : rel) hdr_dt.push_back(r * dt);
  }
  cv::Mat fixed_pattern;  // STD, HDR, TEXTURE
  std::string fixed_name = "uniform:" + std::to_string(plan.uniform_grey);
  if (mode == IlluminationMode::kTexture) {
    INSPECT_ASSIGN_OR_RETURN(fixed_pattern, MakeHfPattern(projector.resolution(), period.cell_projector_px, prm.gamma));
    fixed_name = "checkerboard:" + std::to_string(period.cell_projector_px) + ":gamma=" + std::to_string(prm.gamma);
    // Same mean projector irradiance as STD's uniform pattern: the exposure is scaled by
    // prf(uniform) / mean prf(checkerboard), so the mean grey stays near STD's.
    const ProjectorResponseFunction& pr = *bundle->projector_response;
    dt *= pr.Irradiance(plan.uniform_grey) / cv::mean(pr.IrradianceImage(fixed_pattern))[0];
  } else if (!adapt) {
    fixed_pattern = uniform;
  }
  const ProjectorResponseFunction* prf = adapt ? &*bundle->projector_response : nullptr;
  // Shown pattern for an adapted irradiance (HF+ADAPT adds the checkerboard, eq. 5.18).
  auto shown = [&](const cv::Mat& irr) -> StatusOr<cv::Mat> {
    cv::Mat p = comp->PatternFor(irr);
    if (mode == IlluminationMode::kHfAdapt) return AddHfPattern(p, cb, prm.psi);
    return p;
  };

  if (!adapt) {
    INSPECT_RETURN_IF_ERROR(projector.Show(fixed_pattern));
  }
  cv::Mat irr_cur, irr_prev, irr_next;  // ADAPT family: corrected irradiances of z_i, z_i-1, and the next prediction
  if (adapt) {
    INSPECT_RETURN_IF_ERROR(rig.stage().MoveTo(plan.z_um[0]).WithContext("frame 0: stage"));
    irr_next = prf->IrradianceImage(uniform);
    if (mode != IlluminationMode::kAdaptIterative) {
      // Predictive modes: two initialisation frames at the first z (thesis 5.1.3).
      for (int k = 0; k < 2; ++k) {
        INSPECT_ASSIGN_OR_RETURN(cv::Mat p, k == 0 ? StatusOr<cv::Mat>(uniform) : shown(irr_next));
        INSPECT_ASSIGN_OR_RETURN(cv::Mat f, capture(0, p, dt, false, raw_name(0, "init", k)));
        INSPECT_ASSIGN_OR_RETURN(CompensationStep st,
                                 comp->Step(prf->IrradianceImage(p), f, dt, desired, irr_next));
        irr_next = st.projector_irradiance;
      }
    }
  }

  for (int i = 0; i < count; ++i) {
    if (cancel.load()) {
      return Status::Cancelled("scan cancelled at frame " + std::to_string(i) + " of " + std::to_string(count));
    }
    INSPECT_RETURN_IF_ERROR(rig.stage().MoveTo(plan.z_um[i]).WithContext("frame " + std::to_string(i) + ": stage"));
    if (hdr) {
      std::vector<cv::Mat> frames;
      for (size_t k = 0; k < hdr_dt.size(); ++k) {
        INSPECT_ASSIGN_OR_RETURN(cv::Mat f, capture(i, cv::Mat(), hdr_dt[k], false, raw_name(i, "e", int(k))));
        frames.push_back(f);
      }
      INSPECT_ASSIGN_OR_RETURN(cv::Mat e, MergeRadiance(frames, hdr_dt, *bundle->camera_response));  // eq. 3.44
      const double hi = std::exp(bundle->camera_response->LogExposure(top)) / hdr_dt.front();
      const double lo = std::exp(bundle->camera_response->LogExposure(1)) / hdr_dt.back();
      INSPECT_RETURN_IF_ERROR(push(i, RadianceTo16(e, lo, hi), 0.0, fixed_name + ":hdr" + std::to_string(prm.hdr_exposures)));
      continue;
    }
    if (!adapt) {
      INSPECT_ASSIGN_OR_RETURN(cv::Mat f, capture(i, cv::Mat(), dt, true, ""));
      INSPECT_RETURN_IF_ERROR(push(i, f, dt, fixed_name));
      continue;
    }
    if (mode == IlluminationMode::kAdaptIterative) {
      // Eq. 5.5-5.6 and 5.11 repeated at this z, starting from the previous z's pattern, until
      // the error is below tolerance, stops improving, or max_iterations frames were taken.
      cv::Mat irr = irr_next, frame, pattern;
      double last_err = std::numeric_limits<double>::infinity();
      for (int k = 0;; ++k) {
        INSPECT_ASSIGN_OR_RETURN(pattern, shown(irr));
        INSPECT_ASSIGN_OR_RETURN(frame, capture(i, pattern, dt, false, raw_name(i, "it", k), /*defer_report=*/true));
        INSPECT_ASSIGN_OR_RETURN(CompensationStep st, comp->Step(prf->IrradianceImage(pattern), frame, dt, desired, irr));
        const double err = st.mean_abs_error_grey / level_scale;
        const bool done = k + 1 >= prm.max_iterations || err < prm.tolerance_grey ||
                          err > last_err * (1.0 - prm.min_improvement);
        last_err = err;
        // The last frame is the stack frame; the next z starts from the pattern that made it.
        report(pending, done);
        if (done) break;
        irr = st.projector_irradiance;
      }
      irr_next = irr;
      INSPECT_RETURN_IF_ERROR(push(i, frame, dt, "adapted"));
      continue;
    }
    // Predictive modes (eq. 5.12): show the prediction, capture the stack frame, correct once.
    INSPECT_ASSIGN_OR_RETURN(cv::Mat pattern, shown(irr_next));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, capture(i, pattern, dt, true, ""));
    INSPECT_RETURN_IF_ERROR(push(i, frame, dt, "adapted"));
    INSPECT_ASSIGN_OR_RETURN(CompensationStep st, comp->Step(prf->IrradianceImage(pattern), frame, dt, desired, irr_next));
    irr_prev = irr_cur.empty() ? st.projector_irradiance : irr_cur;
    irr_cur = st.projector_irradiance;
    INSPECT_ASSIGN_OR_RETURN(irr_next, PredictIrradiance(irr_cur, irr_prev, prm.lambda,
                                                         bundle->projector_response->relative_irradiance[0]));
  }
  out.images_acquired = acquisition;
  const auto t1 = Clock::now();
  INSPECT_RETURN_IF_ERROR(WriteStackManifest(stack_dir, m));
  INSPECT_ASSIGN_OR_RETURN(out.depth, engine->Finish());
  out.engine_finish_seconds = std::chrono::duration<double>(Clock::now() - t1).count();
  out.acquisition_seconds = std::chrono::duration<double>(t1 - t0).count();
  if (SimulationControl* sim = rig.simulation()) {
    out.ground_truth_um = sim->GroundTruthDepthUm();
    DepthExportMeta meta;
    meta.pixel_size_um = m.pixel_size_um;
    meta.description = "ground truth depth (um) of simulated specimen " + m.specimen;
    INSPECT_RETURN_IF_ERROR(WriteDepthTiff(stack_dir / kGroundTruthDepthName, out.ground_truth_um, meta));
  }
  return out;
}

}  // namespace inspection
