// CPU feature detection for the run-time choice of the SFF kernels (core/util/cpu_features.h).
#include "core/util/cpu_features.h"

namespace inspection {

bool CpuHasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

bool CpuHasAvx512() {
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("avx512f");
  return has;
}

}  // namespace inspection
