// Shape-from-focus engine (thesis 3.1): frames are pushed one by one as the camera delivers
// them; the engine keeps O(pixels) state (best focus value, its neighbours and the all-in-focus
// grey value per pixel), never a pixels x frames focus volume, so the depth map is ready when
// the last frame arrives. Scans and Reconstruct both run through it.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/sff/sff_options.h"
#include "core/util/status.h"

namespace inspection {

struct DepthResult {
  cv::Mat depth_um;             // CV_32FC1: stage z (µm) at which the pixel is sharpest; NaN = no depth
  cv::Mat confidence;           // CV_32FC1 in [0, 1]
  cv::Mat all_in_focus;         // same type as the frames: grey value from the sharpest frame
  double valid_fraction = 0.0;  // share of pixels with finite depth
  int frame_count = 0;
};

// Not thread-safe: one producer pushes frames in acquisition order. The engine may use
// several threads internally per frame.
//
// State per pixel, independent of the frame count: best focus value F_max and its frame index,
// the focus values next to it (1, or linefit_half_width on each side), the last two focus
// values, the sum of F and the squared second differences of the curve (for the confidence),
// and the all-in-focus grey value. At Finish each pixel is interpolated
// (core/sff/depth_interpolation.h) and gets its confidence; pixels below min_confidence get NaN.
// Size (state_bytes() / pixels): 23 bytes for 8-bit frames with Tenengrad and maximum or
// Gaussian interpolation (the scan default: exact int32 F_max, 16-bit float codes of the other
// focus values, truncated-float sums; details in core/sff/sff_state.h), and there Finish writes
// the result into the state's own buffers, so it adds no memory. Other measures, 16-bit frames
// and the line fit keep exact 32-bit state: 24 + 12 j bytes (j = 1, or linefit_half_width),
// plus the result (9 or 10 bytes per pixel) at Finish.
//
// Speed: 8-bit frames with Tenengrad run through a fused integer kernel (Sobel, squares, window
// sum and state update per cache-sized tile; 16-bit AVX2 lanes chosen at run time, portable
// fallback, bit-identical: core/sff/internal/tenengrad_kernel.h). PushFrame splits each frame into tiles
// over options.threads threads; with the compact state it takes frames in chunks of 8 and runs
// each tile across the chunk, so the state is streamed through memory once per 8 frames (the
// chunk's frames are held by reference meanwhile; at most 7 frames wait, and Finish processes
// them); ReconstructInMemory runs each tile across all frames so its state stays in cache.
// Other measures, 16-bit frames and illumination_invariant compute the focus map of
// core/sff/focus_measure.h and share the same state update; the map is computed in row bands
// over options.threads threads where the measure allows it bit for bit (FocusMeasureIsRowLocal:
// Tenengrad, the modified Laplacians, the grey-level variance), so that only band-sized float
// temporaries exist, else for the whole frame. inspect-bench measures it
// (tests/bench/inspect_bench.cc).
// Implementation: core/sff/sff_engine.cc (Create), sff_compact_engine.cc (the scan default),
// sff_exact_engine.cc (every other case), sff_batch.cc (ReconstructInMemory).
class SffEngine {
 public:
  // frame_type: CV_8UC1 or CV_16UC1.
  static StatusOr<std::unique_ptr<SffEngine>> Create(const SffOptions& options, cv::Size frame_size, int frame_type);
  virtual ~SffEngine() = default;

  // z_um must be strictly monotonic over the pushed frames (either direction). The frame is
  // validated at once (errors name it); its pixels may be processed later, up to Finish: the
  // engine keeps a reference (cv::Mat shares them; a Mat over memory it does not own is
  // copied), so the caller must not write into a pushed frame's pixels.
  virtual Status PushFrame(const cv::Mat& frame, double z_um) = 0;
  // Needs >= 3 frames. After Finish the engine cannot take more frames.
  virtual StatusOr<DepthResult> Finish() = 0;
  virtual int frames_pushed() const = 0;
  // Bytes of per-pixel state the engine holds while frames are pushed (0 after Finish).
  virtual size_t state_bytes() const = 0;

  // Batch path for a stack already in memory: same result as pushing the frames one by one
  // (bit-identical), but processes cache-sized tiles across all frames on options.threads
  // threads, so the per-pixel state never leaves the cache. frames: >= 3, all CV_8UC1 or all
  // CV_16UC1 of one size; z_um: one per frame, strictly monotonic.
  static StatusOr<DepthResult> ReconstructInMemory(const SffOptions& options, const std::vector<cv::Mat>& frames,
                                                   const std::vector<double>& z_um);
};

}  // namespace inspection
