// Threshold, consistency, refinement, fill in one pass over the options (core/depth_postprocess.h).
#include "core/depth_postprocess.h"

#include <cmath>
#include <limits>

namespace inspection {

Status DepthPostProcessOptions::Validate() const {
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) {
    return Status::InvalidArgument("min_confidence must be between 0 and 1");
  }
  if (consistency) INSPECT_RETURN_IF_ERROR(consistency_options.Validate());
  INSPECT_RETURN_IF_ERROR(refinement.Validate());
  if (fill_low_confidence) INSPECT_RETURN_IF_ERROR(fill_options.Validate());
  return Status::Ok();
}

StatusOr<DepthResult> PostProcessDepth(const DepthResult& raw, const std::vector<double>& z_um, int focus_window_px,
                                       const DepthPostProcessOptions& o, DepthPostProcessFigures* figures) {
  INSPECT_RETURN_IF_ERROR(o.Validate());
  if (raw.depth_um.empty() || raw.depth_um.type() != CV_32FC1 || raw.confidence.type() != CV_32FC1 ||
      raw.confidence.size() != raw.depth_um.size()) {
    return Status::InvalidArgument("depth result must carry CV_32FC1 depth and confidence of one size");
  }
  DepthResult out = raw;
  out.depth_um = raw.depth_um.clone();
  out.confidence = raw.confidence.clone();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  out.depth_um.setTo(nan, out.confidence < o.min_confidence);
  if (o.consistency) {
    const double z_step = MedianZStep(z_um);
    if (!(z_step > 0.0)) return Status::InvalidArgument("z_um must hold at least two distinct positions");
    INSPECT_ASSIGN_OR_RETURN(cv::Mat kept, RejectInconsistentDepth(out.depth_um, raw.depth_um, z_step, focus_window_px,
                                                                   o.consistency_options, raw.all_in_focus));
    // Rejected here (finite before, NaN now): not measured, whatever the curve's own confidence.
    // (cv::compare's CMP_NE is false for NaN, so NaN is found as "not equal to itself" via ~EQ.)
    const cv::Mat rejected = (out.depth_um == out.depth_um) & ~(kept == kept);
    out.confidence.setTo(0.f, rejected);
    if (figures) figures->consistency_rejected_fraction = double(cv::countNonZero(rejected)) / double(rejected.total());
    out.depth_um = kept;
  }
  if (o.refinement.method != DepthRefinement::kNone) {
    INSPECT_ASSIGN_OR_RETURN(out.depth_um, RefineDepth(out.depth_um, out.confidence, raw.all_in_focus, o.refinement));
  }
  if (o.fill_low_confidence) {
    const int before = cv::countNonZero(out.depth_um == out.depth_um);
    INSPECT_ASSIGN_OR_RETURN(out.depth_um, FillDepth(out.depth_um, out.confidence, raw.all_in_focus, o.fill_options));
    if (figures) {
      figures->filled_fraction =
          double(cv::countNonZero(out.depth_um == out.depth_um) - before) / double(out.depth_um.total());
    }
  }
  out.valid_fraction = double(cv::countNonZero(out.depth_um == out.depth_um)) / double(out.depth_um.total());
  return out;
}

}  // namespace inspection
