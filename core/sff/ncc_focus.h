// Correlation focus measure of thesis 5.4.2 (eq. 5.24-5.26): the normalised cross correlation
// (NCC) of every pixel's window in a stack frame with the same window of a focused template
// image, summed over U; per pixel the maximum through the stack (ISFF) or, ISFF-FAST, the first
// local maximum above a correlation threshold, then the usual interpolation (thesis 3.1.4).
//
// Why the default focus value weights the NCC by the frame patch's contrast: eq. 5.25 divides by
// the frame patch's own standard deviation, so the NCC does not measure how sharp a frame is but
// how closely its blur matches the template's. With Gaussian blurs of widths a (frame) and b
// (template) on a white texture, NCC = 2ab / (a^2 + b^2): its maximum lies where a = b. A
// restored template is never quite as sharp as the in-focus frame (the IPSF is a regularised
// inverse), so the NCC peaks on both sides of focus and is flat in between - the thesis's ISFF
// errors of Table 6.8 (2.7 / 16.7 um against STD's 1.7 / 2.4). C sigma_w = cov(w, t) / sigma_t
// is the part of the frame patch that is the template's texture, in grey levels: proportional to
// <G_a, G_b> / |G_b|, it falls monotonically with the frame's blur whatever the template's, so its
// maximum is the sharpest frame. On the simulated rig (tests/bench/isff_evaluate.cc) this takes
// ISFF from 6x STD's sigma to below it; the thesis's sum of (C + 1) stays selectable.
#pragma once

#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "core/sff/depth_interpolation.h"
#include "core/sff/sff_engine.h"  // DepthResult
#include "core/util/status.h"

namespace inspection {

// The focus value F per pixel and frame, from the NCC C (eq. 5.25) over U:
enum class CorrelationFocusValue {
  kContrastWeighted,  // F = sum over U of C sigma_w = cov(w, t) / sigma_t (grey levels); default
  kShiftedSum,        // F = sum over U of (C + 1), eq. 5.26 as in the thesis
};
const char* CorrelationFocusValueName(CorrelationFocusValue v);  // "contrast_weighted", "shifted_sum"

struct NccFocusOptions {
  // Side of the correlation patch w / t of eq. 5.25 (thesis 6.4: 7 x 7), odd, 3..31.
  int correlation_window_px = 7;
  // Side of the summation window U of eq. 5.26, odd, 1..31 (1 = the NCC of the pixel alone).
  int summation_window_px = 7;
  CorrelationFocusValue focus_value = CorrelationFocusValue::kContrastWeighted;
  // The engine's default (core/sff/sff_options.h). Derived for gradient energy; on the correlation
  // curve it also measured better than the Gaussian (tests/server/procedures/isff_rig_test.cc).
  DepthInterpolation interpolation = DepthInterpolation::kDefocusParabola;
  int linefit_half_width = 2;  // line fit only, 1..4 (as SffOptions)
  // Pixels whose confidence (FocusConfidence, core/sff/depth_interpolation.h) is below this get NaN
  // depth; the same rule and default as the other focus measures (SffOptions::min_confidence).
  double min_confidence = 0.4;

  // ISFF-FAST (thesis 5.4.2, 6.4.4): a pixel's search stops at its first local maximum of F
  // whose correlation (the mean NCC over U, -1..1: the normalised quantity the threshold needs)
  // is at least stop_threshold; pixels that never reach one keep the global maximum. Stopped
  // pixels cost nothing for later frames: the frame is processed in tiles of tile_px x tile_px,
  // each only over the bounding box of its pixels still searching, and a tile whose pixels have
  // all stopped is skipped (its frame pixels are not even read).
  bool stop_at_first_maximum = false;
  double stop_threshold = 0.9;  // (0, 1]: "fast_threshold" in the API
  // 8..256. 64: the halo of the windows (6 px each side for 7 x 7) costs ~40 % on a 64 px tile,
  // ~90 % on a 32 px one; smaller tiles follow the stopped pixels more closely. On the simulated
  // SKEW5 stack ISFF-FAST's search took the same time with 64 and 128, ISFF's 10 % longer with 64.
  int tile_px = 64;

