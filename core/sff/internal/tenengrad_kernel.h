// The fused 8-bit Tenengrad kernel of the SFF engine: Sobel energy (thesis eq. 3.13), window
// sum (eq. 3.14) and the per-pixel state update of the running maximum (3.1.4) in one pass over
// a cache-sized tile, and the state read-out at Finish. Internal to core/.
//
// Laid out as OpenCV lays out its dispatched kernels: the algorithm is written once in
// tenengrad_kernel.simd.h and compiled per instruction set (tenengrad_kernel_portable.cc,
// tenengrad_kernel_avx2.cc), each file adding its hand-written intrinsics (AVX-512 has only the
// compact state update: tenengrad_kernel_avx512.cc). The ISA code is compiled with per-function
// target attributes, not per-file flags, so one binary runs on any x86-64 CPU; the dispatcher
// functions below (tenengrad_kernel_dispatch.cc) pick the implementation at run time from the
// state's avx2 / avx512 / simd flags (set from SffOptions and core/util/cpu_features.h). Every
// implementation gives bit-identical results (tests/core/sff/sff_engine_test.cc).
#pragma once

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "core/sff/sff_options.h"
#include "core/sff/sff_state.h"

namespace inspection::sff_internal {

// Tile of the fused kernel in PushFrame: 256 x 64 pixels; the halo (window + 1 extra rows and
// columns of input) stays near 10 % for the 7 x 7 window.
constexpr int kTileW = 256;
constexpr int kTileH = 64;
// Batch path: 256 x 32 tiles (compact state 23 bytes per pixel = 188 KB, in L2; exact line-fit
// state up to 76 bytes = 620 KB), frames in chunks of 8 whose focus rows are kept (256 x 32 x 8
// x 4 B = 256 KB) so that each state row is updated for 8 frames while it sits in registers / L1.
constexpr int kBatchTileH = 32;
constexpr int kFrameChunk = 8;

// Scratch of the fused Tenengrad kernel for one tile (one per worker thread).
struct TenengradScratch {
  std::vector<int16_t> in[3];   // three input rows, reflected, widened: width tw + 2R + 2
  std::vector<int16_t> sv, dv;  // vertical [1 2 1] and [1 0 -1] of the three rows (AVX2 path)
  std::vector<int32_t> ering;   // the last `window` energy rows Gx^2 + Gy^2: stride EnergyStride(ew)
  std::vector<int32_t> zeros;   // an all-zero energy row: the "old" row of the first `window` rows
  std::vector<int32_t> colsum;  // vertical window sums of the energy
  std::vector<int32_t> pairs;   // horizontal pair sums of colsum
  std::vector<int32_t> focus;   // one output row
  void Reserve(int window) {
    const int r = window / 2, ew = kTileW + 2 * r, es = EnergyStride(ew);
    // The AVX2 kernel runs whole blocks of 16 up to es (+ 16 input columns); the columns past
    // the tile's are computed but never read.
    for (auto& v : in) v.resize(size_t(es) + 18);
    sv.resize(size_t(es) + 18);
    dv.resize(size_t(es) + 18);
    ering.resize(size_t(es) * window);
    zeros.assign(size_t(es), 0);
    colsum.resize(size_t(es));
    pairs.resize(size_t(ew));
    focus.resize(size_t(kTileW));
  }
  // Energy row width ew rounded up to whole blocks of 16.
  static int EnergyStride(int ew) { return (ew + 15) & ~15; }
};

// ---- Dispatcher: what the engines call ----

// Exact state (line fit): frame k over the tile [x0, x0 + tw) x [y0, y0 + th), updating the
// state whose (0, 0) is the tile's top-left at (sx, sy). next: the frame after, to prefetch.
void FusedTileFrame(const cv::Mat& frame, int k, int x0, int y0, int tw, int th, int window, TenengradScratch& sc,
                    StatePlanes<int32_t, uint8_t>& st, int sx, int sy, const cv::Mat* next = nullptr);

// Batch and compact paths: the focus rows of the tile for `frame` into slot `slot` of the
// per-worker volume (kFrameChunk slots of kBatchTileH x kTileW), for a later state update.
void FocusRowsToVolume(bool avx2, const cv::Mat& frame, int slot, int x0, int y0, int tw, int th, int window,
                       TenengradScratch& sc, int32_t* vol, const cv::Mat* next);

// Exact state (batch line fit): frames k_begin .. k_end-1 over the n pixels of a state row at
// off; the focus value of frame k is vol_row[(k - k_begin) * slot_stride + x], its grey value
// pix_rows[k - k_begin][x].
void UpdateExactRowFrames(StatePlanes<int32_t, uint8_t>& st, size_t off, int n, int k_begin, int k_end,
                          const int32_t* vol_row, size_t slot_stride, const uint8_t* const* pix_rows);

// Exact state of the other measures: frame k's focus map (CV_32FC1, core/sff/focus_measure.h) and
// pixels over rows y_begin .. y_end-1. The map may cover only a band of the frame: its row 0 is
// frame row focus_y0 (0 for a whole-frame map).
void UpdateExactRowsFromFocus(StatePlanes<float, uint8_t>& st, int k, const cv::Mat& focus, int focus_y0,
                              const cv::Mat& frame, int y_begin, int y_end);
void UpdateExactRowsFromFocus(StatePlanes<float, uint16_t>& st, int k, const cv::Mat& focus, int focus_y0,
                              const cv::Mat& frame, int y_begin, int y_end);

// Compact state: frames k_begin .. k_end-1 over the n pixels of a state row at off (frame 0 on
// the Reset state initialises it): the focus value of frame k at x is
// vol_row[(k - slot0) * slot_stride + x], its grey value pix_rows[k - slot0][x]. AVX-512
// blocks of 16, AVX2 blocks of 8 and the portable rest, as the state selects.
void UpdateCompactRow(CompactState& st, size_t off, int n, int k_begin, int k_end, int slot0, const int32_t* vol_row,
                      size_t slot_stride, const uint8_t* const* pix_rows);

// Compact state at Finish: interpolation (maximum or Gaussian) and confidence of `count` pixels
// of a row at off. zf: the frames' z_um. The outputs may be the state's own buffers (depth into
// best, confidence into sum_idx): each pixel block is read before it is written. Returns the
// number of pixels with finite depth.
size_t FinishCompactRow(CompactState& st, size_t off, int count, const std::vector<float>& zf, const SffOptions& o,
                        uint32_t* depth, uint32_t* conf, uint8_t* aif);

// ---- Per-instruction-set implementations (only the dispatcher calls these) ----

enum class Isa { kPortable, kAvx2, kAvx512 };

// Specialised in tenengrad_kernel_<isa>.cc; the comments say which sets implement what. The
// arguments are those of the dispatcher functions above.
template <Isa I>
struct TenengradKernels {
  // Portable and AVX2 (from tenengrad_kernel.simd.h).
  static void FusedTileFrame(const cv::Mat& frame, int k, int x0, int y0, int tw, int th, int window,
                             TenengradScratch& sc, StatePlanes<int32_t, uint8_t>& st, int sx, int sy,
                             const cv::Mat* next);
  static void FocusRowsToVolume(const cv::Mat& frame, int slot, int x0, int y0, int tw, int th, int window,
                                TenengradScratch& sc, int32_t* vol, const cv::Mat* next);
  static void ExactRowFrames(StatePlanes<int32_t, uint8_t>& st, size_t off, int n, int k_begin, int k_end,
                             const int32_t* vol_row, size_t slot_stride, const uint8_t* const* pix_rows);
  static void ExactRowsFromFocus(StatePlanes<float, uint8_t>& st, int k, const cv::Mat& focus, int focus_y0,
                                 const cv::Mat& frame, int y_begin, int y_end);
  static void ExactRowsFromFocus(StatePlanes<float, uint16_t>& st, int k, const cv::Mat& focus, int focus_y0,
                                 const cv::Mat& frame, int y_begin, int y_end);
  // Tenengrad map of a whole 8-bit frame (CV_32SC1 out, allocated): ComputeTenengradU8.
  static void TenengradMap(const cv::Mat& frame, int window_px, cv::Mat* out);
  // Portable (the scalar reference), AVX2 (blocks of 8) and AVX-512 (blocks of 16): pixels
  // x_begin .. x_end-1; the vector sets need x_end - x_begin a multiple of their block. The row
  // pointers come by value: a copy the stores (8-bit all-in-focus ones may alias anything)
  // cannot change, so the loops keep them in registers.
  static void UpdateCompact(CompactPtrs s, int x_begin, int x_end, int k_begin, int k_end, int slot0,
                            const int32_t* vol_row, size_t slot_stride, const uint8_t* const* pix_rows);
  // Portable and AVX2 (blocks of 8), pixels x_begin .. x_end-1. interpolation: kMaximum,
  // kGaussian or kDefocusParabola (the line fit needs the exact state).
  static size_t FinishCompact(CompactPtrs s, int x_begin, int x_end, const float* zf, int n,
                              DepthInterpolation interpolation, float min_confidence, uint32_t* depth, uint32_t* conf,
                              uint8_t* aif);
};

}  // namespace inspection::sff_internal
