// AVX2 instance of the fused Tenengrad kernel (thesis eq. 3.13-3.14, state update of 3.1.4) and
// the AVX2 compact-state kernels: bit-identical to tenengrad_kernel_portable.cc. Every function
// here is compiled with target("avx2") and only called where the CPU has AVX2.
#include <immintrin.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <limits>

#include "core/sff/depth_interpolation.h"
#include "core/sff/internal/tenengrad_kernel.h"

namespace inspection::sff_internal::avx2 {

// Sobel energy of one row and the running column sums (contract: core/sff/internal/tenengrad_kernel.simd.h)
// in 16-bit lanes: |Gx|, |Gy| <= 1020 fit int16, and vpmaddwd of interleaved (Gx, Gy) pairs
// gives Gx^2 + Gy^2 in int32 exactly.
// Whole blocks of 16 up to EnergyStride(ew) (buffers sized by TenengradScratch::Reserve): the
// columns past ew hold garbage that is never read.
__attribute__((target("avx2"))) inline void EnergyRowAvx2(const int16_t* a, const int16_t* b, const int16_t* c,
                                                          int16_t* sv, int16_t* dv, const int32_t* old_in,
                                                          int32_t* old_out, int32_t* colsum, int ew) {
  const int es = TenengradScratch::EnergyStride(ew);
  for (int i = 0; i < es + 2; i += 16) {
    const __m256i va = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a + i));
    const __m256i vb = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + i));
    const __m256i vc = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(c + i));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(sv + i),
                        _mm256_add_epi16(_mm256_add_epi16(va, vc), _mm256_add_epi16(vb, vb)));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(dv + i), _mm256_sub_epi16(va, vc));
  }
  for (int x = 0; x < es; x += 16) {
    const __m256i gx = _mm256_sub_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(sv + x)),
                                        _mm256_loadu_si256(reinterpret_cast<const __m256i*>(sv + x + 2)));
    const __m256i d1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(dv + x + 1));
    const __m256i gy =
        _mm256_add_epi16(_mm256_add_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(dv + x)),
                                          _mm256_loadu_si256(reinterpret_cast<const __m256i*>(dv + x + 2))),
                         _mm256_add_epi16(d1, d1));
    const __m256i lo = _mm256_unpacklo_epi16(gx, gy), hi = _mm256_unpackhi_epi16(gx, gy);
    const __m256i elo = _mm256_madd_epi16(lo, lo), ehi = _mm256_madd_epi16(hi, hi);
    // unpack works within 128-bit lanes: restore pixel order x .. x+7 and x+8 .. x+15.
    const __m256i e0 = _mm256_permute2x128_si256(elo, ehi, 0x20);
    const __m256i e1 = _mm256_permute2x128_si256(elo, ehi, 0x31);
    __m256i* cs = reinterpret_cast<__m256i*>(colsum + x);
    const __m256i* oi = reinterpret_cast<const __m256i*>(old_in + x);
    __m256i* od = reinterpret_cast<__m256i*>(old_out + x);
    const __m256i o0 = _mm256_loadu_si256(oi), o1 = _mm256_loadu_si256(oi + 1);
    _mm256_storeu_si256(cs, _mm256_add_epi32(_mm256_loadu_si256(cs), _mm256_sub_epi32(e0, o0)));
    _mm256_storeu_si256(cs + 1, _mm256_add_epi32(_mm256_loadu_si256(cs + 1), _mm256_sub_epi32(e1, o1)));
    _mm256_storeu_si256(od, e0);
    _mm256_storeu_si256(od + 1, e1);
  }
}

__attribute__((target("avx2"))) inline void SobelEnergyRow(const int16_t* a, const int16_t* b, const int16_t* c,
                                                           TenengradScratch& sc, const int32_t* old_in,
                                                           int32_t* old_out, int ew) {
  EnergyRowAvx2(a, b, c, sc.sv.data(), sc.dv.data(), old_in, old_out, sc.colsum.data(), ew);
}

}  // namespace inspection::sff_internal::avx2

#define SFF_ISA Isa::kAvx2
#define SFF_ISA_NS avx2
#define SFF_TARGET __attribute__((target("avx2")))
#include "core/sff/internal/tenengrad_kernel.simd.h"

namespace inspection::sff_internal {
namespace {

__attribute__((target("avx2"))) inline __m256i ld(const int32_t* p) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
}
__attribute__((target("avx2"))) inline void st(int32_t* p, __m256i v) {
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), v);
}