  int threads = 0;  // 0 = all hardware threads

  // INVALID_ARGUMENT naming the field when out of range.
  Status Validate() const;
};

// Work done by an engine (for ISFF-FAST's saving, thesis Table 6.9).
struct NccWorkCounters {
  int64_t computed_pixel_frames = 0;       // pixels whose NCC and F were computed, summed over frames
  int64_t computed_pixel_frames_full = 0;  // the global maximum search's: pixels x frames
  int64_t tile_frames = 0;                 // tiles processed, summed over frames
  int64_t tile_frames_full = 0;            // tiles x frames
  int64_t pixel_frames = 0;                // state updates (pixels that were still searching)
  int64_t stopped_pixels = 0;              // ISFF-FAST: pixels that stopped at a local maximum >= threshold
};

// Reference whole-frame maps (tests and offline use). frame and focused_template: single
// channel, same size, CV_8U / CV_16U / CV_32F. Border: both images extended by mirroring
// without repeating the edge pixel (BORDER_REFLECT_101) for the correlation patches, and the
// per-pixel maps likewise for the summation window U, as for the other focus measures
// (core/sff/focus_measure.h). A patch of zero variance (in w or t) has NCC 0.
//   ncc: CV_32FC1, eq. 5.25 at every pixel.
//   focus: CV_32FC1, F of `value` (see CorrelationFocusValue); may be null.
Status ComputeNccFocus(const cv::Mat& frame, const cv::Mat& focused_template, int correlation_window_px,
                       int summation_window_px, CorrelationFocusValue value, cv::Mat* ncc, cv::Mat* focus);

// Streaming ISFF: one producer pushes frames in acquisition order; not thread-safe (uses
// options.threads internally). The template is fixed at creation (the restored all-in-focus
// image, core/sff/integral_sff.h, or a ground-truth texture for ISFF-GT).
//
// State per pixel, independent of the frame count (O(pixels), like SffEngine): the focus value
// F at the best frame, its mean NCC and index, the j values on each side of it, the last
// max(j, 2) values, the sum of F, the squared second differences (confidence), the grey value
// of the best frame and, for ISFF-FAST, whether and when the pixel stopped: 4 (6 + 2 j +
// max(j, 2)) + 5 bytes (45 for the Gaussian interpolation), plus the template's statistics (12
// bytes per pixel). The frame is processed in tiles
// with their halo (correlation and summation windows); the patch sums are exact for 8-bit
// frames and double for 16-bit ones, so flat windows do not lose their variance to
// cancellation.
class NccFocusEngine {
 public:
  // focused_template: CV_8U / CV_16U / CV_32F single channel of the frame size; frame_type
  // CV_8UC1 or CV_16UC1 (the all-in-focus output has this type).
  static StatusOr<std::unique_ptr<NccFocusEngine>> Create(const NccFocusOptions& options,
                                                          const cv::Mat& focused_template, int frame_type);
  ~NccFocusEngine();

  // z_um strictly monotonic over the pushed frames; errors name the frame. This is the search,
  // where ISFF-FAST saves.
  Status PushFrame(const cv::Mat& frame, double z_um);
  // Needs >= 3 frames. After Finish the engine takes no more frames.
  StatusOr<DepthResult> Finish();

  int frames_pushed() const;
  size_t state_bytes() const;
  const NccWorkCounters& work() const;
  // The discrete index of each pixel's chosen maximum (CV_16SC1), valid after Finish (for the
  // ISFF-FAST "wrong maxima" comparison of thesis Table 6.9).
  const cv::Mat& max_index() const;
  // Frames each pixel's search took (CV_16SC1, valid after Finish): the frame count, or for a
  // pixel ISFF-FAST stopped the frames up to and including the one that showed the drop.
  const cv::Mat& frames_searched() const;

 private:
  struct Impl;
  explicit NccFocusEngine(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace inspection
