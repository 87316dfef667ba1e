// The run-time choice among a kernel's per-instruction-set variants (OpenCV's *.dispatch.cpp
// pattern): each kernel lists the variants it was compiled for, portable first, and takes the
// highest one this CPU runs. The variants are compiled in the room's internal/ folder, one file
// per instruction set (<kernel>_portable.cc, <kernel>_sse2.cc, <kernel>_avx2.cc, ...); tests
// call each variant directly and compare it with the portable one.
#pragma once

#include <cstddef>

#include "core/util/cpu_features.h"

namespace inspection {

template <typename Fn>
struct IsaVariant {
  Isa isa;
  Fn fn;
};

// The variant of the highest level the CPU has, among variants ordered by level with the
// portable one first; with use_simd false the portable one.
template <typename Fn, size_t N>
Fn PickVariant(const IsaVariant<Fn> (&variants)[N], bool use_simd = true) {
  static_assert(N > 0);
  Fn fn = variants[0].fn;
  if (!use_simd) return fn;
  for (size_t i = 1; i < N; ++i)
    if (CpuHas(variants[i].isa)) fn = variants[i].fn;
  return fn;
}

}  // namespace inspection
