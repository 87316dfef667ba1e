// Reconstructs a stack folder (core/io/stack.h) through the streaming SFF engine (thesis 3.1):
// frames are decoded and pushed one at a time, as if from the camera, so memory stays
// O(pixels). The one stack-folder -> engine loop: Reconstruct jobs and the tests use it.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <optional>

#include "core/io/frame_statistics.h"
#include "core/sff/sff_engine.h"
#include "core/io/stack.h"
#include "core/registration/chain_registration.h"
#include "core/registration/stack_alignment.h"
#include "core/util/status.h"

namespace inspection {

// NaN depth and zero confidence (and black all-in-focus) where some frame of the aligned stack
// did not see the pixel (StackAligner::seen_by_every_frame); nothing when the aligner warps none.
void MaskUnseenPixels(const StackAligner& aligner, DepthResult* result);

// Called after each frame is pushed: (frame index, frame count, z_um, grey-value statistics).
using StackFrameCallback = std::function<void(int, int, double, const FrameStatistics&)>;

// How the frames of a stack folder are aligned before the focus measure (core/registration/stack_alignment.h).
struct StackFolderAlignment {
  FrameAlignment alignment = FrameAlignment::kNone;
  const FocusBreathingModel* calibrated = nullptr;  // kCalibrated: the model (must outlive the call)
  // kEstimate only: when no frame pair registers at all (a featureless stack: no evidence of
  // motion either way), reconstruct unaligned instead of failing (the server's default for
  // imported stacks; an explicit request fails). figures->alignment then says kNone and
  // figures->fallback_reason why, naming the pairs; likewise (chain) for frames under 32x32 px or
  // fewer than 3 frames. A chain some of whose pairs register but which cannot be aligned (pairs
  // failing or disagreeing) fails either way, naming the pairs.
  bool fall_back_to_none = false;
  StackAlignmentOptions options;
  // kEstimate: imported stacks (a folder's z is nominal; stack.json names no illumination) are
  // registered as a chain of neighbours (core/registration/chain_registration.h); a rig's scan
  // (stack.json names its illumination; z is the stage's) gets the linear-in-z focus-breathing
  // model estimated from its frames, as kCalibrated uses the calibrated one.
  ChainRegistrationOptions chain;
  // kEstimate on a stack whose stack.json names no illumination (imported): the chain instead
  // of the linear-in-z estimate (false: the linear-in-z estimate for every stack). With
  // fall_back_to_none (the default) an imported stack gets the linear estimate first, which
  // decides most still stacks at a fraction of the chain's cost; where that model does not fit
  // (a focus rail) the chain registers it, and figures->decision says so.
  bool chain_for_imported_stacks = true;
  // With fall_back_to_none (the default) on an imported stack: the still floor of the linear
  // estimate and of the chain. A stack whose measured motion moves no frame corner by this much
  // is left as captured, and figures->decision names the motion and the floor when the motion
  // was significant (kImportedWarpPaysPx: below it a warp does not pay in depth accuracy). A rig's
  // scan keeps options.min_motion_px (kNegligibleAlignmentPx); an explicit request keeps the
  // chain's own floor (chain.min_motion_px).
  double imported_default_min_motion_px = kImportedWarpPaysPx;
};

// manifest: as read by ReadStackManifest(dir). on_frame may be empty. cancel is polled before
// each frame: CANCELLED naming the frame. Errors name the frame and its file, e.g.
// "frame 3 (frame_0003.png): ...".
// Alignment: kEstimate first registers the frames (one pass over the folder, two frames in
// memory), then every frame is warped onto the middle frame's grid as it is pushed (StackAligner:
// a negligible model leaves the frames as they are); the depth map is in that grid, NaN where a
// frame did not see the pixel. figures (may be null) receives what ran.
// Colour stacks (core/io/stack.h): focus is measured on each frame's luminance (core/io/colour.h) and
// result.all_in_focus is the colour image (CV_8UC3 / CV_16UC3, BGR) composed beside the engine
// (AllInFocusComposer + FocusScore, O(pixels)): its luminance is the engine's grey all-in-focus.
// Grey stacks give exactly the engine's result. A frame whose channel count differs from frame
// 0's is INVALID_ARGUMENT naming it.
StatusOr<DepthResult> ReconstructStackFolder(const std::filesystem::path& dir, const StackManifest& manifest,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel,
                                             const StackFolderAlignment& alignment = {},
                                             AlignmentFigures* figures = nullptr);

// The frames of a stack, by index, as stored (CV_8U/16U, 1 or 3 channels; DecodeStackFrame):
// ReconstructStackFrames asks for them strictly in z order (twice with kEstimate alignment: the
// registration pass, then the engine pass) and calls release(i) once frame i is in the engine.
struct StackFrameSource {
  std::function<StatusOr<cv::Mat>(int)> frame;
  std::function<void(int)> release;  // may be empty
  // May be empty or return nullopt: the statistics of grey frame(index) as stored, if already
  // known (a StackFrameDecoder computes them on its threads); else they are computed here.
  std::function<std::optional<FrameStatistics>(int)> statistics;

  // The grey image focus is measured on: frame(index) as stored, or a colour frame's luminance
  // (LuminanceOf, core/io/colour.h).
  StatusOr<cv::Mat> grey(int index) const;
};

// ReconstructStackFolder on frames from `source` (e.g. a StackFrameDecoder,
// core/io/stack_frame_decoder.h) instead of the folder: the same loop, the same result bit for bit.
StatusOr<DepthResult> ReconstructStackFrames(const StackManifest& manifest, const StackFrameSource& source,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel,
                                             const StackFolderAlignment& alignment = {},
                                             AlignmentFigures* figures = nullptr);

// Largest displacement (px) of a frame corner over the frames at z_um under the model,
// relative to the middle frame: below ~0.5 px alignment changes nothing measurable.
double MaxCornerDisplacementPx(const FocusBreathingModel& model, const std::vector<double>& z_um);

}  // namespace inspection
