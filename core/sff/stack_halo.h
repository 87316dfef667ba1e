// Halo suppression (core/sff/halo_suppression.h) on a stack's frames after the engine: the frames
// are read again through the same StackFrameSource, resampled exactly as the engine saw them (the
// alignment the engine used, rebuilt from its AlignmentFigures), and handed to SuppressHalos.
// Reconstruct jobs and rig scans run it when ReconstructionOptions.halo_suppression asks.
#pragma once

#include "core/registration/stack_alignment.h"
#include "core/sff/halo_suppression.h"
#include "core/sff/stack_reconstruct.h"

namespace inspection {

// raw: ReconstructStackFrames' (or the scan engine's) result with SffOptions::min_confidence 0,
// before post-processing; alignment: the figures that run filled (default: frames as stored).
// Each frame is asked for twice more from source.frame, in z order (SuppressHalos' two passes),
// and released after each use. Colour stacks keep their colour all-in-focus image. Errors name the
// frame (as ReconstructStackFrames' do) or the option.
StatusOr<DepthResult> SuppressStackHalos(const DepthResult& raw, const StackManifest& manifest,
                                         const StackFrameSource& source, const AlignmentFigures& alignment,
                                         const SffOptions& sff, const HaloSuppressionOptions& options,
                                         HaloSuppressionFigures* figures = nullptr);

}  // namespace inspection