// Lanes of y where the 32-bit lane of mask is all ones, else of x (mask lanes: 0 or all ones).
// vblendvps: GCC turns _mm256_blendv_epi8 on such masks into an extra byte comparison.
__attribute__((target("avx2"))) inline __m256i BlendLanes(__m256i x, __m256i y, __m256i mask) {
  return _mm256_castps_si256(
      _mm256_blendv_ps(_mm256_castsi256_ps(x), _mm256_castsi256_ps(y), _mm256_castsi256_ps(mask)));
}

__attribute__((target("avx2"))) inline __m256i Ld16(const uint16_t* p) {
  return _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
}
__attribute__((target("avx2"))) inline void St16(uint16_t* p, __m256i v) {  // lanes < 65536
  _mm_storeu_si128(reinterpret_cast<__m128i*>(p),
                   _mm_packus_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1)));
}
__attribute__((target("avx2"))) inline __m256i Ld8(const uint8_t* p) {
  return _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)));
}
__attribute__((target("avx2"))) inline void St8(uint8_t* p, __m256i v) {  // lanes < 256
  const __m128i w = _mm_packus_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
  _mm_storel_epi64(reinterpret_cast<__m128i*>(p), _mm_packus_epi16(w, w));
}
__attribute__((target("avx2"))) inline __m256 AsPs(__m256i v) { return _mm256_castsi256_ps(v); }
__attribute__((target("avx2"))) inline __m256i AsSi(__m256 v) { return _mm256_castps_si256(v); }

// Natural logarithm of positive, finite floats: exponent and mantissa in [sqrt(1/2), sqrt(2)),
// log(m) = 2 atanh(s), s = (m - 1) / (m + 1), |s| < 0.172, series to s^9 (relative error < 1e-7).
__attribute__((target("avx2"))) inline __m256 LogPositiveAvx2(__m256 x) {
  const __m256i bits = _mm256_castps_si256(x);
  __m256i e = _mm256_sub_epi32(_mm256_srli_epi32(bits, 23), _mm256_set1_epi32(127));
  __m256 m = _mm256_castsi256_ps(_mm256_or_si256(_mm256_and_si256(bits, _mm256_set1_epi32(0x007fffff)),
                                                 _mm256_set1_epi32(0x3f800000)));  // [1, 2)
  const __m256 big = _mm256_cmp_ps(m, _mm256_set1_ps(1.41421356f), _CMP_GT_OQ);
  m = _mm256_blendv_ps(m, _mm256_mul_ps(m, _mm256_set1_ps(0.5f)), big);
  e = _mm256_sub_epi32(e, _mm256_castps_si256(big));  // big lanes are -1: e + 1
  const __m256 one = _mm256_set1_ps(1.f);
  const __m256 sv = _mm256_div_ps(_mm256_sub_ps(m, one), _mm256_add_ps(m, one));
  const __m256 s2 = _mm256_mul_ps(sv, sv);
  __m256 poly = _mm256_set1_ps(1.f / 9.f);
  poly = _mm256_add_ps(_mm256_mul_ps(poly, s2), _mm256_set1_ps(1.f / 7.f));
  poly = _mm256_add_ps(_mm256_mul_ps(poly, s2), _mm256_set1_ps(1.f / 5.f));
  poly = _mm256_add_ps(_mm256_mul_ps(poly, s2), _mm256_set1_ps(1.f / 3.f));
  poly = _mm256_add_ps(_mm256_mul_ps(poly, s2), one);
  const __m256 log_m = _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(2.f), sv), poly);
  return _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(e), _mm256_set1_ps(0.69314718056f)), log_m);
}

}  // namespace

