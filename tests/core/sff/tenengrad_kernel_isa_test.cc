// The Tenengrad kernels' AVX2 and AVX-512 variants are checked against the portable ones by the
// engine's bit-identity tests (sff_engine_test.cc: CompactStreamingKernelsAgree,
// PortableKernelsGiveTheSameResult, ...). Those compare whatever the state chose; this makes
// sure the state chooses every variant this CPU has, so that they do check it.
#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include "core/sff/sff_state.h"
#include "tests/core/util/isa_check.h"

namespace inspection {
namespace {

TEST(TenengradKernelIsaTest, StateRunsEveryVariantTheCpuHas) {
  const std::vector<Isa> isas = testing_isa::IsasToCheck({Isa::kAvx2, Isa::kAvx512});
  auto has = [&](Isa isa) { return std::find(isas.begin(), isas.end(), isa) != isas.end(); };
  sff_internal::CompactState all, no512, portable;
  all.Allocate(32, 4, /*use_simd=*/true, /*use_avx512=*/true);
  no512.Allocate(32, 4, true, false);
  portable.Allocate(32, 4, false, true);
  EXPECT_EQ(all.avx2, has(Isa::kAvx2));
  EXPECT_EQ(all.avx512, has(Isa::kAvx512));
  EXPECT_EQ(no512.avx2, has(Isa::kAvx2));
  EXPECT_FALSE(no512.avx512);
  EXPECT_FALSE(portable.avx2);
  EXPECT_FALSE(portable.avx512);
}

}  // namespace
}  // namespace inspection
