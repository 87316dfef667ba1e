// AVX2 + FMA variant of the Gauss-Newton row sums (core/registration/internal/gauss_newton_kernel.h):
// blocks of 8 pixels accumulate in float lanes (a lane sums at most a row's pixels / 8 values of
// order 1, where float keeps ~6 digits), then each lane total is added to the double sums and
// the rest of the row (< 8 pixels) runs the portable loop. The portable loop's 32 independent
// but unvectorised double sums per pixel take ~50 cycles a pixel; this is ~10x faster. Results
// differ from the portable ones by float rounding only (tests/core/registration/).
#include <cstdint>

#include "core/registration/internal/gauss_newton_kernel.h"

#if defined(__x86_64__)
#include <immintrin.h>

namespace inspection::registration_internal {

namespace {

struct LaneSums {
  // The 21 upper-triangle Hessian terms j_i j_k (row-major, i <= k), the 6 gradient terms j_i r,
  // then sw, st, sww, stt, swt.
  static constexpr int kTerms = 32;
  alignas(32) float v[kTerms][8] = {};
};

__attribute__((target("avx2,fma"))) void AccumulateBlocks(const float* wr, const float* up, const float* dn,
                                                          const float* tr, int blocks, float u0, float du, float v,
                                                          float gain, float offset, LaneSums* out) {
  __m256 acc[LaneSums::kTerms];
  for (int q = 0; q < LaneSums::kTerms; ++q) acc[q] = _mm256_setzero_ps();
  const __m256 half_gain = _mm256_set1_ps(0.5f * gain), vv = _mm256_set1_ps(v), g = _mm256_set1_ps(gain),
               o = _mm256_set1_ps(offset), step = _mm256_set1_ps(8.0f * du);
  __m256 u = _mm256_add_ps(_mm256_set1_ps(u0), _mm256_mul_ps(_mm256_set1_ps(du), _mm256_setr_ps(0, 1, 2, 3, 4, 5, 6, 7)));
  for (int b = 0; b < blocks; ++b, wr += 8, up += 8, dn += 8, tr += 8) {
    const __m256 w = _mm256_loadu_ps(wr), t = _mm256_loadu_ps(tr);
    const __m256 ix = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(wr + 1), _mm256_loadu_ps(wr - 1)), half_gain);
    const __m256 iy = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(dn), _mm256_loadu_ps(up)), half_gain);
    const __m256 j[5] = {_mm256_fmadd_ps(ix, u, _mm256_mul_ps(iy, vv)),     // d/da
                         _mm256_fmsub_ps(iy, u, _mm256_mul_ps(ix, vv)),     // d/db
                         ix, iy, w};                                         // d/dtx, d/dty, d/dgain
    const __m256 r = _mm256_sub_ps(_mm256_fmadd_ps(g, w, o), t);           // j_5 = 1 (d/doffset)
    int q = 0;
    for (int i = 0; i < 5; ++i) {
      for (int k = i; k < 5; ++k, ++q) acc[q] = _mm256_fmadd_ps(j[i], j[k], acc[q]);
      acc[q] = _mm256_add_ps(acc[q], j[i]);  // j_i * j_5
      ++q;
    }
    acc[20] = _mm256_add_ps(acc[20], _mm256_set1_ps(1.0f));  // j_5 * j_5
    for (int i = 0; i < 5; ++i) acc[21 + i] = _mm256_fmadd_ps(j[i], r, acc[21 + i]);
    acc[26] = _mm256_add_ps(acc[26], r);
    acc[27] = _mm256_add_ps(acc[27], w);
    acc[28] = _mm256_add_ps(acc[28], t);
    acc[29] = _mm256_fmadd_ps(w, w, acc[29]);
    acc[30] = _mm256_fmadd_ps(t, t, acc[30]);
    acc[31] = _mm256_fmadd_ps(w, t, acc[31]);
    u = _mm256_add_ps(u, step);
  }
  for (int q = 0; q < LaneSums::kTerms; ++q) _mm256_store_ps(out->v[q], acc[q]);
}

// Adds the lane totals to the double sums, in the portable loop's order of terms.
void AddLaneSums(const LaneSums& lanes, NormalSums* s) {
  auto total = [&](int q) {
    double t = 0;
    for (int l = 0; l < 8; ++l) t += lanes.v[q][l];
    return t;
  };
  int q = 0;
  for (int i = 0; i < 6; ++i)
    for (int k = i; k < 6; ++k) s->hs[i][k] += total(q++);
  for (int i = 0; i < 6; ++i) s->gs[i] += total(q++);
  for (int i = 0; i < 5; ++i) s->s5[i] += total(q++);
}

}  // namespace

void GaussNewtonRowAvx2(const GaussNewtonRow& row, NormalSums* sums) {
  GaussNewtonRow rest = row;
  if (row.x1 - row.x0 + 1 >= 8) {
    LaneSums lanes;
    const int blocks = (row.x1 - row.x0 + 1) / 8, x0 = row.x0;
    AccumulateBlocks(row.wr + x0, row.up + x0, row.dn + x0, row.tr + x0, blocks, float((x0 - row.cx) / row.half),
                     float(1.0 / row.half), float(row.v), float(row.gain), float(row.offset), &lanes);
    AddLaneSums(lanes, sums);
    sums->n += blocks * 8;
    rest.x0 = x0 + blocks * 8;
  }
  GaussNewtonRowPortable(rest, sums);
}

}  // namespace inspection::registration_internal
#endif