// The compact state update (scalar reference: tenengrad_kernel_portable.cc) for blocks of 8
// pixels whose state stays in registers over the frames.
template <>
__attribute__((target("avx2"))) void TenengradKernels<Isa::kAvx2>::UpdateCompact(CompactPtrs s, int x_begin, int x_end,
                                                                                 int k_begin, int k_end, int slot0,
                                                                                 const int32_t* vol_row,
                                                                                 size_t slot_stride,
                                                                                 const uint8_t* const* pix_rows) {
  const __m256i one_bits = _mm256_set1_epi32(int(kOneBits)), low8 = _mm256_set1_epi32(0xFF);
  const __m256i sample_mask = _mm256_set1_epi32(int(kSampleMask)), pending_mask = _mm256_set1_epi32(int(kPendingMask));
  const __m256 sum_mask = AsPs(_mm256_set1_epi32(int(kSumMask)));
  const __m256 pmax = AsPs(_mm256_set1_epi32(int(kPendingMaxBits)));
  const __m256 fone = _mm256_set1_ps(1.f), fzero = _mm256_setzero_ps();
  const __m256i ione = _mm256_set1_epi32(1);
  for (int x = x_begin; x + 8 <= x_end; x += 8) {
    __m256i b = ld(s.best + x);
    const __m256i w1 = ld(reinterpret_cast<const int32_t*>(s.sum_idx + x));
    const __m256i w2 = ld(reinterpret_cast<const int32_t*>(s.kept_idx + x));
    __m256i id = _mm256_or_si256(_mm256_and_si256(w1, low8), _mm256_slli_epi32(_mm256_and_si256(w2, low8), 8));
    __m256 sum = _mm256_and_ps(AsPs(w1), sum_mask), kept = _mm256_and_ps(AsPs(w2), sum_mask);
    __m256i lbits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.last + x), 12), one_bits);
    __m256i l2bits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.last2 + x), 12), one_bits);
    __m256i pbits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.before + x), 12), one_bits);
    __m256i nbits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.after + x), 12), one_bits);
    __m256i ebits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.pending + x), 13), one_bits);
    __m256i a = Ld8(s.aif + x);
    __m256 lf = _mm256_sub_ps(AsPs(lbits), fone);
    __m256 d = _mm256_sub_ps(lf, _mm256_sub_ps(AsPs(l2bits), fone));
    __m256 ef = _mm256_sub_ps(AsPs(ebits), fone);
    __m256i kv = _mm256_set1_epi32(k_begin), km2 = _mm256_set1_epi32(k_begin - 2), km3 = _mm256_set1_epi32(k_begin - 3);
    for (int k = k_begin; k < k_end; ++k) {
      const int slot = k - slot0;
      const __m256i v = ld(vol_row + size_t(slot) * slot_stride + x);
      const __m256i p = Ld8(pix_rows[slot] + x);
      const __m256 fv = _mm256_cvtepi32_ps(v);
      const __m256 t = _mm256_sub_ps(_mm256_sub_ps(fv, lf), d);
      const __m256 t2 = k >= 2 ? _mm256_mul_ps(t, t) : fzero;
      const __m256i gt = _mm256_cmpgt_epi32(v, b);
      const __m256 gtf = AsPs(gt);
      const __m256i was = _mm256_cmpgt_epi32(id, km2);
      const __m256 nearf = AsPs(_mm256_cmpgt_epi32(id, km3));
      kept = _mm256_and_ps(_mm256_add_ps(kept, _mm256_blendv_ps(_mm256_andnot_ps(nearf, t2), ef, gtf)), sum_mask);
      const __m256 en = _mm256_blendv_ps(_mm256_add_ps(ef, _mm256_and_ps(nearf, t2)), t2, gtf);
      ebits = _mm256_and_si256(AsSi(_mm256_min_ps(_mm256_add_ps(en, fone), pmax)), pending_mask);
      ef = _mm256_sub_ps(AsPs(ebits), fone);
      sum = _mm256_and_ps(_mm256_add_ps(sum, fv), sum_mask);
      const __m256i vbits = _mm256_and_si256(AsSi(_mm256_add_ps(fv, fone)), sample_mask);
      const __m256 vf = _mm256_sub_ps(AsPs(vbits), fone);
      nbits = BlendLanes(BlendLanes(nbits, vbits, was), one_bits, gt);
      pbits = BlendLanes(pbits, lbits, gt);
      b = BlendLanes(b, v, gt);
      id = BlendLanes(id, kv, gt);
      a = BlendLanes(a, p, gt);
      d = _mm256_sub_ps(vf, lf);
      lf = vf;
      l2bits = lbits;
      lbits = vbits;
      kv = _mm256_add_epi32(kv, ione);
      km2 = _mm256_add_epi32(km2, ione);
      km3 = _mm256_add_epi32(km3, ione);
    }
    st(s.best + x, b);
    st(reinterpret_cast<int32_t*>(s.sum_idx + x), _mm256_or_si256(AsSi(sum), _mm256_and_si256(id, low8)));
    st(reinterpret_cast<int32_t*>(s.kept_idx + x), _mm256_or_si256(AsSi(kept), _mm256_srli_epi32(id, 8)));
    St16(s.last + x, _mm256_srli_epi32(_mm256_sub_epi32(lbits, one_bits), 12));
    St16(s.last2 + x, _mm256_srli_epi32(_mm256_sub_epi32(l2bits, one_bits), 12));
    St16(s.before + x, _mm256_srli_epi32(_mm256_sub_epi32(pbits, one_bits), 12));
    St16(s.after + x, _mm256_srli_epi32(_mm256_sub_epi32(nbits, one_bits), 12));
    St16(s.pending + x, _mm256_srli_epi32(_mm256_sub_epi32(ebits, one_bits), 13));
    St8(s.aif + x, a);
  }
}

