// PNG row unfiltering (PNG spec 9.2) for the filters that dominate OpenCV's output, Sub (bpp 1
// and 2: grey 8 and 16 bit) and Up, as used by core/io/png_frame_decode.cc. Variants per
// instruction set (core/util/simd_dispatch.h): png_unfilter_kernel_portable.cc,
// png_unfilter_kernel_sse2.cc. Byte arithmetic: every variant gives the same bytes.
// In place: out may lie before in within one buffer (out[x] is written after in[x] is read and
// never reaches an unread byte of in). Internal to core/io.
#pragma once

#include <cstddef>

#include "core/util/cpu_features.h"

namespace inspection::png_internal {

struct PngUnfilterKernels {
  void (*sub1)(const unsigned char* in, unsigned char* out, size_t stride);  // Sub, bpp 1
  void (*sub2)(const unsigned char* in, unsigned char* out, size_t stride);  // Sub, bpp 2
  void (*up)(const unsigned char* in, const unsigned char* up, unsigned char* out, size_t stride);
};

PngUnfilterKernels PngUnfilterPortable();
PngUnfilterKernels PngUnfilterSse2();  // needs Isa::kSse2

// The variant for this CPU.
const PngUnfilterKernels& PickPngUnfilter();

}  // namespace inspection::png_internal
