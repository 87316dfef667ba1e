// One illumination mode family of thesis 5 and 6.2 as a strategy that RunScan drives: "prepare"
// once before the z loop, then "capture stack frame i" at every z. RunScan keeps the z loop, the
// stack folder and the SFF engine; a strategy decides what to show and capture for each z.
// Families (one file each): uniform (STD), HDR-n, ADAPT-IT, ADAPT (predictive, with HF+ADAPT and
// ADAPTED-HF), TEXTURE (with the checkerboard targets of the combinations).
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "core/calibration/calibration_bundle.h"
#include "core/util/status.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {

// How a capture enters the scan's record (ScanFrameEvent::stack_frame).
enum class CaptureRole {
  kStackFrame,  // the stack frame of its z, reported at once
  kRawFrame,    // kept under raw/ only (HDR exposure, ADAPT initialisation), reported at once
  kUndecided,   // ADAPT-IT iteration: reported by DecideLastCapture once its stop test ran
};

// The rig as a strategy sees it during one scan. RunScan implements it: every capture is
// checked, stored, counted and reported there, so strategies only choose patterns and exposures.
class ScanCaptureContext {
 public:
  virtual ~ScanCaptureContext() = default;
  // Moves the stage to the plan's z of stack frame i ("frame i: stage: ..." on error).
  virtual Status MoveStageTo(int i) = 0;
  // Shows `pattern` (CV_8UC1, projector size) for the captures that follow.
  virtual Status ShowPattern(const cv::Mat& pattern) = 0;
  // CANCELLED when the scan was cancelled; else shows `pattern` (unless empty), captures at
  // exposure_us, writes the frame to raw/<raw_name> (unless empty) and records the capture for
  // stack frame i in `role`.
  virtual StatusOr<cv::Mat> Capture(int i, const cv::Mat& pattern, double exposure_us, CaptureRole role,
                                    const std::string& raw_name) = 0;
  // Reports the last kUndecided capture: whether it became the stack frame of its z.
  virtual void DecideLastCapture(bool stack_frame) = 0;
};

// What RunScan writes to the stack folder and pushes into the engine for one z.
struct CapturedStackFrame {
  cv::Mat image;             // CV_8UC1 / CV_16UC1 of the camera size
  double exposure_us = 0.0;  // recorded in stack.json (0: HDR's merged radiance has none)
  std::string pattern;       // recorded pattern description, e.g. "uniform:128", "adapted"
};

// The parts of the rig a strategy needs before the first capture.
struct IlluminationSetup {
  cv::Size camera_size;
  cv::Size projector_size;
  int camera_bit_depth = 8;
};

// Not thread-safe; lives for one scan. Holds references to the plan and the bundle given to
// the factory, which must outlive it.
class IlluminationStrategy {
 public:
  virtual ~IlluminationStrategy() = default;
  // Bit depth of the stack frames: HDR's merged radiance is 16 bit, the others the camera's.
  virtual int stack_bit_depth() const = 0;
  // Everything before the z loop: the mode's models (texture period, compensator, patterns)
  // and the rig's first state (fixed pattern shown, or ADAPT's initialisation frames).
  virtual Status Prepare(ScanCaptureContext& rig) = 0;
  // With the stage at the plan's z of frame i: the captures this z needs and its stack frame.
  virtual StatusOr<CapturedStackFrame> CaptureStackFrame(int i, ScanCaptureContext& rig) = 0;
};

// The strategy of plan.mode. The caller has validated plan.params and checked the bundle with
// CheckCalibrationFor (bundle may be null for STD only). Building does no device I/O and cannot
// fail; model errors (e.g. no checkerboard period fits the window) come from Prepare.
std::unique_ptr<IlluminationStrategy> CreateIlluminationStrategy(const ScanPlan& plan, const CalibrationBundle* bundle,
                                                                 const IlluminationSetup& setup);

// raw/ file name of a capture that is not a stack frame: "frame_0003_it1.png".
std::string RawFrameName(int i, const char* what, int k);

}  // namespace inspection
