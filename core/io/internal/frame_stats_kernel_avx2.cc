// AVX2 variant of the 16-bit row sums (core/io/internal/frame_stats_kernel.h): the portable loop
// compiled for AVX2 (the compiler's vectorisation, twice as wide).
#include "core/io/internal/frame_stats_kernel.h"

#if defined(__x86_64__)
namespace inspection::frame_stats_internal {

__attribute__((target("avx2"))) RunSums SumRun16Avx2(const uint16_t* p, int n, uint16_t saturated, uint16_t under) {
  return SumRun16Loop(p, n, saturated, under);
}

}  // namespace inspection::frame_stats_internal
#endif
