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
