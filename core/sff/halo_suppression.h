// Halo suppression for shape from focus and the all-in-focus image: z-ordered re-selection of a
// pixel's focus peak near a depth jump. A bright edge defocused in front of a darker background
// spreads its blurred gradient over the background (thin lens with occlusion: the foreground's
// blur circle lies over whatever is behind it); the focus measure of thesis 3.1.3 at a background
// pixel then peaks at the frame whose blur circle reaches that pixel, not at the background's own
// focus, and the depth map and the all-in-focus image show a halo around the object (focus-stack's
// most reported defect, its issue #8: "the widened blur from other images gets mistaken as
// background detail").
//
// Method (z order; two more passes over the frames after the engine). Memory, from its buffers
// (not measured): about 145 bytes per pixel (the depth levels' window sums dominate: 84 bytes at
// layer_half_width_frames 2) plus 72 per candidate pixel, i.e. ~6x the engine's 23-byte state;
// time: two focus-measure passes and 3 box filters per depth level, 11-35x the in-memory engine
// on the bench's small scenes (not optimised).
// - Layers near a pixel, from the engine's depth map: the depth levels (+- layer_half_width_frames)
//   that at least min_layer_support of the confident pixels within band_radius_px have. The
//   occluder: the level whose pixels have the highest typical peak focus (geometric mean; a
//   bright or high-contrast surface, whose blur is what spreads). The surface behind its blur:
//   the best-supported level at least min_jump_frames from it.
// - A pixel is that surface, not what the engine said, when it shows none of the occluder's sharp
//   content (its focus in the occluder's frames is below max_other_layer_ratio of the occluder's
//   typical value: the occluder's edge is not in its window, only its blur can reach it), its
//   depth is not already the surface's, its focus in the surface's frames is consistent with the
//   surface's (>= min_layer_focus_ratio of its typical value) and its own peak outshines the
//   surface (>= min_own_peak_ratio of the surface's typical value: a bright blur's does).
// - Such a pixel takes the surface's depth: its own peak inside the surface's frames when it has
//   one (interpolated as the engine does), else (depth_from_surface_without_peak, off by default)
//   the surface's mean depth around it; and its all-in-focus value from the frame where the
//   occluder is in focus (its blur is then absent; all_in_focus_from_occluder_focus).
// What it cannot undo: pixels within half the focus window of the edge, whose window holds the
// sharp edge itself (SFF's edge fattening: the occluder's sharp content is there), and a surface
// without texture. Opt-in (ReconstructionOptions.halo_suppression, `--halo-suppression`; on a
// stack folder: core/sff/stack_halo.h); figures and limits on halo and natural scenes:
// tests/bench/halo_evaluate_output.md.
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <vector>

#include "core/sff/sff_engine.h"
#include "core/sff/sff_options.h"
#include "core/util/status.h"

namespace inspection {

struct HaloSuppressionOptions {
  // How far a defocused edge's blur reaches into its neighbour, px: the blur-circle radius of the
  // foreground at the background's focus. Pixels this close to a depth jump are re-examined.
  // 2..64; tests/bench/halo_evaluate.cc measures 8, 15 and 25.
  int band_radius_px = 15;
  // A depth jump: the lowest and highest layers within band_radius_px are at least this many
  // frames apart (>= 2 layer_half_width_frames).
  double min_jump_frames = 4.0;
  // A layer: depths within +- this many frames (1..4) of a level that at least
  // min_layer_support of the band_radius_px window's pixels have (confidently), (0, 1).
  int layer_half_width_frames = 2;
  double min_layer_support = 0.03;
  // The pixel is not a layer's surface when its focus in that layer's frames is below this share
  // of the layer's typical peak focus (geometric mean over the layer's pixels in the window).
  double max_other_layer_ratio = 0.2;
  // ... and it belongs to the other layer when its focus in that layer's frames reaches this
  // share of that layer's typical value, (0, 10].
  double min_layer_focus_ratio = 0.3;
  // ... and when its own peak focus value (what the engine chose) is at least this share of the
  // surface's typical value, >= 0: a bright occluder's blur outshines the surface it covers,
  // where a pixel of another surface of its own need not.
  double min_own_peak_ratio = 1.0;
  // A moved pixel without a focus peak of its own in the surface's frames (the occluder's blur
  // covers it there too) takes the surface's mean depth around it; false (the default): it keeps
  // the engine's depth (and gets the occluder-free all-in-focus value). On: a further -30 % halo
  // depth error on the halo scenes, but on the natural scenes' sloped and undulating backgrounds
  // the window's mean depth is off and their error more than doubles (halo_evaluate --sweep).
  bool depth_from_surface_without_peak = false;
  // Pixels that define the layers and their typical focus: engine confidence >= this, [0, 1).
  double min_confidence = 0.4;
  // All-in-focus value of a moved pixel: true = from the frame where the occluder (whose blur
  // reached it) is in focus, so that blur is absent and the surface behind is seen defocused;
  // false = from the surface's own frame (sharp, but veiled by the occluder's blur).
  bool all_in_focus_from_occluder_focus = true;

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

struct HaloSuppressionFigures {
  double candidate_fraction = 0.0;   // of all pixels: with an occluder and a surface behind it in the window
  double reassigned_fraction = 0.0;  // of all pixels: moved to another layer's peak
};

// first: the engine's result for the stack with SffOptions::min_confidence 0 (every pixel's
// unthresholded depth and its confidence). frame(i): frame i of the all-in-focus image's type
// (grey CV_8UC1 / CV_16UC1, or BGR CV_8UC3 / CV_16UC3 measured on its luminance as the engine
// does) as the engine measured it (aligned), asked for twice, in z order each time (the peak
// focus values, then the candidates' focus and pixel values). z_um: the frames' positions
// (strictly monotonic). sff: the engine's options (its focus measure, window and interpolation).
// Returns first with depth_um and all_in_focus changed at the reassigned pixels (confidence
// unchanged: the same curve), ready for PostProcessDepth. Errors: INVALID_ARGUMENT naming the
// option or the frame that does not match.
StatusOr<DepthResult> SuppressHalos(const DepthResult& first, const std::function<StatusOr<cv::Mat>(int)>& frame,
                                    const std::vector<double>& z_um, const SffOptions& sff,
                                    const HaloSuppressionOptions& options, HaloSuppressionFigures* figures = nullptr);

}  // namespace inspection
