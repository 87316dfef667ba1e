// Per-pixel state of the streaming SFF engine (thesis 3.1.3-3.1.4): the running focus maximum,
// the focus values around it and the curve statistics of the confidence, in two layouts: exact
// 32-bit planes, and the compact 23-byte layout of the scan default. Internal to core/.
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "core/util/cpu_features.h"
#include "core/sff/sff_options.h"

// The kernels rely on these being inlined into their (possibly AVX2-compiled) callers.
#define SFF_INLINE inline __attribute__((always_inline))

namespace inspection::sff_internal {

constexpr int kMaxJ = 4;  // most neighbours kept on each side of the maximum (line fit)

// A focus value as float: exact int32 values (fused Tenengrad) are rounded where they are summed.
inline float ToFloat(int32_t v) { return float(v); }
inline float ToFloat(float v) { return v; }

// ---- Exact state: every case but the compact one below ----
// Planes (structure of arrays), so that the update loops vectorise; 24 + 12 j bytes per pixel.
// Used by the line fit (j = linefit_half_width neighbours each side) and by every measure
// other than 8-bit Tenengrad (j = 1).
// T: focus value type (int32_t exact for the fused 8-bit Tenengrad, float otherwise).
// P: pixel type of the frames (all-in-focus image).
template <typename T, typename P>
struct StatePlanes {
  int width = 0, height = 0, j = 1;
  bool simd = true;  // AVX2 row kernels (when the CPU has AVX2) or the portable ones
  std::vector<T> best;
  // Frame index of the maximum (bits 16-31; < 65535 frames, CheckPush) | the all-in-focus grey
  // value (bits 0-15, P is 8 or 16 bits): one 32-bit lane, so the row loops vectorise with the
  // same width as the float planes, and 4 bytes per pixel less than two planes.
  std::vector<uint32_t> idx_aif;
  std::vector<T> before[kMaxJ], after[kMaxJ], ring[kMaxJ];  // F(m-1-i), F(m+1+i), F(k-1-i)
  std::vector<T> last2;                                     // F(k-2)
  // Sum of F; sum of squared second differences t_k = F_k - 2 F_(k-1) + F_(k-2) over the curve,
  // and over the (up to three) t_k that involve the current maximum (excluded at the end).
  std::vector<float> sum, curv_all, curv_excl;

  static SFF_INLINE int32_t IndexOf(uint32_t w) { return int32_t(w >> 16); }
  static SFF_INLINE uint32_t GreyOf(uint32_t w) { return w & 0xFFFFu; }
  static SFF_INLINE uint32_t Pack(int32_t index, uint32_t grey) { return (uint32_t(index) << 16) | grey; }

