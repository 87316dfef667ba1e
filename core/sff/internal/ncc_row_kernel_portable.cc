// Portable variants of the NCC row and patch-sum kernels (core/sff/internal/ncc_row_kernel.h),
// and the run-time choice among the variants.
#include "core/sff/internal/ncc_row_kernel.h"

#include "core/util/simd_dispatch.h"

namespace inspection::ncc_kernel {

void NccRowFloatPortable(const float* sw, const float* sww, const float* swt, const float* tsum, const float* tinv,
                         int n, int count, float* c_out, float* p_out) {
  NccRowPortable(sw, sww, swt, tsum, tinv, n, 0, count, c_out, p_out);
}

namespace {
template <typename A>
void WindowSumsPortable(const A* v, A* out, int count, int k) {
  WindowSumsLoop(v, out, count, k);
}
template <typename A>
void SlidePortable(const A* wo, const A* wn, const float* to, const float* tn, A* vw, A* vww, A* vwt, int count) {
  SlidePatchSumsLoop(wo, wn, to, tn, vw, vww, vwt, count);
}
}  // namespace

template <typename A>
PatchSumKernels<A> PatchSumsPortable() {
  return {WindowSumsPortable<A>, SlidePortable<A>};
}

template <typename A>
const PatchSumKernels<A>& PickPatchSums() {
  using Pick = PatchSumKernels<A> (*)();
#if defined(__x86_64__)
  static constexpr IsaVariant<Pick> kVariants[] = {{Isa::kPortable, PatchSumsPortable<A>},
                                                   {Isa::kAvx2, PatchSumsAvx2<A>}};
#else
  static constexpr IsaVariant<Pick> kVariants[] = {{Isa::kPortable, PatchSumsPortable<A>}};
#endif
  static const PatchSumKernels<A> kernels = PickVariant(kVariants)();
  return kernels;
}

template PatchSumKernels<float> PatchSumsPortable<float>();
template PatchSumKernels<double> PatchSumsPortable<double>();
template const PatchSumKernels<float>& PickPatchSums<float>();
template const PatchSumKernels<double>& PickPatchSums<double>();

NccRowFloatFn PickNccRowFloat() {
#if defined(__x86_64__)
  static constexpr IsaVariant<NccRowFloatFn> kVariants[] = {{Isa::kPortable, NccRowFloatPortable},
                                                            {Isa::kAvx2, NccRowFloatAvx2}};
#else
  static constexpr IsaVariant<NccRowFloatFn> kVariants[] = {{Isa::kPortable, NccRowFloatPortable}};
#endif
  return PickVariant(kVariants);
}

}  // namespace inspection::ncc_kernel
