// The stack folder -> SFF engine loop (core/stack_reconstruct.h): decode, push, report, per frame.
#include "core/stack_reconstruct.h"

#include <memory>
#include <optional>
#include <string>

namespace inspection {

namespace {

// The aligner for the folder's frames, or nullopt when the frames are used as they are.
StatusOr<std::optional<StackAligner>> PrepareAlignment(const std::filesystem::path& dir, const StackManifest& manifest,
                                                       const StackFolderAlignment& a, const std::atomic<bool>& cancel,
                                                       AlignmentFigures* figures) {
  if (figures) *figures = AlignmentFigures{};
  std::vector<double> z_um;
  for (const StackFrame& f : manifest.frames) z_um.push_back(f.z_um);
  FocusBreathingModel model;
  switch (a.alignment) {
    case FrameAlignment::kNone:
      return std::optional<StackAligner>();
    case FrameAlignment::kCalibrated:
      if (a.calibrated == nullptr) {
        return Status::FailedPrecondition(
            "alignment CALIBRATED needs the focus_breathing calibration step (missing in the active calibration)");
      }
      model = *a.calibrated;
      break;
    case FrameAlignment::kEstimate: {
      auto load = [&](int i) -> StatusOr<cv::Mat> {
        if (cancel.load())
          return Status::Cancelled("reconstruction cancelled while aligning frame " + std::to_string(i));
        return LoadStackFrame(dir, manifest, size_t(i));  // errors name the frame
      };
      StatusOr<FocusBreathingModel> estimate = EstimateFocusBreathing(load, z_um, a.options);
      if (!estimate.ok()) {
        const StatusCode code = estimate.status().code();
        if (a.fall_back_to_none && (code == StatusCode::kFailedPrecondition || code == StatusCode::kInvalidArgument)) {
          return std::optional<StackAligner>();
        }
        return estimate.status();
      }
      model = *estimate;
      break;
    }
  }
  INSPECT_ASSIGN_OR_RETURN(cv::Mat first, LoadStackFrame(dir, manifest, 0));
  INSPECT_ASSIGN_OR_RETURN(StackAligner aligner, StackAligner::Create(model, a.alignment, z_um, first.size()));
  if (figures) *figures = aligner.figures();
  return std::optional<StackAligner>(std::move(aligner));
}

}  // namespace

StatusOr<DepthResult> ReconstructStackFolder(const std::filesystem::path& dir, const StackManifest& manifest,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel, const StackFolderAlignment& alignment,
                                             AlignmentFigures* figures) {
  INSPECT_ASSIGN_OR_RETURN(std::optional<StackAligner> aligner,
                           PrepareAlignment(dir, manifest, alignment, cancel, figures));
  std::unique_ptr<SffEngine> engine;
  const int count = int(manifest.frames.size());
  for (int i = 0; i < count; ++i) {
    if (cancel.load()) return Status::Cancelled("reconstruction cancelled at frame " + std::to_string(i));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, LoadStackFrame(dir, manifest, size_t(i)));
    if (!engine) {
      INSPECT_ASSIGN_OR_RETURN(engine, SffEngine::Create(options, frame.size(), frame.type()));
    }
    const std::string name = "frame " + std::to_string(i) + " (" + manifest.frames[i].file + ")";
    if (aligner) {
      INSPECT_ASSIGN_OR_RETURN(frame, aligner->Warp(frame, i));
    }
    INSPECT_RETURN_IF_ERROR(engine->PushFrame(frame, manifest.frames[i].z_um).WithContext(name));
    if (on_frame) on_frame(i, count, manifest.frames[i].z_um, ComputeFrameStatistics(frame, manifest.bit_depth));
  }
  if (!engine) return Status::InvalidArgument("stack has no frames");
  INSPECT_ASSIGN_OR_RETURN(DepthResult result, engine->Finish());
  if (aligner) aligner->MaskUnseen(&result);
  return result;
}

}  // namespace inspection
