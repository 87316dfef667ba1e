// Portable variants of the frame statistics' row sums (core/io/internal/frame_stats_kernel.h),
// and the run-time choice among the variants.
#include "core/io/internal/frame_stats_kernel.h"

#include "core/util/simd_dispatch.h"

namespace inspection::frame_stats_internal {

RunSums SumRun8Portable(const uint8_t* p, int n, uint8_t under) { return SumRun8Tail(p, 0, n, under, 0, 0, 0, 0); }

RunSums SumRun16Portable(const uint16_t* p, int n, uint16_t saturated, uint16_t under) {
  return SumRun16Loop(p, n, saturated, under);
}

SumRun8Fn PickSumRun8() {
#if defined(__x86_64__)
  static constexpr IsaVariant<SumRun8Fn> kVariants[] = {{Isa::kPortable, SumRun8Portable}, {Isa::kSse2, SumRun8Sse2}};
#else
  static constexpr IsaVariant<SumRun8Fn> kVariants[] = {{Isa::kPortable, SumRun8Portable}};
#endif
  return PickVariant(kVariants);
}

SumRun16Fn PickSumRun16() {
#if defined(__x86_64__)
  static constexpr IsaVariant<SumRun16Fn> kVariants[] = {{Isa::kPortable, SumRun16Portable},
                                                         {Isa::kAvx2, SumRun16Avx2}};
#else
  static constexpr IsaVariant<SumRun16Fn> kVariants[] = {{Isa::kPortable, SumRun16Portable}};
#endif
  return PickVariant(kVariants);
}

}  // namespace inspection::frame_stats_internal
