// Portable variant of the float-sum NCC row (core/sff/internal/ncc_row_kernel.h), and the
// run-time choice among the variants.
#include "core/sff/internal/ncc_row_kernel.h"

#include "core/util/simd_dispatch.h"

namespace inspection::ncc_kernel {

void NccRowFloatPortable(const float* sw, const float* sww, const float* swt, const float* tsum, const float* tinv,
                         int n, int count, float* c_out, float* p_out) {
  NccRowPortable(sw, sww, swt, tsum, tinv, n, 0, count, c_out, p_out);
}

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