// Interpolation and confidence of a compact state row span, 8 pixels at a time in float (one
// neighbour each side: maximum, Gaussian or defocus parabola): the confidence of FocusConfidence
// and the peak position of GaussianPeakZ / DefocusParabolaPeakZ. The outputs may be the state's
// own buffers (PushFrame's Finish writes depth into best and confidence into sum_idx): each block
// is read before it is written. Pixels x_begin .. x_end-1 (x_end - x_begin a multiple of 8);
// returns the number kept.
template <>
__attribute__((target("avx2"))) size_t TenengradKernels<Isa::kAvx2>::FinishCompact(
    CompactPtrs s, int x_begin, int x_end, const float* zf, int n, DepthInterpolation interpolation,
    float min_confidence, uint32_t* depth, uint32_t* conf, uint8_t* aif) {
  size_t valid = 0;
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.f);
  const __m256i izero = _mm256_setzero_si256(), low8 = _mm256_set1_epi32(0xFF);
  const __m256i one_bits = _mm256_set1_epi32(int(kOneBits));
  const __m256 sum_mask = AsPs(_mm256_set1_epi32(int(kSumMask)));
  const __m256i last_frame = _mm256_set1_epi32(n - 1);
  const __m256 inv_n = _mm256_set1_ps(1.f / float(n));
  const __m256 nan = _mm256_set1_ps(std::numeric_limits<float>::quiet_NaN());
  for (int x = x_begin; x < x_end; x += 8) {
    const __m256i w1 = ld(reinterpret_cast<const int32_t*>(s.sum_idx + x));
    const __m256i w2 = ld(reinterpret_cast<const int32_t*>(s.kept_idx + x));
    const __m256i m = _mm256_or_si256(_mm256_and_si256(w1, low8), _mm256_slli_epi32(_mm256_and_si256(w2, low8), 8));
    const __m256 best = _mm256_cvtepi32_ps(ld(s.best + x));
    const __m256 f1 = _mm256_sub_ps(AsPs(_mm256_add_epi32(_mm256_slli_epi32(Ld16(s.before + x), 12), one_bits)), one);
    const __m256 f3 = _mm256_sub_ps(AsPs(_mm256_add_epi32(_mm256_slli_epi32(Ld16(s.after + x), 12), one_bits)), one);
    const __m128i grey = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(s.aif + x));
    // Confidence: prominence over the noise level of the second differences away from the peak.
    const __m256 mean = _mm256_mul_ps(_mm256_and_ps(AsPs(w1), sum_mask), inv_n);
    const __m256 prominence = _mm256_sub_ps(best, mean);
    const __m256i hi = _mm256_min_epi32(last_frame, _mm256_add_epi32(m, _mm256_set1_epi32(2)));
    const __m256i lo = _mm256_max_epi32(_mm256_set1_epi32(2), m);
    const __m256i excluded = _mm256_max_epi32(izero, _mm256_add_epi32(_mm256_sub_epi32(hi, lo), _mm256_set1_epi32(1)));
    const __m256i count = _mm256_sub_epi32(_mm256_set1_epi32(std::max(0, n - 2)), excluded);
    const __m256 sq = _mm256_max_ps(zero, _mm256_and_ps(AsPs(w2), sum_mask));
    const __m256 countf = _mm256_cvtepi32_ps(count);
    // FocusConfidence: the flank terms count 1 + kFlankTermExtraWeight times. FlankTermCount(m,
    // n) = (m >= 3) + (m <= n - 4); the compare masks are -1 where true.
    const __m256i flank_terms = _mm256_sub_epi32(
        izero, _mm256_add_epi32(_mm256_cmpgt_epi32(m, _mm256_set1_epi32(2)),
                                _mm256_cmpgt_epi32(_mm256_set1_epi32(n - 3), m)));
    const __m256 weighted = _mm256_add_ps(
        countf, _mm256_mul_ps(_mm256_set1_ps(float(kFlankTermExtraWeight)), _mm256_cvtepi32_ps(flank_terms)));
    __m256 sigma = _mm256_sqrt_ps(_mm256_div_ps(sq, _mm256_mul_ps(_mm256_set1_ps(6.f), _mm256_max_ps(weighted, one))));
    sigma = _mm256_and_ps(sigma, _mm256_cmp_ps(countf, zero, _CMP_GT_OQ));
    sigma = _mm256_max_ps(sigma, _mm256_mul_ps(_mm256_set1_ps(1e-3f), best));
    __m256 c = _mm256_sub_ps(one, _mm256_div_ps(_mm256_mul_ps(_mm256_set1_ps(float(kConfidenceSnrZero)), sigma),
                                                _mm256_max_ps(prominence, _mm256_set1_ps(1e-30f))));
    c = _mm256_min_ps(one, _mm256_max_ps(zero, c));
    const __m256 has_peak =
        _mm256_and_ps(_mm256_cmp_ps(prominence, zero, _CMP_GT_OQ), _mm256_cmp_ps(best, zero, _CMP_GT_OQ));
    c = _mm256_and_ps(c, has_peak);
    const __m256i at_end = _mm256_or_si256(_mm256_cmpeq_epi32(m, izero), _mm256_cmpeq_epi32(m, last_frame));
    c = _mm256_blendv_ps(c, _mm256_mul_ps(c, _mm256_set1_ps(0.5f)), AsPs(at_end));
    // Depth: the frame's z, moved to the Gaussian's peak where the fit is valid.
    const __m256 z2 = _mm256_i32gather_ps(zf, m, 4);
    __m256 z_um = z2;
    if (interpolation == DepthInterpolation::kGaussian || interpolation == DepthInterpolation::kDefocusParabola) {
      const __m256i mm1 = _mm256_max_epi32(izero, _mm256_sub_epi32(m, _mm256_set1_epi32(1)));
      const __m256i mp1 = _mm256_min_epi32(last_frame, _mm256_add_epi32(m, _mm256_set1_epi32(1)));
      const __m256 u1 = _mm256_sub_ps(_mm256_i32gather_ps(zf, mm1, 4), z2);
      const __m256 u3 = _mm256_sub_ps(_mm256_i32gather_ps(zf, mp1, 4), z2);
      const __m256 ok_f =
          _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(f1, zero, _CMP_GT_OQ), _mm256_cmp_ps(f3, zero, _CMP_GT_OQ)),
                        _mm256_andnot_ps(AsPs(at_end), _mm256_cmp_ps(best, zero, _CMP_GT_OQ)));
      // Transforms only of positive finite ratios (others are masked out below). The drops from
      // the maximum to its neighbours: ln(f2/f) for the Gaussian, sqrt(f2/f) - 1 for the parabola.
      const __m256 safe1 = _mm256_blendv_ps(one, f1, ok_f), safe3 = _mm256_blendv_ps(one, f3, ok_f);
      const __m256 safe2 = _mm256_blendv_ps(one, best, ok_f);
      const __m256 r1 = _mm256_div_ps(safe2, safe1), r3 = _mm256_div_ps(safe2, safe3);
      const bool parabola = interpolation == DepthInterpolation::kDefocusParabola;
      const __m256 a = parabola ? _mm256_sub_ps(_mm256_sqrt_ps(r1), one) : LogPositiveAvx2(r1);
      const __m256 b = parabola ? _mm256_sub_ps(_mm256_sqrt_ps(r3), one) : LogPositiveAvx2(r3);
      const __m256 den = _mm256_sub_ps(_mm256_mul_ps(a, u3), _mm256_mul_ps(b, u1));
      const __m256 num_var = _mm256_mul_ps(_mm256_mul_ps(u1, u3), _mm256_sub_ps(u1, u3));
      const __m256 mu =
          _mm256_div_ps(_mm256_sub_ps(_mm256_mul_ps(a, _mm256_mul_ps(u3, u3)), _mm256_mul_ps(b, _mm256_mul_ps(u1, u1))),
                        _mm256_mul_ps(_mm256_set1_ps(2.f), den));
      const __m256 in_range = _mm256_and_ps(_mm256_cmp_ps(mu, _mm256_min_ps(u1, u3), _CMP_GE_OQ),
                                            _mm256_cmp_ps(mu, _mm256_max_ps(u1, u3), _CMP_LE_OQ));
      const __m256 ok =
          _mm256_and_ps(_mm256_and_ps(ok_f, in_range), _mm256_cmp_ps(_mm256_mul_ps(den, num_var), zero, _CMP_GT_OQ));
      z_um = _mm256_add_ps(z2, _mm256_and_ps(mu, ok));
    }
    const __m256 keep = _mm256_cmp_ps(c, _mm256_set1_ps(min_confidence), _CMP_GE_OQ);
    _mm256_storeu_ps(reinterpret_cast<float*>(conf + x), c);
    _mm256_storeu_ps(reinterpret_cast<float*>(depth + x), _mm256_blendv_ps(nan, z_um, keep));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(aif + x), grey);
    valid += size_t(__builtin_popcount(unsigned(_mm256_movemask_ps(keep))));
  }
  return valid;
}

}  // namespace inspection::sff_internal
