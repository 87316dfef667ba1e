// Lateral alignment during a scan: which alignment a scan runs and the aligner that
// warps each stack frame onto the middle frame's grid before the engine measures its focus, with
// the calibrated focus-breathing model (core/registration/stack_alignment.h). The stored stack keeps the
// frames as captured.
#pragma once

#include <optional>

#include "core/calibration/calibration_bundle.h"
#include "core/io/stack.h"
#include "core/registration/stack_alignment.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {

// nullopt: frames go to the engine as captured (NONE, an integral method, or no model and no
// explicit request). FAILED_PRECONDITION for CALIBRATED without the bundle's focus_breathing
// model or with a model of another camera size; INVALID_ARGUMENT for ESTIMATE (scans cannot).
StatusOr<std::optional<StackAligner>> CreateScanAligner(const ScanPlan& plan, const CalibrationBundle* bundle,
                                                        cv::Size frame_size);

// The frame as the engine gets it: warped when there is an aligner (errors name the frame).
StatusOr<cv::Mat> AlignScanFrame(const std::optional<StackAligner>& aligner, const cv::Mat& frame, int index);

// What stack.json records of the alignment (StackManifest::alignment): the figures and each
// frame's transform, as the job result's AlignmentDetail names them. A scan without an aligner
// records alignment "none" with no transforms (pass a default AlignmentFigures).
StackAlignmentRecord AlignmentRecordOf(const AlignmentFigures& figures);

}  // namespace inspection
