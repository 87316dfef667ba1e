// The stack folder: the one on-disk form of an SFF image stack, used by scans (the server
// writes it), Reconstruct (reads it) and the CLI (uploads it). Format (docs/stack-format.md):
//
//   <dir>/stack.json          manifest, see StackManifest
//   <dir>/<frame files>       8- or 16-bit PNG, TIFF or JPEG, or camera RAW (core/io/raw_frame_decode.h),
//                             one per z position: grey (1 channel) or colour (3 channels); all
//                             frames alike (one format, size, channel count and bit depth)
//   <dir>/ground_truth_depth.tiff   optional, float32 µm, written by the simulated rig
//
// stack.json:
//   { "format": "inspection-stack", "version": 1, "pixel_size_um": 0.74,
//     "frames": [ { "file": "frame_0000.png", "z_um": 0.0, "exposure_us": 8000,
//                   "pattern": "uniform:128" }, ... ],
//     "bit_depth": 8, "specimen": "skew5", "calibration_id": "", "illumination": "STD",
//     "alignment": { "alignment": "calibrated", "method": "model", "still": false, ... } }
// "alignment" (optional; StackAlignmentRecord): the lateral alignment the stack was reconstructed
// with and each frame's transform, written by a scan; read back and checked, not re-applied (the
// frames stay as captured; a reconstruction chooses its own alignment).
// Frames are listed in acquisition order; z_um must be strictly monotonic (either direction,
// steps need not be uniform). "pattern" names what the projector showed for that frame.
// "pixel_size_um" is optional: without it the scale is unknown (StackManifest::pixel_size_um 0).
#pragma once

#include <array>
#include <filesystem>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/status.h"

