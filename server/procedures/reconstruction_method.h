// Reconstruction methods of a stack (ReconstructionOptions.method): shape from focus (thesis
// 3.1, the streaming SffEngine) or integral SFF (thesis 5.4, 6.4: ISFF, ISFF-GT, ISFF-FAST over
// core/sff/integral_sff.h), with what each needs (the calibrated IPSF, uniform illumination, the
// simulated rig's ground truth) checked here for both Scan and Reconstruct.
#pragma once

#include <filesystem>
#include <string>

#include "core/calibration/calibration_bundle.h"
#include "core/sff/integral_sff.h"
#include "core/sff/sff_options.h"
#include "core/util/status.h"

namespace inspection {

enum class ReconstructionMethod {
  kSff,              // focus measure of SffOptions (thesis 3.1.3), streaming while a scan runs
  kIsff,             // NCC with the template restored from the integral image by the IPSF (5.4, 6.4.2)
  kIsffGroundTruth,  // NCC with the simulated rig's noise-free in-focus rendering (6.4.3)
  kIsffFast,         // ISFF stopping each pixel's search at the first good local maximum (6.4.4)
};
// "SFF", "ISFF", "ISFF-GT", "ISFF-FAST" (the names of thesis Tables 6.8 and 6.9).
const char* ReconstructionMethodName(ReconstructionMethod method);

struct ReconstructionMethodSettings {
  ReconstructionMethod method = ReconstructionMethod::kSff;
  // ISFF-FAST: the mean NCC over the summation window (-1..1) a local maximum needs to stop the
  // search, (0, 1]; thesis Table 6.9 (0.9: < 2 % wrong maxima on the simulated SKEW5).
  double isff_fast_threshold = 0.9;

  bool integral() const { return method != ReconstructionMethod::kSff; }
  // INVALID_ARGUMENT "isff_fast_threshold must be in (0, 1]".
  Status Validate() const;
};

// The integral methods' options from the request's SFF options: window_px is both the
// correlation window of eq. 5.25 and the summation window U of eq. 5.26 (thesis 6.4: 7 x 7);
// interpolation, line-fit width, min_confidence and threads carry over; focus_measure does not
// apply. ISFF-FAST sets the stop at the first local maximum.
IsffOptions IsffOptionsFor(const ReconstructionMethodSettings& settings, const SffOptions& sff);

// What an integral reconstruction reports beside its depth map (DepthSummary).
struct IntegralSffFigures {
  double frame_noise_sigma = 0.0;  // grey levels, estimated from the stack (0 for ISFF-GT)
  // Mean over the pixels of the frames each pixel's search took, over the frame count: 1 for
  // ISFF and ISFF-GT, below 1 for ISFF-FAST.
  double frames_searched_fraction = 1.0;
};
IntegralSffFigures FiguresOf(const IsffResult& result);

// The integral image of eq. 5.19 assumes one fixed illumination through the stack: the
// illumination recorded in stack.json must be empty (unknown, e.g. a foreign stack) or "STD".
// FAILED_PRECONDITION naming it otherwise.
Status CheckIntegralIllumination(const std::string& illumination);

// What an integral method needs to run over a stored stack folder (Reconstruct): ISFF-GT never
// can (the ground-truth texture exists only while the simulated rig scans), ISFF and ISFF-FAST
// need the IPSF in `bundle` (may be null). FAILED_PRECONDITION saying which; OK for SFF.
Status CheckStackFolderMethod(const ReconstructionMethodSettings& settings, const CalibrationBundle* bundle);

// ISFF or ISFF-FAST over a stack folder (core/io/stack.h) in the two streaming passes of
// ReconstructIntegralSffStack, with the IPSF of `bundle`; CheckStackFolderMethod and
// CheckIntegralIllumination first.
StatusOr<IsffResult> ReconstructStackFolderIntegralSff(const std::filesystem::path& dir,
                                                       const ReconstructionMethodSettings& settings,
                                                       const SffOptions& sff, const CalibrationBundle* bundle);

// The same on a stack's frames from `source` (ReconstructIntegralSffFrames: e.g. decoded from a
// stored scan's archive in memory); manifest: the stack's.
StatusOr<IsffResult> ReconstructStackIntegralSff(const StackManifest& manifest, const StackFrameSource& source,
                                                 const ReconstructionMethodSettings& settings, const SffOptions& sff,
                                                 const CalibrationBundle* bundle);

}  // namespace inspection
