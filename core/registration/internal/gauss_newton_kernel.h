// The per-row sums of frame registration's Gauss-Newton step (core/registration/frame_registration.cc):
// the normal equations of the residual r = gain * I(W(x)) + offset - T(x) over 4 geometric and 2
// photometric parameters, and the correlation's sums. Variants per instruction set
// (core/util/simd_dispatch.h): gauss_newton_kernel_portable.cc (double sums, per pixel),
// gauss_newton_kernel_avx2.cc (float lanes over blocks of 8 pixels, the rest of the row portable).
// Internal to core/registration.
#pragma once

#include "core/util/cpu_features.h"

namespace inspection::registration_internal {

// Sums over the pixels added so far: hs the upper triangle (i <= k) of J^T J, gs J^T r, s5 the
// correlation's sw, st, sww, stt, swt; n the pixels.
struct NormalSums {
  double hs[6][6] = {};
  double gs[6] = {};
  double s5[5] = {};
  long n = 0;
};

// One row's run of pixels x in [x0, x1]. wr: the warped frame's row, up / dn: its neighbours
// (the x gradient reads wr[x - 1] and wr[x + 1]), tr: the reference's row. The geometric
// Jacobian uses u = (x - cx) / half and v (the row's coordinate, normalised likewise).
struct GaussNewtonRow {
  const float* wr;
  const float* up;
  const float* dn;
  const float* tr;
  int x0, x1;
  double cx, half, v, gain, offset;
};

using GaussNewtonRowFn = void (*)(const GaussNewtonRow& row, NormalSums* sums);

void GaussNewtonRowPortable(const GaussNewtonRow& row, NormalSums* sums);
void GaussNewtonRowAvx2(const GaussNewtonRow& row, NormalSums* sums);  // needs Isa::kAvx2

// The variant for this CPU (portable when use_simd is false).
GaussNewtonRowFn PickGaussNewtonRow(bool use_simd);

}  // namespace inspection::registration_internal
