// AVX-512 instance of the compact-state update of the fused Tenengrad kernel (thesis 3.1.4):
// the AVX2 kernel (tenengrad_kernel_avx2.cc) with 16 lanes and mask registers, bit-identical.
// Compiled with target("avx512f") and only called where the CPU has AVX-512F.
#include <immintrin.h>

#include <cstdint>

#include "core/sff/internal/tenengrad_kernel.h"

namespace inspection::sff_internal {

// GCC 12's AVX-512 headers trip -Wmaybe-uninitialized (their _mm512_undefined_* pass-through).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

namespace {

__attribute__((target("avx512f"))) inline __m512 And512(__m512 x, __m512i mask) {
  return _mm512_castsi512_ps(_mm512_and_si512(_mm512_castps_si512(x), mask));
}
__attribute__((target("avx512f"))) inline __m512i Ld16x16(const uint16_t* p) {
  return _mm512_cvtepu16_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)));
}
__attribute__((target("avx512f"))) inline void St16x16(uint16_t* p, __m512i v) {
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), _mm512_cvtepi32_epi16(v));
}

}  // namespace

// The same operations per pixel as the AVX2 kernel (a masked add of t_k^2 equals adding
// t_k^2 & mask, as the pending sum is never -0), 16 pixels at a time.
template <>
__attribute__((target("avx512f"))) void TenengradKernels<Isa::kAvx512>::UpdateCompact(CompactPtrs s, int x_begin,
                                                                                      int x_end, int k_begin, int k_end,
                                                                                      int slot0, const int32_t* vol_row,
                                                                                      size_t slot_stride,
                                                                                      const uint8_t* const* pix_rows) {
  const __m512i one_bits = _mm512_set1_epi32(int(kOneBits)), low8 = _mm512_set1_epi32(0xFF);
  const __m512i sample_mask = _mm512_set1_epi32(int(kSampleMask)), pending_mask = _mm512_set1_epi32(int(kPendingMask));
  const __m512i sum_mask = _mm512_set1_epi32(int(kSumMask));
  const __m512 pmax = _mm512_castsi512_ps(_mm512_set1_epi32(int(kPendingMaxBits)));
  const __m512 fone = _mm512_set1_ps(1.f), fzero = _mm512_setzero_ps();
  const __m512i ione = _mm512_set1_epi32(1);
  for (int x = x_begin; x + 16 <= x_end; x += 16) {
    __m512i b = _mm512_loadu_si512(s.best + x);
    const __m512i w1 = _mm512_loadu_si512(s.sum_idx + x), w2 = _mm512_loadu_si512(s.kept_idx + x);
    __m512i id = _mm512_or_si512(_mm512_and_si512(w1, low8), _mm512_slli_epi32(_mm512_and_si512(w2, low8), 8));
    __m512 sum = _mm512_castsi512_ps(_mm512_and_si512(w1, sum_mask));
    __m512 kept = _mm512_castsi512_ps(_mm512_and_si512(w2, sum_mask));
    __m512i lbits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.last + x), 12), one_bits);
    __m512i l2bits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.last2 + x), 12), one_bits);
    __m512i pbits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.before + x), 12), one_bits);
    __m512i nbits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.after + x), 12), one_bits);
    __m512i ebits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.pending + x), 13), one_bits);
    __m512i a = _mm512_cvtepu8_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(s.aif + x)));
    __m512 lf = _mm512_sub_ps(_mm512_castsi512_ps(lbits), fone);
    __m512 d = _mm512_sub_ps(lf, _mm512_sub_ps(_mm512_castsi512_ps(l2bits), fone));
    __m512 ef = _mm512_sub_ps(_mm512_castsi512_ps(ebits), fone);
    __m512i kv = _mm512_set1_epi32(k_begin), km2 = _mm512_set1_epi32(k_begin - 2), km3 = _mm512_set1_epi32(k_begin - 3);
    for (int k = k_begin; k < k_end; ++k) {
      const int slot = k - slot0;
      const __m512i v = _mm512_loadu_si512(vol_row + size_t(slot) * slot_stride + x);
      const __m512i p = _mm512_cvtepu8_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(pix_rows[slot] + x)));
      const __m512 fv = _mm512_cvtepi32_ps(v);
      const __m512 t = _mm512_sub_ps(_mm512_sub_ps(fv, lf), d);
      const __m512 t2 = k >= 2 ? _mm512_mul_ps(t, t) : fzero;
      const __mmask16 gt = _mm512_cmpgt_epi32_mask(v, b);
      const __mmask16 was = _mm512_cmpgt_epi32_mask(id, km2);
      const __mmask16 near = _mm512_cmpgt_epi32_mask(id, km3);
      const __m512 addend = _mm512_mask_mov_ps(_mm512_maskz_mov_ps(_mm512_knot(near), t2), gt, ef);
      kept = And512(_mm512_add_ps(kept, addend), sum_mask);
      const __m512 en = _mm512_mask_mov_ps(_mm512_mask_add_ps(ef, near, ef, t2), gt, t2);
      ebits = _mm512_and_si512(_mm512_castps_si512(_mm512_min_ps(_mm512_add_ps(en, fone), pmax)), pending_mask);
      ef = _mm512_sub_ps(_mm512_castsi512_ps(ebits), fone);
      sum = And512(_mm512_add_ps(sum, fv), sum_mask);
      const __m512i vbits = _mm512_and_si512(_mm512_castps_si512(_mm512_add_ps(fv, fone)), sample_mask);
      const __m512 vf = _mm512_sub_ps(_mm512_castsi512_ps(vbits), fone);
      nbits = _mm512_mask_mov_epi32(_mm512_mask_mov_epi32(nbits, was, vbits), gt, one_bits);
      pbits = _mm512_mask_mov_epi32(pbits, gt, lbits);
      b = _mm512_mask_mov_epi32(b, gt, v);
      id = _mm512_mask_mov_epi32(id, gt, kv);
      a = _mm512_mask_mov_epi32(a, gt, p);
      d = _mm512_sub_ps(vf, lf);
      lf = vf;
      l2bits = lbits;
      lbits = vbits;
      kv = _mm512_add_epi32(kv, ione);
      km2 = _mm512_add_epi32(km2, ione);
      km3 = _mm512_add_epi32(km3, ione);
    }
    _mm512_storeu_si512(s.best + x, b);
    _mm512_storeu_si512(s.sum_idx + x, _mm512_or_si512(_mm512_castps_si512(sum), _mm512_and_si512(id, low8)));
    _mm512_storeu_si512(s.kept_idx + x, _mm512_or_si512(_mm512_castps_si512(kept), _mm512_srli_epi32(id, 8)));
    St16x16(s.last + x, _mm512_srli_epi32(_mm512_sub_epi32(lbits, one_bits), 12));
    St16x16(s.last2 + x, _mm512_srli_epi32(_mm512_sub_epi32(l2bits, one_bits), 12));
    St16x16(s.before + x, _mm512_srli_epi32(_mm512_sub_epi32(pbits, one_bits), 12));
    St16x16(s.after + x, _mm512_srli_epi32(_mm512_sub_epi32(nbits, one_bits), 12));
    St16x16(s.pending + x, _mm512_srli_epi32(_mm512_sub_epi32(ebits, one_bits), 13));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(s.aif + x), _mm512_cvtepi32_epi8(a));
  }
}
#pragma GCC diagnostic pop

}  // namespace inspection::sff_internal
