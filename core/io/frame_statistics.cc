#include "core/io/frame_statistics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace inspection {

namespace {

// Sums over a run of at most kRun pixels of one row, in 32-bit counters (65535 * 65536 < 2^32;
// for 8-bit frames also 255^2 * 65536), which vectorise several times wider than the 64-bit sums
// they replaced: this runs once per frame for the progress events, and took ~1.2 ms per
// 1600x1200 frame. Squares of 16-bit values do not fit 32 bits, so their sum stays 64-bit.
constexpr int kRun = 65536;

struct RunSums {
  uint64_t sum2 = 0;
  uint32_t sum = 0, saturated = 0, under = 0;
};

#if defined(__clang__) || !defined(__x86_64__)
#define INSPECT_STATS_KERNEL
#else
#define INSPECT_STATS_KERNEL __attribute__((target_clones("avx2", "default")))
#endif

RunSums SumRun8(const uint8_t* __restrict p, int n, uint8_t under) {
  uint64_t s = 0, sat = 0, u = 0;
  uint32_t s2 = 0;
  int x = 0;
#if defined(__SSE2__)
  // The compiler's widening of bytes to 32-bit lanes ran at ~1.2 ms a frame; byte-wise SAD sums,
  // 16-bit multiply-adds and byte compares do the same sums ~4x faster.
  const __m128i zero = _mm_setzero_si128(), one = _mm_set1_epi8(1), full = _mm_set1_epi8(char(255));
  const __m128i below = _mm_set1_epi8(char(under == 0 ? 0 : under - 1));
  __m128i vs = zero, vs2 = zero, vsat = zero, vu = zero;
  for (; x + 16 <= n; x += 16) {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(p + x));
    vs = _mm_add_epi64(vs, _mm_sad_epu8(v, zero));
    const __m128i lo = _mm_unpacklo_epi8(v, zero), hi = _mm_unpackhi_epi8(v, zero);
    vs2 = _mm_add_epi32(vs2, _mm_add_epi32(_mm_madd_epi16(lo, lo), _mm_madd_epi16(hi, hi)));
    vsat = _mm_add_epi64(vsat, _mm_sad_epu8(_mm_and_si128(_mm_cmpeq_epi8(v, full), one), zero));
    if (under > 0) {  // v <= under - 1
      const __m128i le = _mm_cmpeq_epi8(_mm_min_epu8(v, below), v);
      vu = _mm_add_epi64(vu, _mm_sad_epu8(_mm_and_si128(le, one), zero));
    }
  }
  alignas(16) uint64_t q[2];
  alignas(16) uint32_t d[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(q), vs);
  s = q[0] + q[1];
  _mm_store_si128(reinterpret_cast<__m128i*>(q), vsat);
  sat = q[0] + q[1];
  _mm_store_si128(reinterpret_cast<__m128i*>(q), vu);
  u = q[0] + q[1];
  _mm_store_si128(reinterpret_cast<__m128i*>(d), vs2);  // each lane < 4 * 255^2 * 4096 < 2^32
  s2 = d[0] + d[1] + d[2] + d[3];
#endif
  for (; x < n; ++x) {
    const uint32_t v = p[x];
    s += v;
    s2 += v * v;
    sat += v == 255u;
    u += v < under;
  }
  return {s2, uint32_t(s), uint32_t(sat), uint32_t(u)};
}

INSPECT_STATS_KERNEL RunSums SumRun16(const uint16_t* __restrict p, int n, uint16_t saturated, uint16_t under) {
  uint64_t s2 = 0;
  uint32_t s = 0, sat = 0, u = 0;
  for (int x = 0; x < n; ++x) {
    const uint32_t v = p[x];
    s += v;
    s2 += uint64_t(v) * v;
    sat += v >= saturated;
    u += v < under;
  }
  return {s2, s, sat, u};
}

template <typename T>
FrameStatistics Compute(const cv::Mat& frame, int bit_depth) {
  const double full = double((1u << bit_depth) - 1u);
  const T sat = T(full);
  const T under = T(std::floor(0.02 * full));
  // Exact integer sums per run, accumulated in double (as the double sums of integers were).
  double sum = 0, sum2 = 0;
  uint64_t n_sat = 0, n_under = 0;
  for (int y = 0; y < frame.rows; ++y) {
    const T* row = frame.ptr<T>(y);
    for (int x0 = 0; x0 < frame.cols; x0 += kRun) {
      const int n = std::min(kRun, frame.cols - x0);
      RunSums r;
      if constexpr (sizeof(T) == 1) {
        r = SumRun8(row + x0, n, under);
      } else {
        r = SumRun16(row + x0, n, sat, under);
      }
      sum += double(r.sum);
      sum2 += double(r.sum2);
      n_sat += r.saturated;
      n_under += r.under;
    }
  }
  const double n = double(frame.total());
  FrameStatistics s;
  if (n == 0) return s;
  const double scale = 255.0 / full;
  const double mean = sum / n;
  s.mean_grey = mean * scale;
  s.stddev_grey = std::sqrt(std::max(0.0, sum2 / n - mean * mean)) * scale;
  s.saturated_percent = 100.0 * double(n_sat) / n;
  s.underexposed_percent = 100.0 * double(n_under) / n;
  return s;
}
}  // namespace

FrameStatistics ComputeFrameStatistics(const cv::Mat& frame, int bit_depth) {
  if (frame.depth() == CV_16U) return Compute<uint16_t>(frame, std::clamp(bit_depth, 8, 16));
  return Compute<uint8_t>(frame, 8);
}

}  // namespace inspection
