// The stack folder -> SFF engine loop (core/sff/stack_reconstruct.h): decode, push, report, per frame.
#include "core/sff/stack_reconstruct.h"

#include <algorithm>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <string>

#include "core/sff/all_in_focus.h"
#include "core/sff/focus_measure.h"
#include "core/io/colour.h"

namespace inspection {

StatusOr<cv::Mat> StackFrameSource::grey(int index) const {
  INSPECT_ASSIGN_OR_RETURN(cv::Mat image, frame(index));
  if (image.channels() == 1) return image;
  return LuminanceOf(image);
}

namespace {

// Rows per band of a colour frame's focus score (the composer's; the engine has its own).
constexpr int kScoreBandRows = 256;

// Why a stack whose motion is significant (and not negligible) is still used as captured: it moves
// no corner by the imported default's floor (kImportedWarpPaysPx), below which a warp does not pay.
std::string BelowTheFloor(double corner_px, double statistic, double threshold, double floor_px) {
  char text[256];
  std::snprintf(text, sizeof text,
                "the frames move (still statistic %.2f > %.2f) but by %.2f px at most at the corners, below the %.2g px "
                "where a warp starts to pay in depth accuracy; used as captured",
                statistic, threshold, corner_px, floor_px);
  return text;
}

// The aligner for the folder's frames, or nullopt when the frames are used as they are.
StatusOr<std::optional<StackAligner>> PrepareAlignment(const StackFrameSource& source, const StackManifest& manifest,
                                                       const StackFolderAlignment& a, const std::atomic<bool>& cancel,
                                                       AlignmentFigures* figures) {
  if (figures) *figures = AlignmentFigures{};
  std::vector<double> z_um;
  for (const StackFrame& f : manifest.frames) z_um.push_back(f.z_um);
  FocusBreathingModel model;
  StackAlignmentOptions estimate_options = a.options;
  bool imported_default = false;  // an imported stack's default: the floor is a.imported_default_min_motion_px
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
        return source.grey(i);  // errors name the frame
      };
      // A rig's scan has metric z from the stage: the linear-in-z focus-breathing model is the
      // right prior there. An imported stack's z is nominal: a chain of neighbour registrations
      // assumes nothing about it (a.chain_for_imported_stacks), on request.
      // The default (fall_back_to_none) keeps the linear estimate: as the default the chain
      // warped 12 of 25 and 26 of 50 held-out still stacks of the simulated rig (8/25, 16/50 of
      // the natural-scene renderer's) and cost 11x the engine on a still 60 x 1600x1200 stack
      // (docs/alignment.md); an explicit request is the user's choice.
      // When the linear estimate does not fit an imported stack (a focus rail: its scale and
      // shift follow the frame index, not a nominal z), the default registers it as a chain
      // instead of leaving a stack that visibly moves unaligned; the result says so
      // (figures->decision). A rig's scan keeps the linear model's verdict.
      const bool imported = a.chain_for_imported_stacks && manifest.illumination.empty();
      // An imported stack's default holds the linear estimate to the chain's floor: below it a
      // warp loses more depth accuracy in resampling than the motion does (docs/alignment.md).
      imported_default = imported && a.fall_back_to_none;
      if (imported_default) estimate_options.min_motion_px = a.imported_default_min_motion_px;
      std::string decision;
      if (!imported || a.fall_back_to_none) {
        StatusOr<FocusBreathingModel> estimate = EstimateFocusBreathing(load, z_um, estimate_options);
        if (estimate.ok()) {
          model = *estimate;
          break;
        }
        const StatusCode code = estimate.status().code();
        const bool fallback =
            a.fall_back_to_none && (code == StatusCode::kFailedPrecondition || code == StatusCode::kInvalidArgument);
        if (!fallback) return estimate.status();
        if (!imported) {
          if (figures) figures->fallback_reason = "the focus-breathing estimate failed: " + estimate.status().message();
          return std::optional<StackAligner>();
        }
        decision = "the linear-in-z focus-breathing model did not fit (" + estimate.status().message() +
                   "); registered as a chain of neighbouring frames instead";
      }
      if (a.fall_back_to_none && z_um.size() < 3) {
        if (figures) figures->fallback_reason = "a stack of fewer than 3 frames is not registered";
        return std::optional<StackAligner>();
      }
      INSPECT_ASSIGN_OR_RETURN(cv::Mat first, source.grey(0));
      if (a.fall_back_to_none && (first.cols < 32 || first.rows < 32)) {
        // No measurement of motion is possible on frames this small: the default says so and
        // reconstructs them as they are; an explicit request fails in RegisterChain.
        if (figures) {
          figures->fallback_reason = "frames of " + std::to_string(first.cols) + "x" + std::to_string(first.rows) +
                                     " px are too small to register (alignment needs at least 32x32 px)";
        }
        return std::optional<StackAligner>();
      }
      int registered_pairs = 0;
      // Frames a thread-safe source holds in memory (a.options.threads != 1, as for the linear
      // estimate) register in runs concurrently.
      ChainRegistrationOptions chain_options = a.chain;
      if (a.options.threads != 1) chain_options.threads = a.options.threads;
      if (imported_default) chain_options.min_motion_px = std::max(chain_options.min_motion_px, a.imported_default_min_motion_px);
      StatusOr<ChainRegistration> chain = RegisterChain(load, int(z_um.size()), chain_options, &registered_pairs);
      if (!chain.ok()) {
        // The default (not an explicit request) reconstructs unaligned only when no pair
        // registered (a featureless stack: no evidence of motion either way), and says so in
        // figures->fallback_reason (the job result and the CLI print it). A stack some of whose
        // pairs register may move: aligning it wrongly or not at all would both smear the depth
        // map, so the job fails naming the pairs (--alignment none is the user's choice).
        if (a.fall_back_to_none && chain.status().code() == StatusCode::kFailedPrecondition && registered_pairs == 0) {
          if (figures) figures->fallback_reason = "no frame pair could be registered: " + chain.status().message();
          return std::optional<StackAligner>();
        }
        if (!decision.empty()) return Status(chain.status().code(), decision + ", which failed: " + chain.status().message());
        return chain.status();
      }
      INSPECT_ASSIGN_OR_RETURN(StackAligner aligner,
                               StackAligner::FromTransforms(chain->frame_from_reference, chain->reference_frame,
                                                            a.alignment, first.size(), !chain->still));
      if (figures) {
        *figures = aligner.figures();
        figures->method = "chain";
        figures->decision = decision;
        if (imported_default && chain->still && chain->still_statistic > chain->still_threshold &&
            chain->max_corner_displacement_px >= kNegligibleAlignmentPx) {
          const std::string why = BelowTheFloor(chain->max_corner_displacement_px, chain->still_statistic,
                                                chain->still_threshold, chain_options.min_motion_px);
          figures->decision = decision.empty() ? why : decision + "; " + why;
        }
        figures->still_statistic = chain->still_statistic;
        figures->still_threshold = chain->still_threshold;
        figures->max_corner_displacement_px = chain->max_corner_displacement_px;
      }
      return std::optional<StackAligner>(std::move(aligner));
    }
  }
  INSPECT_ASSIGN_OR_RETURN(cv::Mat first, source.grey(0));
  INSPECT_ASSIGN_OR_RETURN(StackAligner aligner,
                           StackAligner::Create(model, a.alignment, z_um, first.size(), estimate_options.min_motion_px));
  if (figures) {
    *figures = aligner.figures();
    // Said where the motion is significant and not negligible (kNegligibleAlignmentPx, a rig's
    // floor): a stack the old 0.5 px floor would have warped.
    if (imported_default && !aligner.warps() && model.still_threshold > 0 && model.still_statistic > model.still_threshold) {
      const double corner_px = MaxCornerDisplacementPx(model, z_um);
      if (corner_px >= kNegligibleAlignmentPx) {
        figures->decision =
            BelowTheFloor(corner_px, model.still_statistic, model.still_threshold, estimate_options.min_motion_px);
      }
    }
  }
  return std::optional<StackAligner>(std::move(aligner));
}

}  // namespace

