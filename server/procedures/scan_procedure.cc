// Scan procedure (thesis 3.1.2, Fig. 3.3): scan plan, the z loop, stack folder and engine push; what
// each z shows and captures is the illumination strategy of the mode (illumination_strategy.h).
#include "server/procedures/scan_procedure.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>

#include "core/io/depth_export.h"
#include "core/sff/stack_halo.h"
#include "core/sff/stack_reconstruct.h"
#include "server/procedures/illumination_auto.h"
#include "server/procedures/illumination_strategy.h"
#include "server/procedures/scan_alignment.h"

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
                                   "] with z_step_um " + std::to_string(z_step_um) + " gives fewer than 3 frames");
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
  if (!(min_improvement >= 0 && min_improvement < 1))
    return Status::InvalidArgument("min_improvement must be in [0, 1)");
  if (!(target_grey > 0 && target_grey < 255)) return Status::InvalidArgument("target_grey must be in (0, 255)");
  return compensation.Validate();
}

std::string IlluminationModeName(IlluminationMode mode, int hdr_exposures) {
  switch (mode) {
    case IlluminationMode::kStd:
      return "STD";
    case IlluminationMode::kHdr:
      return "HDR" + std::to_string(hdr_exposures);
    case IlluminationMode::kAdaptIterative:
      return "ADAPT-IT";
    case IlluminationMode::kAdapt:
      return "ADAPT";
    case IlluminationMode::kTexture:
      return "TEXTURE";
    case IlluminationMode::kHfAdapt:
      return "HF+ADAPT";
    case IlluminationMode::kAdaptedHf:
      return "ADAPTED-HF";
    case IlluminationMode::kAuto:
      return "AUTO";
  }
  return "?";
}

StatusOr<std::vector<double>> HdrRelativeExposures(int n) {
  switch (n) {  // thesis Table 6.2, in % of the STD exposure
    case 2:
      return std::vector<double>{0.50, 1.50};
    case 3:
      return std::vector<double>{0.50, 1.00, 2.00};
    case 4:
      return std::vector<double>{0.25, 0.75, 1.50, 2.00};
    case 5:
      return std::vector<double>{0.25, 0.50, 1.00, 2.00, 4.00};
    default:
      return Status::InvalidArgument("hdr_exposures must be in [2, 5] (thesis Table 6.2)");
  }
}

Status CheckCalibrationFor(IlluminationMode mode, const CalibrationBundle* bundle) {
  std::vector<CalibrationStep> need;
  const bool adapt = mode == IlluminationMode::kAdaptIterative || mode == IlluminationMode::kAdapt ||
                     mode == IlluminationMode::kHfAdapt || mode == IlluminationMode::kAdaptedHf;
  const bool texture =
      mode == IlluminationMode::kTexture || mode == IlluminationMode::kHfAdapt || mode == IlluminationMode::kAdaptedHf;
  if (mode == IlluminationMode::kHdr || adapt) need.push_back(CalibrationStep::kCameraResponse);
  if (adapt || texture) need.push_back(CalibrationStep::kProjectorResponse);
  if (texture) need.push_back(CalibrationStep::kGeometry);
  if (texture) need.push_back(CalibrationStep::kPsf);
  if (adapt) need.push_back(CalibrationStep::kScatterMatrix);
  std::string missing;
  for (CalibrationStep s : need) {
    if (bundle == nullptr || !bundle->HasModel(s))
      missing += std::string(missing.empty() ? "" : ", ") + CalibrationStepName(s);
  }
  if (!missing.empty()) {
    return Status::FailedPrecondition(
        "illumination " + IlluminationModeName(mode) + " needs the calibration step(s) " + missing +
        (bundle == nullptr ? " (no active calibration)" : " (missing in the active calibration)"));
  }
  return Status::Ok();
}

namespace {

// The rig during one scan as the illumination strategies see it: every capture is checked,
// stored (raw/ unless a stack frame), counted and reported here.
class ScanRecorder : public ScanCaptureContext {
 public:
  ScanRecorder(Rig& rig, const ScanPlan& plan, const fs::path& stack_dir,
               const std::function<void(const ScanFrameEvent&)>& on_frame, const std::atomic<bool>& cancel,
               ScanOutcome& out)
      : rig_(rig),
        plan_(plan),
        stack_dir_(stack_dir),
        on_frame_(on_frame),
        cancel_(cancel),
        out_(out),
        count_(int(plan.z_um.size())) {}

