// CPU feature detection for the run-time choice of the kernels (core/util/cpu_features.h).
#include "core/util/cpu_features.h"

namespace inspection {

namespace {

struct Features {
  bool sse2 = false, avx2 = false, avx512 = false;
  Features() {
#if defined(__x86_64__) || defined(__i386__)
    sse2 = __builtin_cpu_supports("sse2");
    avx2 = sse2 && __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    avx512 = avx2 && __builtin_cpu_supports("avx512f");
#endif
  }
};

}  // namespace

const char* IsaName(Isa isa) {
  switch (isa) {
    case Isa::kPortable:
      return "portable";
    case Isa::kSse2:
      return "sse2";
    case Isa::kAvx2:
      return "avx2";
    case Isa::kAvx512:
      return "avx512f";
  }
  return "?";
}

bool CpuHas(Isa isa) {
  static const Features f;
  switch (isa) {
    case Isa::kPortable:
      return true;
    case Isa::kSse2:
      return f.sse2;
    case Isa::kAvx2:
      return f.avx2;
    case Isa::kAvx512:
      return f.avx512;
  }
  return false;
}

}  // namespace inspection