  void Allocate(int w, int h, int jj, bool use_simd) {
    simd = use_simd && CpuHasAvx2();
    width = w;
    height = h;
    j = jj;
    const size_t n = size_t(w) * h;
    best.assign(n, T(0));
    idx_aif.assign(n, 0u);
    for (int i = 0; i < jj; ++i) {
      before[i].assign(n, T(0));
      after[i].assign(n, T(0));
      ring[i].assign(n, T(0));
    }
    last2.assign(n, T(0));
    sum.assign(n, 0.f);
    curv_all.assign(n, 0.f);
    curv_excl.assign(n, 0.f);
  }
  size_t Bytes() const {
    size_t b = (best.size() + last2.size()) * sizeof(T) + idx_aif.size() * 4 +
               (sum.size() + curv_all.size() + curv_excl.size()) * 4;
    for (int i = 0; i < kMaxJ; ++i) b += (before[i].size() + after[i].size() + ring[i].size()) * sizeof(T);
    return b;
  }
};

// Depth, confidence and all-in-focus images that the exact state's Finish writes into.
struct DepthOutputs {
  cv::Mat depth, confidence, aif;
};

// Interpolation (core/sff/depth_interpolation.h) and confidence of the `count` exact-state pixels
// of one row span at off; writes the outputs at (ox, oy). Returns the number of pixels with
// finite depth (confidence >= o.min_confidence). z: the frames' z_um.
template <typename T, typename P>
size_t FinishExactSpan(const StatePlanes<T, P>& st, size_t off, int count, const std::vector<double>& z,
                       const SffOptions& o, DepthOutputs& out, int ox, int oy);

// ---- Compact state: the fused 8-bit Tenengrad path with one neighbour each side ----
// (maximum and Gaussian interpolation, the scan default): 23 bytes per pixel instead of 36.
//  - F_max exact (int32): the running maximum compares exactly.
//  - The four curve samples the fit and the second differences need, F(k-1), F(k-2), F(m-1) and
//    F(m+1), as 16-bit codes of F + 1 (5 exponent and 11 mantissa bits, truncated): relative
//    error < 2^-11 (exact below 2^12), 0 <-> 0; every F < 2^31 fits. The Gaussian fit only uses
//    ln(F_max / F(m-1)) and ln(F_max / F(m+1)), which move by < 5e-4.
//  - The sum of F and the sum of the squared second differences t_k^2 that do not involve the
//    current maximum ("kept"), as floats truncated to a 16-bit significand (relative error
//    < 2^-15 per frame); their freed low bytes hold the 16-bit frame index of the maximum.
//  - The pending t_k^2 that do involve the maximum (at most three; they join "kept" when a new
//    maximum arrives and are left out at the end), as a 16-bit code of P + 1 with 6 exponent and
//    10 mantissa bits (saturated at ~2^64).
//  - The all-in-focus grey value (8 bits).
// Every rounding is a truncation of float bits applied after each frame, by the per-frame
// streaming kernels and by the batch kernels that keep a pixel's state in registers over a
// chunk of frames alike, so streaming and batch stay bit-identical.
constexpr uint32_t kOneBits = 0x3F800000u;         // 1.0f: codes are offsets from it
constexpr uint32_t kSampleMask = 0xFFFFF000u;      // 11 mantissa bits
constexpr uint32_t kPendingMask = 0xFFFFE000u;     // 10 mantissa bits
constexpr uint32_t kPendingMaxBits = 0x5F7FE000u;  // code 65535 (~1.8e19)
constexpr uint32_t kSumMask = 0xFFFFFF00u;         // 16-bit significand; low byte: index bits

inline float FromBits(uint32_t b) { return std::bit_cast<float>(b); }
inline uint32_t Bits(float f) { return std::bit_cast<uint32_t>(f); }

// Row pointers into a CompactState (one row span).
struct CompactPtrs {
  int32_t* best;
  uint32_t* sum_idx;   // sum of F | idx bits 0-7
  uint32_t* kept_idx;  // kept sum of t_k^2 | idx bits 8-15
  uint16_t *last, *last2, *before, *after, *pending;
  uint8_t* aif;
};

struct CompactState {
  static constexpr int kBytesPerPixel = 23;
  int width = 0, height = 0;
  bool avx2 = false, avx512 = false;  // kernels to use: chosen from the options and the CPU
  // Float-typed Mats holding int32 / packed words while frames arrive, so that Finish writes
  // depth_um and confidence into them in place and hands them out as the result.
  cv::Mat best, sum_idx, aif;
  std::vector<uint32_t> kept_idx;
  std::vector<uint16_t> last, last2, before, after, pending;

  void Allocate(int w, int h, bool use_simd, bool use_avx512);
  // The state before frame 0: F_max below every focus value, so that frame 0 is a new maximum
  // for every pixel and the update kernels initialise the state themselves; all else 0.
  void Reset();
  size_t Bytes() const;
  CompactPtrs Row(size_t off) {
    return {reinterpret_cast<int32_t*>(best.data) + off,
            reinterpret_cast<uint32_t*>(sum_idx.data) + off,
            kept_idx.data() + off,
            last.data() + off,
            last2.data() + off,
            before.data() + off,
            after.data() + off,
            pending.data() + off,
            aif.data + off};
  }
};

// Prefetches the n pixels of a compact state row span for writing.
SFF_INLINE void PrefetchCompactRow(const CompactPtrs& s, int n) {
  for (int i = 0; i < n; i += 16) {
    __builtin_prefetch(s.best + i, 1, 3);
    __builtin_prefetch(s.sum_idx + i, 1, 3);
    __builtin_prefetch(s.kept_idx + i, 1, 3);
  }
  for (int i = 0; i < n; i += 32) {
    for (uint16_t* p : {s.last, s.last2, s.before, s.after, s.pending}) __builtin_prefetch(p + i, 1, 3);
  }
  for (int i = 0; i < n; i += 64) __builtin_prefetch(s.aif + i, 1, 3);
}

}  // namespace inspection::sff_internal
