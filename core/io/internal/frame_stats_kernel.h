// The row sums of the per-frame statistics (core/io/frame_statistics.cc): sum, sum of squares,
// saturated and underexposed counts over a run of one row. Variants per instruction set
// (core/util/simd_dispatch.h): 8-bit portable / SSE2 (frame_stats_kernel_portable.cc,
// frame_stats_kernel_sse2.cc), 16-bit portable / AVX2 (the same loop compiled for AVX2,
// frame_stats_kernel_avx2.cc). All integer: every variant gives the same sums. Internal to core/io.
#pragma once

#include <cstdint>

#include "core/util/cpu_features.h"

namespace inspection::frame_stats_internal {

// A run is at most kRun pixels, so that the sums fit 32-bit counters (65535 * 65536 < 2^32; for
// 8-bit frames also 255^2 * 65536), which vectorise several times wider than 64-bit sums: this
// runs once per frame for the progress events, and took ~1.2 ms per 1600x1200 frame with 64-bit
// sums. Squares of 16-bit values do not fit 32 bits, so their sum stays 64-bit.
constexpr int kRun = 65536;

struct RunSums {
  uint64_t sum2 = 0;
  uint32_t sum = 0, saturated = 0, under = 0;
};

// 8-bit: saturated means 255, under means < `under`.
using SumRun8Fn = RunSums (*)(const uint8_t* p, int n, uint8_t under);
RunSums SumRun8Portable(const uint8_t* p, int n, uint8_t under);
RunSums SumRun8Sse2(const uint8_t* p, int n, uint8_t under);  // needs Isa::kSse2
SumRun8Fn PickSumRun8();

// 16-bit: saturated means >= `saturated`, under means < `under`.
using SumRun16Fn = RunSums (*)(const uint16_t* p, int n, uint16_t saturated, uint16_t under);
RunSums SumRun16Portable(const uint16_t* p, int n, uint16_t saturated, uint16_t under);
RunSums SumRun16Avx2(const uint16_t* p, int n, uint16_t saturated, uint16_t under);  // needs Isa::kAvx2
SumRun16Fn PickSumRun16();

// The 16-bit loop, written once and compiled into each variant (inlined into its target).
__attribute__((always_inline)) inline RunSums SumRun16Loop(const uint16_t* __restrict p, int n, uint16_t saturated,
                                                           uint16_t under) {
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

// The 8-bit scalar loop over [x, n), added to the given sums.
__attribute__((always_inline)) inline RunSums SumRun8Tail(const uint8_t* __restrict p, int x, int n, uint8_t under,
                                                          uint64_t s, uint32_t s2, uint64_t sat, uint64_t u) {
  for (; x < n; ++x) {
    const uint32_t v = p[x];
    s += v;
    s2 += v * v;
    sat += v == 255u;
    u += v < under;
  }
  return {s2, uint32_t(s), uint32_t(sat), uint32_t(u)};
}

}  // namespace inspection::frame_stats_internal
