// SSE2 variant of the PNG unfilter kernels (core/io/internal/png_unfilter_kernel.h).
#include <cstdint>

#include "core/io/internal/png_unfilter_kernel.h"

#if defined(__x86_64__)
#include <emmintrin.h>

namespace inspection::png_internal {

namespace {

// The last `bpp` (1 or 2) bytes of v in every lane: the running sums a Sub row carries on.
template <size_t bpp>
__attribute__((target("sse2"))) inline __m128i BroadcastLast(__m128i v) {
  if constexpr (bpp == 1) v = _mm_unpackhi_epi8(v, v);  // 16-bit lane 7 = byte 15 twice
  v = _mm_shufflehi_epi16(v, 0xFF);                     // lanes 4..7 = lane 7
  return _mm_unpackhi_epi64(v, v);
}

// Sub with bpp 1 or 2 (grey 8 and 16 bit, the filter OpenCV writes by default): out[x] = in[x] +
// out[x - bpp] is a running sum in bytes, 16 bytes at a time by log-step shifted adds plus the
// previous block's last sums. The scalar loop is bound by the store-to-load latency of out[x - 1]
// (~5 cycles a byte); this is ~10x faster. Each block is loaded before its store, which is what
// the in-place layout (out before in) needs.
template <size_t bpp>
__attribute__((target("sse2"))) void UnfilterSub(const unsigned char* in, unsigned char* out, size_t stride) {
  __m128i carry = _mm_setzero_si128();
  size_t x = 0;
  for (; x + 16 <= stride; x += 16) {
    __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(in + x));
    if constexpr (bpp == 1) v = _mm_add_epi8(v, _mm_slli_si128(v, 1));
    v = _mm_add_epi8(v, _mm_slli_si128(v, 2));
    v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
    v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
    v = _mm_add_epi8(v, carry);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + x), v);
    carry = BroadcastLast<bpp>(v);
  }
  for (; x < stride; ++x) out[x] = uint8_t(in[x] + (x >= bpp ? out[x - bpp] : 0));
}

// Up: 16 bytes at a time (the compiler will not vectorise it, as out and in overlap).
__attribute__((target("sse2"))) void UnfilterUp(const unsigned char* in, const unsigned char* up, unsigned char* out, size_t stride) {
  size_t x = 0;
  for (; x + 16 <= stride; x += 16) {
    const __m128i v = _mm_add_epi8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(in + x)),
                                   _mm_loadu_si128(reinterpret_cast<const __m128i*>(up + x)));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + x), v);
  }
  for (; x < stride; ++x) out[x] = uint8_t(in[x] + up[x]);
}

}  // namespace

PngUnfilterKernels PngUnfilterSse2() { return {UnfilterSub<1>, UnfilterSub<2>, UnfilterUp}; }

}  // namespace inspection::png_internal
#endif
