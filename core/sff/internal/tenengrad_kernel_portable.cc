// Portable instance of the fused Tenengrad kernel (thesis eq. 3.13-3.14, state update of 3.1.4),
// for CPUs without AVX2 or use_simd = false, and the scalar reference of the compact kernels.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/sff/depth_interpolation.h"
#include "core/sff/internal/tenengrad_kernel.h"

namespace inspection::sff_internal::portable {

// Sobel energy of one row (eq. 3.13-3.14 before the window sum) and the running column sums
// (contract: core/sff/internal/tenengrad_kernel.simd.h), in int32 lanes that GCC vectorises.
SFF_INLINE void EnergyRow(const int16_t* __restrict a, const int16_t* __restrict b, const int16_t* __restrict c,
                          const int32_t* old_in, int32_t* old_out, int32_t* __restrict colsum, int ew) {
  for (int x = 0; x < ew; ++x) {
    const int32_t gx = (a[x] + 2 * b[x] + c[x]) - (a[x + 2] + 2 * b[x + 2] + c[x + 2]);
    const int32_t gy = (a[x] - c[x]) + 2 * (a[x + 1] - c[x + 1]) + (a[x + 2] - c[x + 2]);
    const int32_t e = gx * gx + gy * gy;
    colsum[x] += e - old_in[x];
    old_out[x] = e;
  }
}

SFF_INLINE void SobelEnergyRow(const int16_t* a, const int16_t* b, const int16_t* c, TenengradScratch& sc,
                               const int32_t* old_in, int32_t* old_out, int ew) {
  EnergyRow(a, b, c, old_in, old_out, sc.colsum.data(), ew);
}

}  // namespace inspection::sff_internal::portable

#define SFF_ISA Isa::kPortable
#define SFF_ISA_NS portable
#define SFF_TARGET
#include "core/sff/internal/tenengrad_kernel.simd.h"

