// Halo suppression on a stack's frames (core/sff/stack_halo.h).
#include "core/sff/stack_halo.h"

#include <optional>
#include <string>
#include <vector>

namespace inspection {

StatusOr<DepthResult> SuppressStackHalos(const DepthResult& raw, const StackManifest& manifest,
                                         const StackFrameSource& source, const AlignmentFigures& alignment,
                                         const SffOptions& sff, const HaloSuppressionOptions& options,
                                         HaloSuppressionFigures* figures) {
  std::vector<double> z_um;
  for (const StackFrame& f : manifest.frames) z_um.push_back(f.z_um);
  // The engine's resampling, rebuilt from what it reported: figures.still is exactly "did not
  // warp" (StackAligner::FromTransforms), so a still stack is read as stored here too.
  std::optional<StackAligner> aligner;
  if (!alignment.method.empty() && !alignment.still && !alignment.frame_from_reference.empty()) {
    if (alignment.frame_from_reference.size() != manifest.frames.size()) {
      return Status::InvalidArgument("halo suppression: the alignment has " +
                                     std::to_string(alignment.frame_from_reference.size()) + " frame transforms for " +
                                     std::to_string(manifest.frames.size()) + " frames");
    }
    INSPECT_ASSIGN_OR_RETURN(StackAligner a,
                             StackAligner::FromTransforms(alignment.frame_from_reference, alignment.reference_frame,
                                                          alignment.alignment, alignment.frame_size, true));
    aligner.emplace(std::move(a));
  }
  auto frame = [&](int i) -> StatusOr<cv::Mat> {
    const std::string name = "frame " + std::to_string(i) + " (" + manifest.frames[size_t(i)].file + ")";
    StatusOr<cv::Mat> stored = source.frame(i);
    if (!stored.ok()) return stored.status().WithContext(name);
    cv::Mat f = *stored;
    if (aligner) {
      INSPECT_ASSIGN_OR_RETURN(f, aligner->Warp(f, i));
    }
    // The source's copy can go now (f holds its own reference to the pixels); SuppressHalos
    // keeps only the focus score and a few pixel values of each frame.
    if (source.release) source.release(i);
    return f;
  };
  INSPECT_ASSIGN_OR_RETURN(DepthResult out, SuppressHalos(raw, frame, z_um, sff, options, figures));
  // Pixels some frame did not see stay as the engine left them (NaN, zero confidence, black):
  // a warped frame's replicated border is not evidence.
  if (aligner) MaskUnseenPixels(*aligner, &out);
  return out;
}

}  // namespace inspection
