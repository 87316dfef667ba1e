// Portable variant of the depth-plane row kernels (core/sff/internal/depth_plane_kernel.h), and
// the run-time choice among the variants.
#include "core/sff/internal/depth_plane_kernel.h"

#include "core/util/simd_dispatch.h"

namespace inspection::depth_plane_kernel {

namespace {
void AddDepthRowPortable(const float* __restrict s, int w, double centre, double cx0, double yc, double sign, double* __restrict c0,
                         double* __restrict c1, double* __restrict c2, double* __restrict c3, double* __restrict c4) {
  AddDepthRowLoop(s, w, centre, cx0, yc, sign, c0, c1, c2, c3, c4);
}
void PlaneRowPortable(const PlaneSums& prefix, int w, int r, double n, const double* __restrict mean_xc, const double* __restrict var_x,
                      double my, double vy, float* __restrict o, float* __restrict sx, float* __restrict sy) {
  PlaneRowLoop(prefix, w, r, n, mean_xc, var_x, my, vy, o, sx, sy);
}
}  // namespace

PlaneKernels PlaneKernelsPortable() { return {AddDepthRowPortable, PlaneRowPortable}; }

const PlaneKernels& PickPlaneKernels() {
  using Pick = PlaneKernels (*)();
#if defined(__x86_64__)
  static constexpr IsaVariant<Pick> kVariants[] = {{Isa::kPortable, PlaneKernelsPortable},
                                                   {Isa::kAvx2, PlaneKernelsAvx2}};
#else
  static constexpr IsaVariant<Pick> kVariants[] = {{Isa::kPortable, PlaneKernelsPortable}};
#endif
  static const PlaneKernels kernels = PickVariant(kVariants)();
  return kernels;
}

}  // namespace inspection::depth_plane_kernel
