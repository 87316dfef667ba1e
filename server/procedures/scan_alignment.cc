// Scan-time lateral alignment with the calibrated focus-breathing model (scan_alignment.h).
#include "server/procedures/scan_alignment.h"

#include <string>

namespace inspection {

StatusOr<std::optional<StackAligner>> CreateScanAligner(const ScanPlan& plan, const CalibrationBundle* bundle,
                                                        cv::Size frame_size) {
  const bool have_model = bundle != nullptr && bundle->focus_breathing.has_value();
  FrameAlignment a = plan.alignment.value_or(have_model ? FrameAlignment::kCalibrated : FrameAlignment::kNone);
  if (plan.reconstruction.integral() && !plan.alignment) a = FrameAlignment::kNone;
  switch (a) {
    case FrameAlignment::kNone:
      return std::optional<StackAligner>();
    case FrameAlignment::kEstimate:
      return Status::InvalidArgument(
          "reconstruction.alignment ESTIMATE needs the whole stack; scans align with the calibrated model");
    case FrameAlignment::kCalibrated:
      break;
  }
  if (!have_model) {
    return Status::FailedPrecondition(
        "reconstruction.alignment CALIBRATED needs the calibration step focus_breathing (missing in the active "
        "calibration)");
  }
  auto aligner = StackAligner::Create(*bundle->focus_breathing, a, plan.z_um, frame_size);
  if (!aligner.ok()) return aligner.status().WithContext("reconstruction.alignment CALIBRATED");
  return std::optional<StackAligner>(std::move(aligner).value());
}

StatusOr<cv::Mat> AlignScanFrame(const std::optional<StackAligner>& aligner, const cv::Mat& frame, int index) {
  if (!aligner) return frame;
  return aligner->Warp(frame, index);
}

}  // namespace inspection
