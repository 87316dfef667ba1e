// Portable variant of the PNG unfilter kernels (core/io/internal/png_unfilter_kernel.h), and the
// run-time choice among the variants.
#include <cstdint>

#include "core/io/internal/png_unfilter_kernel.h"
#include "core/util/simd_dispatch.h"

namespace inspection::png_internal {

namespace {

template <size_t bpp>
void UnfilterSub(const unsigned char* in, unsigned char* out, size_t stride) {
  for (size_t x = 0; x < bpp && x < stride; ++x) out[x] = in[x];
  for (size_t x = bpp; x < stride; ++x) out[x] = uint8_t(in[x] + out[x - bpp]);
}

void UnfilterUp(const unsigned char* in, const unsigned char* up, unsigned char* out, size_t stride) {
  for (size_t x = 0; x < stride; ++x) out[x] = uint8_t(in[x] + up[x]);
}

}  // namespace

PngUnfilterKernels PngUnfilterPortable() { return {UnfilterSub<1>, UnfilterSub<2>, UnfilterUp}; }

const PngUnfilterKernels& PickPngUnfilter() {
  using Pick = PngUnfilterKernels (*)();
#if defined(__x86_64__)
  static constexpr IsaVariant<Pick> kVariants[] = {{Isa::kPortable, PngUnfilterPortable},
                                                   {Isa::kSse2, PngUnfilterSse2}};
#else
  static constexpr IsaVariant<Pick> kVariants[] = {{Isa::kPortable, PngUnfilterPortable}};
#endif
  static const PngUnfilterKernels kernels = PickVariant(kVariants)();
  return kernels;
}

}  // namespace inspection::png_internal
