// A job result's proto from its domain parts (result_proto.h).
#include "server/jobs/result_proto.h"

namespace inspection {

namespace {

// The reconstruction method and, for the integral methods, their figures (DepthSummary).
void FillMethod(const ReconstructionMethodSettings& m, const IntegralSffFigures& figures, v1::DepthSummary* d) {
  switch (m.method) {
    case ReconstructionMethod::kSff:
      d->set_method(v1::RECONSTRUCTION_METHOD_SFF);
      return;
    case ReconstructionMethod::kIsff:
      d->set_method(v1::RECONSTRUCTION_METHOD_ISFF);
      break;
    case ReconstructionMethod::kIsffGroundTruth:
      d->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
      break;
    case ReconstructionMethod::kIsffFast:
      d->set_method(v1::RECONSTRUCTION_METHOD_ISFF_FAST);
      d->set_isff_fast_threshold(m.isff_fast_threshold);
      break;
  }
  d->set_frame_noise_sigma(figures.frame_noise_sigma);
  d->set_frames_searched_fraction(figures.frames_searched_fraction);
}

// What the SFF post-processing took away and filled (DepthSummary 26..27).
void FillPostProcess(const DepthPostProcessFigures& f, v1::DepthSummary* d) {
  d->set_consistency_rejected_percent(100.0 * f.consistency_rejected_fraction);
  d->set_filled_percent(100.0 * f.filled_fraction);
}

// How the alignment was found, the still decision, the default's fallback reason and every
// frame's transform (DepthSummary.alignment_detail).
void FillAlignmentDetail(const AlignmentFigures& a, v1::AlignmentDetail* out) {
  out->set_method(a.method);
  out->set_still(a.still);
  out->set_fallback_reason(a.fallback_reason);
  out->set_decision(a.decision);
  out->set_reference_frame(a.reference_frame);
  out->set_still_statistic(a.still_statistic);
  out->set_still_threshold(a.still_threshold);
  out->set_max_corner_displacement_px(a.max_corner_displacement_px);
  const cv::Point2d centre((a.frame_size.width - 1) * 0.5, (a.frame_size.height - 1) * 0.5);
  for (size_t i = 0; i < a.frame_from_reference.size(); ++i) {
    const cv::Matx23d& m = a.frame_from_reference[i];
    const SimilarityTransform t = SimilarityOf(m, centre);
    v1::FrameTransform* f = out->add_frames();
    f->set_frame(int(i));
    f->set_scale(t.scale);
    f->set_rotation_deg(t.rotation_rad * 180.0 / CV_PI);
    f->set_shift_x_px(t.shift_x_px);
    f->set_shift_y_px(t.shift_y_px);
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 3; ++c) f->add_affine(m(r, c));
  }
}

// The lateral alignment that ran and its figures (DepthSummary 22..25, alignment_detail).
void FillAlignment(const AlignmentFigures& a, v1::DepthSummary* d) {
  switch (a.alignment) {
    case FrameAlignment::kNone:
      d->set_alignment(v1::FRAME_ALIGNMENT_NONE);
      break;
    case FrameAlignment::kEstimate:
      d->set_alignment(v1::FRAME_ALIGNMENT_ESTIMATE);
      break;
    case FrameAlignment::kCalibrated:
      d->set_alignment(v1::FRAME_ALIGNMENT_CALIBRATED);
      break;
  }
  d->set_alignment_max_scale_change_percent(a.max_scale_change_percent);
  d->set_alignment_max_shift_px(a.max_shift_px);
  d->set_alignment_seen_percent(a.seen_by_every_frame_percent);
  FillAlignmentDetail(a, d->mutable_alignment_detail());
}

}  // namespace

v1::ZRangeSearchResult ZRangeSearchProto(const ZRangeSearchRecord& r) {
  v1::ZRangeSearchResult z;
  z.set_window_start_um(r.window_start_um);
  z.set_window_end_um(r.window_end_um);
  z.set_coarse_step_um(r.coarse_step_um);
  z.set_coarse_frame_count(int(r.coarse_frames.size()));
  z.set_refine_frame_count(int(r.refine_frames.size()));
  z.set_focus_low_um(r.focus_low_um);
  z.set_focus_high_um(r.focus_high_um);
  z.set_resolved_percent(r.resolved_percent);
  z.set_settled_percent(r.settled_percent);
  z.set_stopped_early(r.stopped_early);
  z.set_margin_um(r.margin_um);
  z.set_z_start_um(r.z_start_um);
  z.set_z_end_um(r.z_end_um);
  z.set_search_seconds(r.search_seconds);
  return z;
}

v1::DepthSummary DepthSummaryProto(const DepthSummaryParts& p) {
  v1::DepthSummary d = SummariseDepth(p.depth, p.pixel_size_um, p.ground_truth_um, p.window_px);
  d.set_engine_seconds(p.engine_seconds);
  if (p.method && p.integral) FillMethod(*p.method, *p.integral, &d);
  d.set_illumination(p.illumination);
  d.set_illumination_decision(p.illumination_decision);
  if (p.z_range_search) *d.mutable_z_range_search() = ZRangeSearchProto(*p.z_range_search);
  if (p.alignment) FillAlignment(*p.alignment, &d);
  if (p.postprocess) FillPostProcess(*p.postprocess, &d);
  if (p.halo) {
    d.set_halo_candidate_percent(100.0 * p.halo->candidate_fraction);
    d.set_halo_reassigned_percent(100.0 * p.halo->reassigned_fraction);
  }
  return d;
}

}  // namespace inspection