namespace inspection {

struct StackFrame {
  std::string file;          // relative to the stack folder, no ".." components
  double z_um = 0.0;         // stage position when the frame was exposed
  double exposure_us = 0.0;  // camera exposure time; 0 when unknown
  std::string pattern;       // projector pattern, e.g. "uniform:128", "checkerboard:8", "file:p/0001.png"
};

// An automatic z range search that chose the stack's range (server/procedures/z_range_search.h):
// written to stack.json as "z_range_search" (not read back: it documents the scan).
struct ZRangeSearchRecord {
  double window_start_um = 0.0;  // searched window (low .. high)
  double window_end_um = 0.0;
  double coarse_step_um = 0.0;
  double margin_um = 0.0;
  std::vector<StackFrame> coarse_frames;  // raw/ files of the coarse sweep, in acquisition order
  // raw/ files of the frames refining the range's ends after the sweep (ZRangeAccumulator::
  // PlanRefinement: 0, 2, 3 or 4), in acquisition order.
  std::vector<StackFrame> refine_frames;
  double focus_low_um = 0.0;              // where the sweep found focus (percentiles of the peaks)
  double focus_high_um = 0.0;
  double resolved_percent = 0.0;  // share of the field with a resolved focus peak
  // Share of the field whose focus the sweep had passed when it ended; stopped_early: it ended
  // before the window's end because that share was reached (core/sff/z_range_search.h).
  double settled_percent = 0.0;
  bool stopped_early = false;
  double z_start_um = 0.0;        // the range chosen for the stack (frames above)
  double z_end_um = 0.0;
  double search_seconds = 0.0;  // the sweep and its analysis, wall time
};

// One frame's lateral transform onto the reference frame's grid (stack.json "alignment.frames"),
// as a similarity about the image centre (p_frame = c + scale R(rotation) (p_ref - c) + shift)
// and the full affine matrix the frame is resampled with (reference grid px -> frame px).
struct StackFrameTransform {
  int frame = 0;  // index in the stack, z order
  double scale = 1.0;
  double rotation_deg = 0.0;
  double shift_x_px = 0.0;
  double shift_y_px = 0.0;
  std::array<double, 6> affine{1.0, 0.0, 0.0, 0.0, 1.0, 0.0};  // row-major 2x3
};

// The lateral alignment of the stack (core/registration/stack_alignment.h AlignmentFigures, as
// the job result's AlignmentDetail names it): stack.json "alignment".
struct StackAlignmentRecord {
  std::string alignment = "none";  // "none", "estimate" or "calibrated"
  std::string method;              // "model" (linear in z), "chain" (neighbour pairs), "" (none)
  bool still = false;              // measured, and indistinguishable from no motion: not warped
  std::string fallback_reason;     // the default fell back to none, and why
  int reference_frame = 0;         // the frame whose grid the others are warped onto
  double max_scale_change_percent = 0.0;
  double max_shift_px = 0.0;
  double seen_by_every_frame_percent = 100.0;
  double max_corner_displacement_px = 0.0;
  std::vector<StackFrameTransform> frames;  // every frame's, z order; empty for none
};

struct StackManifest {
  int version = 1;
  double pixel_size_um = 0.0;  // lateral size of one camera pixel on the specimen; 0 = unknown
                               // (optional in stack.json: lateral outputs then count pixels)
  int bit_depth = 8;           // significant bits per pixel: 8, 10, 12 or 16
  std::string specimen;        // free text; the simulated rig writes its specimen name
  std::string calibration_id;  // calibration bundle active when acquired, empty if none
  std::string illumination;    // illumination mode, e.g. "STD"
  // Set when the scan chose its mode itself (AUTO): the decision and its reasons.
  std::string illumination_decision;
  std::vector<StackFrame> frames;
  std::optional<ZRangeSearchRecord> z_range_search;  // automatic z range only
  std::optional<StackAlignmentRecord> alignment;     // written by scans; absent in older stacks
};

inline constexpr const char* kStackManifestName = "stack.json";
inline constexpr const char* kGroundTruthDepthName = "ground_truth_depth.tiff";

// The format a frame file's extension names: "PNG", "TIFF", "JPEG" or "camera RAW (NEF)" etc.;
// "" for an extension it does not know (such a file is decoded by its content).
std::string FrameFileFormat(std::string_view file);

// INVALID_ARGUMENT naming the first frame whose file format (FrameFileFormat) differs from the
// first frame with a known one: "stack.json: frames[3].file 'b.jpg' is JPEG but frames[0].file
// 'a.png' is PNG; ...". ParseStackManifest runs it.
Status CheckOneFrameFormat(const StackManifest& manifest);

// Parses <dir>/stack.json and checks what can be checked without decoding images: required
// fields present and typed, >= 3 frames, z strictly monotonic, files exist and stay inside dir.
// Errors are INVALID_ARGUMENT naming the field or frame, e.g. "stack.json: frames[4].z_um ...".
StatusOr<StackManifest> ReadStackManifest(const std::filesystem::path& dir);

// Parses manifest text (for uploads before files exist). Does not check that files exist.
StatusOr<StackManifest> ParseStackManifest(const std::string& json_text);

// Writes <dir>/stack.json atomically (temporary file + rename).
Status WriteStackManifest(const std::filesystem::path& dir, const StackManifest& manifest);

// One decoded frame: what focus is measured on, and the colour for the all-in-focus image.
struct StackFrameImage {
  cv::Mat grey;    // CV_8UC1 / CV_16UC1: a grey frame as stored, or a colour frame's luminance
                   // (core/io/colour.h, BT.709 weights)
  cv::Mat colour;  // CV_8UC3 / CV_16UC3 in OpenCV's BGR order; empty for grey frames
  bool is_colour() const { return !colour.empty(); }
};

// Decodes one frame (8- or 16-bit, 1 or 3 channels). Errors name the frame. A JPEG's EXIF
// orientation and a camera RAW's orientation flag are applied (the frame as a viewer shows it);
// PNG and TIFF frames are taken as stored.
StatusOr<StackFrameImage> LoadStackFrameImage(const std::filesystem::path& dir, const StackManifest& manifest,
                                              size_t index);

// The grey image focus is measured on (CV_8UC1 or CV_16UC1): the frame as stored, or the
// luminance of a colour frame. Grey stacks give exactly what they did before colour support.
StatusOr<cv::Mat> LoadStackFrame(const std::filesystem::path& dir, const StackManifest& manifest, size_t index);

// Decodes one frame as stored: CV_8U or CV_16U, 1 (grey) or 3 (colour, BGR) channels. Errors
// name the frame. The decode step the parallel decoder (core/io/stack_frame_decoder.h) runs.
StatusOr<cv::Mat> DecodeStackFrame(const std::filesystem::path& dir, const StackManifest& manifest, size_t index);

// DecodeStackFrame on the bytes of the frame's file held in memory (e.g. read from a stored
// scan's archive): cv::imdecode instead of cv::imread, the same pixels and the same errors.
StatusOr<cv::Mat> DecodeStackFrameBytes(std::string_view file, const StackManifest& manifest, size_t index);

// What a decoded frame looks like, enough to check it against frame 0 after its pixels are gone.
struct StackFrameShape {
  cv::Size size;
  int depth = -1;  // CV_8U or CV_16U
  int channels = 0;
  static StackFrameShape Of(const cv::Mat& image) { return {image.size(), image.depth(), image.channels()}; }
};

// Checks frame `index` (shape) against frame 0 (first) as ValidateStackFrames does; for index 0,
// its bit depth against manifest.bit_depth. Same messages as ValidateStackFrames.
Status CheckStackFrameShape(const StackManifest& manifest, size_t index, const StackFrameShape& first,
                            const StackFrameShape& shape);

// Decodes every frame and checks that all frames share size, channel count (grey or colour) and
// bit depth. Errors name the frame: "frame 3 (frame_0003.png): size 640x480 differs from frame 0
// (1024x768)", "frame 2 (b.png): colour (3 channels) differs from frame 0 (grey)".
Status ValidateStackFrames(const std::filesystem::path& dir, const StackManifest& manifest);

// Returns INVALID_ARGUMENT unless z is strictly monotonic; names the first offending frame.
Status CheckMonotonicZ(const std::vector<double>& z_um);

}  // namespace inspection
