// Portable variant of the Gauss-Newton row sums (core/registration/internal/gauss_newton_kernel.h),
// and the run-time choice among the variants.
#include "core/registration/internal/gauss_newton_kernel.h"

#include "core/util/simd_dispatch.h"

namespace inspection::registration_internal {

void GaussNewtonRowPortable(const GaussNewtonRow& row, NormalSums* sums) {
  // The sums in a local copy, so that they stay in registers (not stores through `sums`).
  NormalSums a = *sums;
  const float *wr = row.wr, *up = row.up, *dn = row.dn, *tr = row.tr;
  const double v = row.v, gain = row.gain, offset = row.offset;
  for (int x = row.x0; x <= row.x1; ++x) {
    const double u = (x - row.cx) / row.half;
    const double iw = wr[x], t = tr[x];
    const double ix = 0.5 * (wr[x + 1] - wr[x - 1]) * gain, iy = 0.5 * (dn[x] - up[x]) * gain;
    const double j[6] = {ix * u + iy * v, -ix * v + iy * u, ix, iy, iw, 1.0};
    const double r = gain * iw + offset - t;
#pragma GCC unroll 6
    for (int i = 0; i < 6; ++i) {
      a.gs[i] += j[i] * r;
#pragma GCC unroll 6
      for (int k = i; k < 6; ++k) a.hs[i][k] += j[i] * j[k];
    }
    a.s5[0] += iw, a.s5[1] += t, a.s5[2] += iw * iw, a.s5[3] += t * t, a.s5[4] += iw * t;
    ++a.n;
  }
  *sums = a;
}

GaussNewtonRowFn PickGaussNewtonRow(bool use_simd) {
#if defined(__x86_64__)
  static constexpr IsaVariant<GaussNewtonRowFn> kVariants[] = {{Isa::kPortable, GaussNewtonRowPortable},
                                                               {Isa::kAvx2, GaussNewtonRowAvx2}};
#else
  static constexpr IsaVariant<GaussNewtonRowFn> kVariants[] = {{Isa::kPortable, GaussNewtonRowPortable}};
#endif
  return PickVariant(kVariants, use_simd);
}

}  // namespace inspection::registration_internal
