// The post-processing of one SFF depth map, in order: confidence threshold (thesis 3.1.4's
// depth is kept where core/sff/depth_interpolation.h's confidence allows), local depth consistency
// (core/sff/depth_consistency.h), optional guided refinement (core/sff/depth_refinement.h) and optional
// fill of the pixels left without depth (core/sff/depth_fill.h). One options struct, so the server,
// the CLI and the evaluations run the same steps with the same defaults.
#pragma once

#include <vector>

#include "core/sff/dense_depth.h"
#include "core/sff/depth_consistency.h"
#include "core/sff/depth_fill.h"
#include "core/sff/depth_refinement.h"
#include "core/sff/sff_engine.h"
#include "core/util/status.h"

namespace inspection {

struct DepthPostProcessOptions {
  // As SffOptions::min_confidence; the engine itself runs with 0 so that every pixel has the
  // unthresholded depth the consistency step needs.
  double min_confidence = 0.4;
  // Local depth consistency; max_residual_z_steps 1 and the focus window + 1 px were chosen on
  // the natural focal stacks without changing the microscope specimens' sigma (docs/reconstruction.md).
  bool consistency = true;
  DepthConsistencyOptions consistency_options;
  // Guided refinement: off by default (it moved the natural-scene RMSE by < 10 % after the
  // consistency step, at several times the engine's cost).
  DepthRefinementOptions refinement{DepthRefinement::kNone};
  // Fill pixels without depth from measured neighbours: off by default (metrology reports NaN
  // where nothing was measured; a filled value is an interpolation).
  bool fill_low_confidence = false;
  DepthFillOptions fill_options;
  // Dense depth (core/sff/dense_depth.h): an edge-aware confidence-weighted fit gives every pixel
  // a depth; measured pixels keep theirs, inferred ones keep confidence < min_confidence. Off
  // here (rig scans: NaN where unmeasured); the server turns it on for imported stacks. Takes
  // precedence over fill_low_confidence.
  bool dense = false;
  DenseDepthOptions dense_options;
  // With dense: the confidence ranks pixels by how far their depth can be trusted. An inferred
  // pixel (unmeasured, or a rejected measurement: x its agreement too) gets min_confidence x the
  // fit's support there (just below min_confidence amid confident measurements, 0 far from any); a
  // measured one keeps at least min_confidence, the part above it scaled by its agreement with
  // the fit. false: inferred pixels keep the engine's confidence, rejected ones 0.
  bool dense_confidence = true;
  // With dense_confidence: an inferred pixel's rank is also multiplied by the square root of the
  // share of measured pixels within dense_rank_radius_px (a (2r + 1)^2 box), so that of two
  // pixels the fit supports alike, the one amid measurements ranks above the one at the end of
  // a long reach along the guide. 0: off (the default). 8 was the best radius on the tuning
  // scenes (seeds 1-8; RMSE over the most confident half 1.268 -> 1.193 frames, AUSE 1.106 ->
  // 0.972) but on held-out scenes it moved the 50 % figure both ways (seeds 9-16 1.015 -> 0.963,
  // 301-308 2.395 -> 2.435, 501-516 1.573 -> 1.484, 701-716 1.869 -> 2.089), so it stays off
  // (tests/bench/natural_heldout_output.md).
  int dense_rank_radius_px = 0;
  // With dense_confidence: the rank is also divided by 1 + (spread / s)^2, spread = the weighted
  // RMS residual of the measured depths the fit draws on at the pixel about its local plane
  // (DenseDepth::spread_um), s = dense_rank_spread_z_steps x the stack's median z step: a pixel
  // filled from measurements that agree ranks above one filled where the fit mixes surfaces at
  // different depths. dense_rank_spread_measured: the part of a measured pixel's confidence above
  // min_confidence is scaled by the same factor (measured pixels still rank above inferred ones).
  // 0: off. 1 z step, measured too, chosen on the tuning scenes (seeds 1-8) of natural-evaluate
  // --experiments among 0.25..4 (RMSE over the most confident half 1.268 -> 1.028 frames, AUSE
  // 1.106 -> 0.859; the depth itself is unchanged; held out: 0.54x -> 0.50x focus-stack's on 56
  // scenes; tests/bench/natural_heldout_output.md).
  double dense_rank_spread_z_steps = 1.0;
  bool dense_rank_spread_measured = true;

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

// raw: the engine's result with SffOptions::min_confidence = 0 (finite depth everywhere). z_um:
// the stack's stage positions (z step for the consistency limit); focus_window_px: the engine's
// window. Returns raw with depth_um post-processed, valid_fraction recounted (filled pixels
// count as valid), and confidence set to 0 where the consistency step rejected a pixel, so that
// "confidence >= min_confidence" still means "measured". all_in_focus is kept (the guide).
struct DepthPostProcessFigures {
  double consistency_rejected_fraction = 0.0;  // of all pixels: above the threshold, rejected by consistency
  double filled_fraction = 0.0;                // of all pixels: depth filled, not measured
};
StatusOr<DepthResult> PostProcessDepth(const DepthResult& raw, const std::vector<double>& z_um, int focus_window_px,
                                       const DepthPostProcessOptions& options,
                                       DepthPostProcessFigures* figures = nullptr);

}  // namespace inspection
