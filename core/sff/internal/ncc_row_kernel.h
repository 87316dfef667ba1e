// The NCC row kernel of the correlation focus measure (core/sff/internal/ncc_kernel.cc): from a
// row's patch sums, the NCC and C sigma_w per pixel (thesis eq. 5.25-5.26). Variants per
// instruction set (core/util/simd_dispatch.h): the portable template below (float and double
// sums), ncc_row_kernel_avx2.cc (float sums, 8 pixels a step). Internal to core/sff.
#pragma once

#include <algorithm>
#include <cmath>

#include "core/util/cpu_features.h"

namespace inspection::ncc_kernel {

// eq. 5.25 in sums: C = (n Swt - Sw St) / sqrt((n Sww - Sw^2)(n Stt - St^2)), and
// C sigma_w = cov(w, t) / sigma_t = (n Swt - Sw St) / (n sqrt(n Stt - St^2)); 0 for a flat patch
// (sww >= 0, so var_w > 1e-9 n sww also asks var_w > 0: a variance at rounding level is flat).
template <typename A>
void NccRowPortable(const A* sw, const A* sww, const A* swt, const float* tsum, const float* tinv, int n, int begin,
                    int count, float* c_out, float* p_out) {
  for (int x = begin; x < count; ++x) {
    const double var_w = double(n) * double(sww[x]) - double(sw[x]) * double(sw[x]);
    const float num = (float(n) * float(swt[x]) - float(sw[x]) * tsum[x]) * tinv[x];
    const bool ok = var_w > 1e-9 * double(n) * double(sww[x]);
    const float root = ok ? float(std::sqrt(var_w)) : 1.0f;
    const float c = ok ? std::clamp(num / root, -1.0f, 1.0f) : 0.0f;
    c_out[x] = c;
    p_out[x] = c * root / float(n);
  }
}

// The patch-sum loops, written once and compiled into each variant below (they vectorise).
// out[x] = sum of v[x .. x + k - 1], x = 0..count-1.
template <typename A>
__attribute__((always_inline)) inline void WindowSumsLoop(const A* __restrict v, A* __restrict out, int count, int k) {
  for (int x = 0; x < count; ++x) out[x] = v[x];
  for (int j = 1; j < k; ++j)
    for (int x = 0; x < count; ++x) out[x] += v[x + j];
}

// Slides the vertical patch sums by one row: - row o, + row n (o and n of w and t).
template <typename A>
__attribute__((always_inline)) inline void SlidePatchSumsLoop(const A* __restrict wo, const A* __restrict wn,
                                                              const float* __restrict to, const float* __restrict tn,
                                                              A* __restrict vw, A* __restrict vww, A* __restrict vwt,
                                                              int count) {
  for (int c = 0; c < count; ++c) {
    vw[c] += wn[c] - wo[c];
    vww[c] += wn[c] * wn[c] - wo[c] * wo[c];
    vwt[c] += wn[c] * A(tn[c]) - wo[c] * A(to[c]);
  }
}

// The two loops for float (A = float) and double sums. Variants: portable, AVX2 (compiled for
// AVX2 without FMA, so each product is rounded as in the portable code: the same sums).
template <typename A>
struct PatchSumKernels {
  void (*window_sums)(const A* v, A* out, int count, int k);
  void (*slide)(const A* wo, const A* wn, const float* to, const float* tn, A* vw, A* vww, A* vwt, int count);
};
template <typename A>
PatchSumKernels<A> PatchSumsPortable();
template <typename A>
PatchSumKernels<A> PatchSumsAvx2();  // needs Isa::kAvx2
template <typename A>
const PatchSumKernels<A>& PickPatchSums();  // the variant for this CPU

// The float-sum row over x in [0, count).
using NccRowFloatFn = void (*)(const float* sw, const float* sww, const float* swt, const float* tsum,
                               const float* tinv, int n, int count, float* c_out, float* p_out);

void NccRowFloatPortable(const float* sw, const float* sww, const float* swt, const float* tsum, const float* tinv,
                         int n, int count, float* c_out, float* p_out);
// Needs Isa::kAvx2. The variance in double as in the portable loop (the float sums are exact
// integers, their products are not); its square root in float, so C and C sigma_w differ from
// the portable ones by float rounding of the root (a few ulp).
void NccRowFloatAvx2(const float* sw, const float* sww, const float* swt, const float* tsum, const float* tinv,
                     int n, int count, float* c_out, float* p_out);

// The variant for this CPU.
NccRowFloatFn PickNccRowFloat();

}  // namespace inspection::ncc_kernel
