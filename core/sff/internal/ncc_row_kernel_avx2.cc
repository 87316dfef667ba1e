// AVX2 variants of the NCC row kernels (core/sff/internal/ncc_row_kernel.h): the float-sum row
// 8 pixels a step (the rest of the row by the portable loop), and the patch-sum loops compiled
// for AVX2.
#include "core/sff/internal/ncc_row_kernel.h"

#if defined(__x86_64__)
#include <immintrin.h>

namespace inspection::ncc_kernel {

__attribute__((target("avx2"))) void NccRowFloatAvx2(const float* sw, const float* sww, const float* swt, const float* tsum,
                                                     const float* tinv, int n, int count, float* c_out, float* p_out) {
  const __m256d nd = _mm256_set1_pd(n), tiny = _mm256_set1_pd(1e-9 * n);
  const __m256 nf = _mm256_set1_ps(float(n)), inv_n = _mm256_set1_ps(1.0f / float(n));
  const __m256 one = _mm256_set1_ps(1.0f), minus_one = _mm256_set1_ps(-1.0f);
  int x = 0;
  for (; x + 8 <= count; x += 8) {
    const __m256 a = _mm256_loadu_ps(sw + x), b = _mm256_loadu_ps(sww + x);
    __m256d var[2], thr[2];
    for (int h = 0; h < 2; ++h) {
      const __m256d ad = _mm256_cvtps_pd(h ? _mm256_extractf128_ps(a, 1) : _mm256_castps256_ps128(a));
      const __m256d bd = _mm256_cvtps_pd(h ? _mm256_extractf128_ps(b, 1) : _mm256_castps256_ps128(b));
      var[h] = _mm256_sub_pd(_mm256_mul_pd(nd, bd), _mm256_mul_pd(ad, ad));
      thr[h] = _mm256_mul_pd(tiny, bd);
    }
    // Pack the two 4 x 64-bit masks and variances into 8 x 32-bit lanes.
    const __m128 m0 = _mm256_cvtpd_ps(_mm256_cmp_pd(var[0], thr[0], _CMP_GT_OQ));
    const __m128 m1 = _mm256_cvtpd_ps(_mm256_cmp_pd(var[1], thr[1], _CMP_GT_OQ));
    // A true 64-bit mask converts to NaN, a false one to 0: NaN != NaN marks the true lanes.
    const __m256 mask_nan = _mm256_set_m128(m1, m0);
    const __m256 ok = _mm256_cmp_ps(mask_nan, mask_nan, _CMP_UNORD_Q);
    const __m256 var_f = _mm256_set_m128(_mm256_cvtpd_ps(var[1]), _mm256_cvtpd_ps(var[0]));
    const __m256 root = _mm256_sqrt_ps(_mm256_blendv_ps(one, var_f, ok));
    const __m256 num = _mm256_mul_ps(
        _mm256_sub_ps(_mm256_mul_ps(nf, _mm256_loadu_ps(swt + x)), _mm256_mul_ps(a, _mm256_loadu_ps(tsum + x))),
        _mm256_loadu_ps(tinv + x));
    __m256 c = _mm256_min_ps(_mm256_max_ps(_mm256_div_ps(num, root), minus_one), one);
    c = _mm256_and_ps(c, ok);
    _mm256_storeu_ps(c_out + x, c);
    _mm256_storeu_ps(p_out + x, _mm256_mul_ps(_mm256_mul_ps(c, root), inv_n));
  }
  NccRowPortable(sw, sww, swt, tsum, tinv, n, x, count, c_out, p_out);
}

namespace {
template <typename A>
__attribute__((target("avx2"))) void WindowSumsAvx2(const A* v, A* out, int count, int k) {
  WindowSumsLoop(v, out, count, k);
}
template <typename A>
__attribute__((target("avx2"))) void SlideAvx2(const A* wo, const A* wn, const float* to, const float* tn, A* vw,
                                               A* vww, A* vwt, int count) {
  SlidePatchSumsLoop(wo, wn, to, tn, vw, vww, vwt, count);
}
}  // namespace

template <typename A>
PatchSumKernels<A> PatchSumsAvx2() {
  return {WindowSumsAvx2<A>, SlideAvx2<A>};
}

template PatchSumKernels<float> PatchSumsAvx2<float>();
template PatchSumKernels<double> PatchSumsAvx2<double>();

}  // namespace inspection::ncc_kernel
#endif
