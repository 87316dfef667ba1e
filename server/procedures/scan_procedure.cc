#include "server/procedures/scan_procedure.h"

#include <chrono>
#include <cmath>
#include <cstdio>

#include <opencv2/imgcodecs.hpp>

#include "core/depth_export.h"

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

StatusOr<ScanOutcome> RunScan(Rig& rig, const ScanPlan& plan, const fs::path& stack_dir,
                              const std::function<void(const ScanFrameEvent&)>& on_frame,
                              const std::atomic<bool>& cancel) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  std::error_code ec;
  fs::create_directories(stack_dir, ec);
  if (ec) return Status::Internal("cannot create " + stack_dir.string() + ": " + ec.message());

  Camera& camera = rig.camera();
  INSPECT_RETURN_IF_ERROR(rig.projector().ShowUniform(plan.uniform_grey));
  INSPECT_RETURN_IF_ERROR(camera.SetExposure(plan.exposure_us));
  const int bit_depth = camera.bit_depth();
  INSPECT_ASSIGN_OR_RETURN(
      std::unique_ptr<SffEngine> engine,
      SffEngine::Create(plan.sff, camera.frame_size(), bit_depth > 8 ? CV_16UC1 : CV_8UC1));

  ScanOutcome out;
  StackManifest& m = out.manifest;
  m.pixel_size_um = rig.pixel_size_um();
  m.bit_depth = bit_depth;
  m.illumination = plan.illumination;
  m.calibration_id = plan.calibration_id;
  if (SimulationControl* sim = rig.simulation()) m.specimen = sim->specimen();
  const std::string pattern = "uniform:" + std::to_string(plan.uniform_grey);
  // Fast PNG compression: frames must be written at camera rate.
  const std::vector<int> png_params = {cv::IMWRITE_PNG_COMPRESSION, 1};

  const int count = int(plan.z_um.size());
  for (int i = 0; i < count; ++i) {
    if (cancel.load()) return Status::Cancelled("scan cancelled at frame " + std::to_string(i) + " of " +
                                                std::to_string(count));
    INSPECT_RETURN_IF_ERROR(rig.stage().MoveTo(plan.z_um[i]).WithContext("frame " + std::to_string(i) + ": stage"));
    INSPECT_ASSIGN_OR_RETURN(double z_reported, rig.stage().position_um());
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, camera.Capture());
    if (frame.size() != camera.frame_size()) {
      return Status::Internal("frame " + std::to_string(i) + ": camera delivered an unexpected size");
    }
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%04d.png", i);
    if (!cv::imwrite((stack_dir / name).string(), frame, png_params)) {
      return Status::Internal(std::string("cannot write ") + name);
    }
    // The commanded z is the stack coordinate: repeatability error is what the stage adds, and
    // the thesis evaluates against the nominal step positions.
    INSPECT_RETURN_IF_ERROR(engine->PushFrame(frame, plan.z_um[i]));
    m.frames.push_back({name, plan.z_um[i], camera.exposure_us(), pattern});
    if (on_frame) {
      ScanFrameEvent ev;
      ev.index = i;
      ev.count = count;
      ev.z_um = z_reported;
      ev.exposure_us = camera.exposure_us();
      ev.statistics = ComputeFrameStatistics(frame, bit_depth);
      on_frame(ev);
    }
  }
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