StatusOr<DepthResult> ReconstructStackFolder(const std::filesystem::path& dir, const StackManifest& manifest,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel, const StackFolderAlignment& alignment,
                                             AlignmentFigures* figures) {
  StackFrameSource source;
  source.frame = [&](int i) { return DecodeStackFrame(dir, manifest, size_t(i)); };
  return ReconstructStackFrames(manifest, source, options, on_frame, cancel, alignment, figures);
}

StatusOr<DepthResult> ReconstructStackFrames(const StackManifest& manifest, const StackFrameSource& source,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel, const StackFolderAlignment& alignment,
                                             AlignmentFigures* figures) {
  INSPECT_ASSIGN_OR_RETURN(std::optional<StackAligner> aligner,
                           PrepareAlignment(source, manifest, alignment, cancel, figures));
  std::unique_ptr<SffEngine> engine;
  // Colour stacks: the engine measures focus on the luminance, and the composer keeps, per pixel,
  // the colour of the frame the engine picks (same scores, same tie rule), O(pixels) state.
  std::optional<AllInFocusComposer> colour;
  const int count = int(manifest.frames.size());
  for (int i = 0; i < count; ++i) {
    if (cancel.load()) return Status::Cancelled("reconstruction cancelled at frame " + std::to_string(i));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat decoded, source.frame(i));
    StackFrameImage image;  // as LoadStackFrameImage: the colour frame, or the grey frame as stored
    if (decoded.channels() == 3) {
      image.colour = decoded;  // its luminance is taken below, after the warp
    } else {
      image.grey = decoded;
    }
    const std::string name = "frame " + std::to_string(i) + " (" + manifest.frames[i].file + ")";
    if (i > 0 && image.is_colour() != colour.has_value()) {
      return Status::InvalidArgument(name + ": " + (image.is_colour() ? "colour (3 channels)" : "grey") +
                                     " differs from frame 0 (" + (colour ? "colour (3 channels)" : "grey") + ")");
    }
    if (!engine) {
      INSPECT_ASSIGN_OR_RETURN(engine, SffEngine::Create(options, decoded.size(), CV_MAKETYPE(decoded.depth(), 1)));
      if (image.is_colour()) {
        INSPECT_ASSIGN_OR_RETURN(AllInFocusComposer c,
                                 AllInFocusComposer::Create(image.colour.size(), image.colour.type()));
        colour.emplace(std::move(c));
      }
    }
    cv::Mat frame = image.grey;
    if (colour) {
      // Warp the colour frame and measure on its luminance, so that the kept colour's luminance
      // is exactly the engine's grey all-in-focus value, aligned or not.
      cv::Mat c = image.colour;
      if (aligner) {
        INSPECT_ASSIGN_OR_RETURN(c, aligner->Warp(c, i));
      }
      INSPECT_ASSIGN_OR_RETURN(frame, LuminanceOf(c));
      // The score in row bands where the measure allows it bit for bit: a whole 24 MP score is
      // 96 MB beside the engine and the composer.
      const int band_rows = FocusMeasureIsRowLocal(options.focus_measure) ? kScoreBandRows : frame.rows;
      auto score_rows = [&](int y0, int y1, cv::Mat* rows) {
        return FocusScoreRows(frame, options.focus_measure, options.window_px, y0, y1, rows);
      };
      INSPECT_RETURN_IF_ERROR(colour->PushFrameInBands(c, score_rows, band_rows).WithContext(name));
    } else if (aligner) {
      INSPECT_ASSIGN_OR_RETURN(frame, aligner->Warp(frame, i));
    }
    INSPECT_RETURN_IF_ERROR(engine->PushFrame(frame, manifest.frames[i].z_um).WithContext(name));
    if (source.release) source.release(i);
    if (on_frame) {
      // Frames as stored (grey, not warped): the source may know their statistics already.
      std::optional<FrameStatistics> statistics;
      if (!colour && !(aligner && aligner->warps()) && source.statistics) statistics = source.statistics(i);
      if (!statistics) statistics = ComputeFrameStatistics(frame, manifest.bit_depth);
      on_frame(i, count, manifest.frames[i].z_um, *statistics);
    }
  }
  if (!engine) return Status::InvalidArgument("stack has no frames");
  INSPECT_ASSIGN_OR_RETURN(DepthResult result, engine->Finish());
  if (colour) result.all_in_focus = colour->all_in_focus();
  if (aligner) MaskUnseenPixels(*aligner, &result);
  return result;
}

void MaskUnseenPixels(const StackAligner& aligner, DepthResult* r) {
  const cv::Mat& seen = aligner.seen_by_every_frame();
  const cv::Size size = seen.size();
  if (!aligner.warps() || r->depth_um.size() != size) return;
  const cv::Mat unseen = seen == 0;
  r->depth_um.setTo(std::numeric_limits<float>::quiet_NaN(), unseen);
  if (r->confidence.size() == size) r->confidence.setTo(0.0f, unseen);
  if (r->all_in_focus.size() == size) r->all_in_focus.setTo(0, unseen);
  const cv::Mat finite = r->depth_um == r->depth_um;  // NaN != NaN
  r->valid_fraction = double(cv::countNonZero(finite)) / double(size.area());
}


}  // namespace inspection