namespace inspection::sff_internal {

// Compact state: frames k_begin .. k_end-1 over pixels x_begin .. x_end-1 of a row (frame 0 on
// the Reset state initialises it: t_0 and t_1 do not exist, F_max = F(0), idx = 0). The
// reference for the vector kernels (tenengrad_kernel_avx2.cc, tenengrad_kernel_avx512.cc), which
// do the same float and integer operations in the same order (bit-identical). Since idx < k at
// frame k, idx == k-1 is idx > k-2 and idx in {k-1, k-2} (t_k involves the maximum) is idx > k-3.
template <>
void TenengradKernels<Isa::kPortable>::UpdateCompact(CompactPtrs s, int x_begin, int x_end, int k_begin, int k_end,
                                                     int slot0, const int32_t* vol_row, size_t slot_stride,
                                                     const uint8_t* const* pix_rows) {
  const float pmax = FromBits(kPendingMaxBits);
  for (int x = x_begin; x < x_end; ++x) {
    int32_t b = s.best[x];
    const uint32_t w1 = s.sum_idx[x], w2 = s.kept_idx[x];
    int32_t id = int32_t((w1 & 0xFFu) | ((w2 & 0xFFu) << 8));
    float sum = FromBits(w1 & kSumMask), kept = FromBits(w2 & kSumMask);
    uint32_t lbits = (uint32_t(s.last[x]) << 12) + kOneBits, l2bits = (uint32_t(s.last2[x]) << 12) + kOneBits;
    uint32_t pbits = (uint32_t(s.before[x]) << 12) + kOneBits, nbits = (uint32_t(s.after[x]) << 12) + kOneBits;
    uint32_t ebits = (uint32_t(s.pending[x]) << 13) + kOneBits;
    int32_t a = s.aif[x];
    float lf = FromBits(lbits) - 1.f;
    float d = lf - (FromBits(l2bits) - 1.f);  // F(k-1) - F(k-2)
    float ef = FromBits(ebits) - 1.f;
    for (int k = k_begin; k < k_end; ++k) {
      const int slot = k - slot0;
      const int32_t v = vol_row[size_t(slot) * slot_stride + x];
      const int32_t p = pix_rows[slot][x];
      const float fv = float(v);
      const float t = (fv - lf) - d;          // t_k in float: for wide windows 2 F overflows int32
      const float t2 = k >= 2 ? t * t : 0.f;  // t_1 does not exist
      const bool gt = v > b, was = id > k - 2, near = id > k - 3;
      kept = FromBits(Bits(kept + (gt ? ef : (near ? 0.f : t2))) & kSumMask);
      const float en = gt ? t2 : ef + (near ? t2 : 0.f);
      const float e1 = en + 1.f;
      ebits = Bits(e1 < pmax ? e1 : pmax) & kPendingMask;
      ef = FromBits(ebits) - 1.f;
      sum = FromBits(Bits(sum + fv) & kSumMask);
      const uint32_t vbits = Bits(fv + 1.f) & kSampleMask;
      const float vf = FromBits(vbits) - 1.f;
      nbits = gt ? kOneBits : (was ? vbits : nbits);
      pbits = gt ? lbits : pbits;
      b = gt ? v : b;
      id = gt ? k : id;
      a = gt ? p : a;
      d = vf - lf;
      lf = vf;
      l2bits = lbits;
      lbits = vbits;
    }
    s.best[x] = b;
    s.sum_idx[x] = Bits(sum) | (uint32_t(id) & 0xFFu);
    s.kept_idx[x] = Bits(kept) | (uint32_t(id) >> 8);
    s.last[x] = uint16_t((lbits - kOneBits) >> 12);
    s.last2[x] = uint16_t((l2bits - kOneBits) >> 12);
    s.before[x] = uint16_t((pbits - kOneBits) >> 12);
    s.after[x] = uint16_t((nbits - kOneBits) >> 12);
    s.pending[x] = uint16_t((ebits - kOneBits) >> 13);
    s.aif[x] = uint8_t(a);
  }
}

namespace {

// Scalar twin of LogPositiveAvx2 (tenengrad_kernel_avx2.cc): the same float operations in the
// same order (bit-identical).
inline float LogPositiveScalar(float x) {
  const uint32_t bits = std::bit_cast<uint32_t>(x);
  int32_t e = int32_t(bits >> 23) - 127;
  float m = std::bit_cast<float>((bits & 0x007fffffu) | 0x3f800000u);
  if (m > 1.41421356f) {
    m = m * 0.5f;
    e += 1;
  }
  const float sv = (m - 1.f) / (m + 1.f);
  const float s2 = sv * sv;
  float poly = 1.f / 9.f;
  poly = poly * s2 + 1.f / 7.f;
  poly = poly * s2 + 1.f / 5.f;
  poly = poly * s2 + 1.f / 3.f;
  poly = poly * s2 + 1.f;
  const float log_m = (2.f * sv) * poly;
  return float(e) * 0.69314718056f + log_m;
}

}  // namespace

// Interpolation and confidence of compact state pixels x_begin .. x_end-1 (the tail after the
// AVX2 blocks, or everything without AVX2): the scalar twin of the AVX2 kernel, bit-identical
// per pixel, with the same in-place rule (core/sff/internal/tenengrad_kernel.h, FinishCompactRow).
template <>
size_t TenengradKernels<Isa::kPortable>::FinishCompact(CompactPtrs s, int x_begin, int x_end, const float* zf, int n,
                                                       DepthInterpolation interpolation, float min_confidence,
                                                       uint32_t* depth, uint32_t* conf, uint8_t* aif) {
  auto maxps = [](float a, float b) { return a > b ? a : b; };  // _mm256_max_ps(a, b)
  auto minps = [](float a, float b) { return a < b ? a : b; };  // _mm256_min_ps(a, b)
  size_t valid = 0;
  const float inv_n = 1.f / float(n);
  for (int x = x_begin; x < x_end; ++x) {
    const uint32_t w1 = s.sum_idx[x], w2 = s.kept_idx[x];
    const int32_t m = int32_t((w1 & 0xFFu) | ((w2 & 0xFFu) << 8));
    const float best = float(s.best[x]);
    const float f1 = FromBits((uint32_t(s.before[x]) << 12) + kOneBits) - 1.f;
    const float f3 = FromBits((uint32_t(s.after[x]) << 12) + kOneBits) - 1.f;
    const uint8_t grey = s.aif[x];
    const float mean = FromBits(w1 & kSumMask) * inv_n;
    const float prominence = best - mean;
    const int32_t hi = std::min(n - 1, m + 2), lo = std::max(2, m);
    const int32_t excluded = std::max(0, hi - lo + 1);
    const int32_t count_t = std::max(0, n - 2) - excluded;
    const float sq = maxps(0.f, FromBits(w2 & kSumMask));
    const float countf = float(count_t);
    // FocusConfidence: the flank terms count 1 + kFlankTermExtraWeight times.
    const float weighted = countf + float(kFlankTermExtraWeight) * float(FlankTermCount(m, n));
    float sigma = std::sqrt(sq / (6.f * maxps(weighted, 1.f)));
    if (!(countf > 0.f)) sigma = 0.f;
    sigma = maxps(sigma, 1e-3f * best);
    float c = 1.f - (float(kConfidenceSnrZero) * sigma) / maxps(prominence, 1e-30f);
    c = minps(1.f, maxps(0.f, c));
    if (!(prominence > 0.f && best > 0.f)) c = 0.f;
    const bool at_end = m == 0 || m == n - 1;
    if (at_end) c = c * 0.5f;
    const float z2 = zf[m];
    float z_um = z2;
    if (interpolation == DepthInterpolation::kGaussian || interpolation == DepthInterpolation::kDefocusParabola) {
      const float u1 = zf[std::max(0, m - 1)] - z2, u3 = zf[std::min(n - 1, m + 1)] - z2;
      const bool ok_f = f1 > 0.f && f3 > 0.f && !at_end && best > 0.f;
      if (ok_f) {
        const float r1 = best / f1, r3 = best / f3;
        const bool parabola = interpolation == DepthInterpolation::kDefocusParabola;
        const float a = parabola ? std::sqrt(r1) - 1.f : LogPositiveScalar(r1);
        const float b = parabola ? std::sqrt(r3) - 1.f : LogPositiveScalar(r3);
        const float den = a * u3 - b * u1;
        const float num_var = (u1 * u3) * (u1 - u3);
        if (den * num_var > 0.f) {
          const float mu = (a * (u3 * u3) - b * (u1 * u1)) / (2.f * den);
          if (mu >= minps(u1, u3) && mu <= maxps(u1, u3)) z_um = z2 + mu;
        }
      }
      if (z_um == z2) z_um = z2 + 0.f;  // as the vector path adds a masked +0
    }
    const bool keep = c >= min_confidence;
    conf[x] = Bits(c);
    depth[x] = Bits(keep ? z_um : std::numeric_limits<float>::quiet_NaN());
    aif[x] = grey;
    valid += keep;
  }
  return valid;
}

}  // namespace inspection::sff_internal
