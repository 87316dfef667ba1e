// Which instruction sets the CPU running this process has, detected once. Every hand-vectorised
// kernel is compiled per instruction set beside its portable code (function target attributes,
// not per-file flags, so one binary runs on any x86-64 CPU) and picked at run time from these
// (core/util/simd_dispatch.h).
#pragma once

namespace inspection {

// Instruction-set levels, each including the ones before it (x86-64: SSE2 is the baseline).
enum class Isa {
  kPortable,  // plain C++ (what the compiler makes of it for the baseline)
  kSse2,
  kAvx2,    // AVX2 with FMA (x86-64-v3 has both; no CPU has shipped AVX2 without FMA)
  kAvx512,  // AVX-512F, and the AVX2 level (the AVX-512 kernels run beside the AVX2 ones)
};

// Lower case, as /proc/cpuinfo spells the flag: "portable", "sse2", "avx2", "avx512f".
const char* IsaName(Isa isa);

// True when this CPU (and the build's target, x86-64) runs code of that level.
bool CpuHas(Isa isa);

inline bool CpuHasAvx2() { return CpuHas(Isa::kAvx2); }
inline bool CpuHasAvx512() { return CpuHas(Isa::kAvx512); }

}  // namespace inspection
