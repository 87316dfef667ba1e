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

StackAlignmentRecord AlignmentRecordOf(const AlignmentFigures& a) {
  StackAlignmentRecord r;
  r.alignment = FrameAlignmentName(a.alignment);
  r.method = a.method;
  r.still = a.still;
  r.fallback_reason = a.fallback_reason;
  r.reference_frame = a.reference_frame;
  r.max_scale_change_percent = a.max_scale_change_percent;
  r.max_shift_px = a.max_shift_px;
  r.seen_by_every_frame_percent = a.seen_by_every_frame_percent;
  r.max_corner_displacement_px = a.max_corner_displacement_px;
  const cv::Point2d centre((a.frame_size.width - 1) * 0.5, (a.frame_size.height - 1) * 0.5);
  for (size_t i = 0; i < a.frame_from_reference.size(); ++i) {
    const cv::Matx23d& m = a.frame_from_reference[i];
    const SimilarityTransform t = SimilarityOf(m, centre);
    StackFrameTransform f;
    f.frame = int(i);
    f.scale = t.scale;
    f.rotation_deg = t.rotation_rad * 180.0 / CV_PI;
    f.shift_x_px = t.shift_x_px;
    f.shift_y_px = t.shift_y_px;
    for (int k = 0; k < 6; ++k) f.affine[size_t(k)] = m(k / 3, k % 3);
    r.frames.push_back(f);
  }
  return r;
}

}  // namespace inspection