  Status CheckCancel(int i) const {
    if (cancel_.load()) {
      return Status::Cancelled("scan cancelled at frame " + std::to_string(i) + " of " + std::to_string(count_));
    }
    return Status::Ok();
  }

  Status MoveStageTo(int i) override {
    return rig_.stage().MoveTo(plan_.z_um[size_t(i)]).WithContext("frame " + std::to_string(i) + ": stage");
  }

  Status ShowPattern(const cv::Mat& pattern) override { return rig_.projector().Show(pattern); }

  StatusOr<cv::Mat> Capture(int i, const cv::Mat& pattern, double exposure_us, CaptureRole role,
                            const std::string& raw_name) override {
    INSPECT_RETURN_IF_ERROR(CheckCancel(i));
    Camera& camera = rig_.camera();
    if (!pattern.empty()) {
      INSPECT_RETURN_IF_ERROR(rig_.projector().Show(pattern).WithContext("frame " + std::to_string(i)));
    }
    if (camera.exposure_us() != exposure_us) INSPECT_RETURN_IF_ERROR(camera.SetExposure(exposure_us));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, camera.Capture());
    if (frame.size() != camera.frame_size()) {
      return Status::Internal("frame " + std::to_string(i) + ": camera delivered an unexpected size");
    }
    if (!raw_name.empty() && !cv::imwrite((stack_dir_ / "raw" / raw_name).string(), frame, kPngParams())) {
      return Status::Internal("cannot write raw/" + raw_name);
    }
    const bool stack_frame = role == CaptureRole::kStackFrame;
    const FrameStatistics st = ComputeFrameStatistics(frame, camera.bit_depth());
    out_.capture_statistics.push_back(st);
    out_.capture_is_stack_frame.push_back(stack_frame);
    ScanFrameEvent ev;
    ev.index = i;
    ev.count = count_;
    INSPECT_ASSIGN_OR_RETURN(ev.z_um, rig_.stage().position_um());
    ev.exposure_us = camera.exposure_us();
    ev.statistics = st;
    ev.acquisition = acquisitions_;
    if (role == CaptureRole::kUndecided)
      pending_ = ev;
    else
      Report(ev, stack_frame);
    ++acquisitions_;
    return frame;
  }

  void DecideLastCapture(bool stack_frame) override { Report(pending_, stack_frame); }

  int acquisitions() const { return acquisitions_; }

  static const std::vector<int>& kPngParams() {
    static const std::vector<int> params = {cv::IMWRITE_PNG_COMPRESSION, 1};
    return params;
  }

 private:
  void Report(ScanFrameEvent ev, bool stack_frame) {
    ev.stack_frame = stack_frame;
    out_.capture_is_stack_frame[size_t(ev.acquisition)] = stack_frame;
    if (on_frame_) on_frame_(ev);
  }

  Rig& rig_;
  const ScanPlan& plan_;
  const fs::path& stack_dir_;
  const std::function<void(const ScanFrameEvent&)>& on_frame_;
  const std::atomic<bool>& cancel_;
  ScanOutcome& out_;
  const int count_;
  int acquisitions_ = 0;
  ScanFrameEvent pending_;  // the last kUndecided capture, reported by DecideLastCapture
};

// What the stack frames stream into while they are captured: the SFF engine, ISFF-GT's NCC
// engine with the ground-truth texture, or nothing (ISFF and ISFF-FAST read the stored stack
// after the last frame).
struct StreamingReconstruction {
  std::unique_ptr<SffEngine> sff;
  std::unique_ptr<NccFocusEngine> ncc;

  Status PushFrame(const cv::Mat& frame, double z_um) {
    if (sff) return sff->PushFrame(frame, z_um);
    if (ncc) return ncc->PushFrame(frame, z_um);
    return Status::Ok();
  }
};

