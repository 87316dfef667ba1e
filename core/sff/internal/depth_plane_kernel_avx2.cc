// AVX2 variant of the depth-plane row kernels (core/sff/internal/depth_plane_kernel.h): the same
// loops compiled for AVX2 (4 doubles a step), without FMA.
#include "core/sff/internal/depth_plane_kernel.h"

#if defined(__x86_64__)

namespace inspection::depth_plane_kernel {

namespace {
__attribute__((target("avx2"))) void AddDepthRowAvx2(const float* __restrict s, int w, double centre, double cx0, double yc,
                                                     double sign, double* __restrict c0, double* __restrict c1, double* __restrict c2, double* __restrict c3,
                                                     double* __restrict c4) {
  AddDepthRowLoop(s, w, centre, cx0, yc, sign, c0, c1, c2, c3, c4);
}
__attribute__((target("avx2"))) void PlaneRowAvx2(const PlaneSums& prefix, int w, int r, double n,
                                                  const double* __restrict mean_xc, const double* __restrict var_x, double my, double vy,
                                                  float* __restrict o, float* __restrict sx, float* __restrict sy) {
  PlaneRowLoop(prefix, w, r, n, mean_xc, var_x, my, vy, o, sx, sy);
}
}  // namespace

PlaneKernels PlaneKernelsAvx2() { return {AddDepthRowAvx2, PlaneRowAvx2}; }

}  // namespace inspection::depth_plane_kernel
#endif