// Checks what the plan's reconstruction method needs before anything is captured.
StatusOr<StreamingReconstruction> CreateStreamingReconstruction(Rig& rig, const ScanPlan& plan,
                                                                const CalibrationBundle* bundle, int frame_type) {
  const ReconstructionMethodSettings& method = plan.reconstruction;
  StreamingReconstruction r;
  if (!method.integral()) {
    // Unthresholded: the post-processing's consistency check needs every pixel's depth, and it
    // applies plan.sff.min_confidence itself.
    SffOptions unthresholded = plan.sff;
    unthresholded.min_confidence = 0.0;
    INSPECT_ASSIGN_OR_RETURN(r.sff, SffEngine::Create(unthresholded, rig.camera().frame_size(), frame_type));
    return r;
  }
  INSPECT_RETURN_IF_ERROR(method.Validate());
  INSPECT_RETURN_IF_ERROR(CheckIntegralIllumination(IlluminationModeName(plan.mode, plan.params.hdr_exposures)));
  if (method.method != ReconstructionMethod::kIsffGroundTruth) {
    INSPECT_RETURN_IF_ERROR(CheckIntegralPsfFor(bundle));
    return r;
  }
  SimulationControl* sim = rig.simulation();
  if (sim == nullptr) {
    return Status::FailedPrecondition(
        "ISFF-GT needs the simulated rig's ground-truth texture; this rig is not simulated (use ISFF)");
  }
  // STD shows one uniform grey at one exposure through the stack: the texture under the same.
  const cv::Mat pattern(rig.projector().resolution(), CV_8UC1, cv::Scalar(plan.uniform_grey));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat texture, sim->GroundTruthTexture(pattern, plan.exposure_us));
  const IsffOptions options = IsffOptionsFor(method, plan.sff);
  INSPECT_RETURN_IF_ERROR(options.Validate());
  INSPECT_ASSIGN_OR_RETURN(r.ncc, NccFocusEngine::Create(options.ncc, texture, frame_type));
  return r;
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
  INSPECT_RETURN_IF_ERROR(plan.params.Validate());
  INSPECT_RETURN_IF_ERROR(CheckCalibrationFor(plan.mode, bundle));
  Camera& camera = rig.camera();
  Projector& projector = rig.projector();
  if (bundle != nullptr && plan.mode != IlluminationMode::kStd &&
      (bundle->camera_size != camera.frame_size() || bundle->projector_size != projector.resolution())) {
    return Status::FailedPrecondition("the active calibration was made for another camera/projector size");
  }
  std::error_code ec;
  fs::create_directories(stack_dir / "raw", ec);
  if (ec) return Status::Internal("cannot create " + stack_dir.string() + ": " + ec.message());

  const IlluminationSetup setup{camera.frame_size(), projector.resolution(), camera.bit_depth()};
  ScanOutcome out;
  ScanRecorder recorder(rig, plan, stack_dir, on_frame, cancel, out);
  // AUTO probes the specimen first; from then on the scan runs the chosen mode's plan. Every
  // mode AUTO can choose keeps the camera's bit depth, so the engine can be set up after it.
  ScanPlan chosen = plan;
  if (plan.mode == IlluminationMode::kAuto) {
    INSPECT_ASSIGN_OR_RETURN(IlluminationChoice choice, ProbeAndChooseIllumination(recorder, plan, bundle, setup));
    chosen.mode = choice.mode;
    out.illumination_decision = choice.reasons;
  }
  out.illumination = chosen.mode;
  const std::unique_ptr<IlluminationStrategy> illumination = CreateIlluminationStrategy(chosen, bundle, setup);
  const int stack_bit_depth = illumination->stack_bit_depth();
  const int frame_type = stack_bit_depth > 8 ? CV_16UC1 : CV_8UC1;
  INSPECT_ASSIGN_OR_RETURN(StreamingReconstruction engine,
                           CreateStreamingReconstruction(rig, chosen, bundle, frame_type));
  INSPECT_ASSIGN_OR_RETURN(std::optional<StackAligner> aligner, CreateScanAligner(chosen, bundle, camera.frame_size()));

  StackManifest& m = out.manifest;
  m.pixel_size_um = rig.pixel_size_um();
  m.bit_depth = stack_bit_depth;
  m.illumination = IlluminationModeName(chosen.mode, chosen.params.hdr_exposures);
  m.illumination_decision = out.illumination_decision;
  m.calibration_id = plan.calibration_id;
  if (SimulationControl* sim = rig.simulation()) m.specimen = sim->specimen();
  const int count = int(plan.z_um.size());

  INSPECT_RETURN_IF_ERROR(illumination->Prepare(recorder));
  for (int i = 0; i < count; ++i) {
    INSPECT_RETURN_IF_ERROR(recorder.CheckCancel(i));
    INSPECT_RETURN_IF_ERROR(recorder.MoveStageTo(i));
    INSPECT_ASSIGN_OR_RETURN(CapturedStackFrame frame, illumination->CaptureStackFrame(i, recorder));
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%04d.png", i);
    if (!cv::imwrite((stack_dir / name).string(), frame.image, ScanRecorder::kPngParams())) {
      return Status::Internal(std::string("cannot write ") + name);
    }
    // The commanded z is the stack coordinate: repeatability error is what the stage adds, and
    // the thesis evaluates against the nominal step positions.
    INSPECT_ASSIGN_OR_RETURN(cv::Mat aligned, AlignScanFrame(aligner, frame.image, i));
    INSPECT_RETURN_IF_ERROR(engine.PushFrame(aligned, plan.z_um[size_t(i)]));
    m.frames.push_back({name, plan.z_um[size_t(i)], frame.exposure_us, frame.pattern});
  }
  out.images_acquired = recorder.acquisitions();
  const auto t1 = Clock::now();
  // The stored frames stay as captured; stack.json says how the engine saw them.
  m.alignment = AlignmentRecordOf(aligner ? aligner->figures() : AlignmentFigures{});
  INSPECT_RETURN_IF_ERROR(WriteStackManifest(stack_dir, m));
  if (engine.sff) {
    INSPECT_ASSIGN_OR_RETURN(DepthResult raw, engine.sff->Finish());
    if (plan.halo) {
      // From the frames just written (lossless PNG: the pixels the engine had), aligned as the
      // engine saw them.
      StackFrameSource frames{[&](int i) { return DecodeStackFrame(stack_dir, m, size_t(i)); }, {}, {}};
      HaloSuppressionFigures halo;
      INSPECT_ASSIGN_OR_RETURN(raw, SuppressStackHalos(raw, m, frames, aligner ? aligner->figures() : AlignmentFigures{}, plan.sff,
                                                       *plan.halo, &halo));
      out.halo = halo;
    }
    DepthPostProcessOptions post = plan.postprocess;
    post.min_confidence = plan.sff.min_confidence;
    INSPECT_ASSIGN_OR_RETURN(out.depth, PostProcessDepth(raw, plan.z_um, plan.sff.window_px, post, &out.postprocess));
  } else if (engine.ncc) {
    INSPECT_ASSIGN_OR_RETURN(out.depth, engine.ncc->Finish());
    out.isff.frame_noise_sigma = 0.0;  // ISFF-GT's template is noise-free; nothing is estimated
    out.isff.frames_searched_fraction = cv::mean(engine.ncc->frames_searched())[0] / double(count);
  } else {
    // ISFF, ISFF-FAST: the restored template needs the whole stack (core/sff/integral_sff.h).
    INSPECT_RETURN_IF_ERROR(recorder.CheckCancel(count));
    INSPECT_ASSIGN_OR_RETURN(IsffResult isff,
                             ReconstructStackFolderIntegralSff(stack_dir, plan.reconstruction, plan.sff, bundle));
    out.depth = std::move(isff.depth);
    out.isff = FiguresOf(isff);
  }
  if (aligner) {
    MaskUnseenPixels(*aligner, &out.depth);
    out.alignment = aligner->figures();
  }
  out.engine_finish_seconds = std::chrono::duration<double>(Clock::now() - t1).count();
  out.acquisition_seconds = std::chrono::duration<double>(t1 - t0).count();
  if (const SimulationControl* sim = rig.simulation()) {
    // In the grid of the middle frame, the alignment's reference (the specimen grid without
    // focus breathing).
    out.ground_truth_um = sim->GroundTruthInCameraGridUm(plan.z_um[(plan.z_um.size() - 1) / 2]);
    DepthExportMeta meta;
    meta.pixel_size_um = m.pixel_size_um;
    meta.description = "ground truth depth (um) of simulated specimen " + m.specimen;
    INSPECT_RETURN_IF_ERROR(WriteDepthTiff(stack_dir / kGroundTruthDepthName, out.ground_truth_um, meta));
  }
  return out;
}

}  // namespace inspection
