// Tests of the CPU feature detection and the variant choice: against /proc/cpuinfo.
#include "core/util/cpu_features.h"

#include <gtest/gtest.h>

#include <string>

#include "core/util/simd_dispatch.h"
#include "tests/core/util/isa_check.h"

namespace inspection {
namespace {

using testing_isa::CpuInfoHas;

TEST(CpuFeaturesTest, AgreesWithProcCpuinfo) {
  ASSERT_FALSE(testing_isa::CpuInfoFlags().empty()) << "no flags line in /proc/cpuinfo";
  for (Isa isa : {Isa::kPortable, Isa::kSse2, Isa::kAvx2, Isa::kAvx512}) {
    EXPECT_EQ(CpuHas(isa), CpuInfoHas(isa)) << IsaName(isa);
  }
  EXPECT_EQ(CpuHasAvx2(), CpuInfoHas(Isa::kAvx2));
  EXPECT_EQ(CpuHasAvx512(), CpuInfoHas(Isa::kAvx512));
#if defined(__x86_64__)
  EXPECT_TRUE(CpuHas(Isa::kSse2));  // the x86-64 baseline
#endif
}

TEST(CpuFeaturesTest, LevelsAreNested) {
  EXPECT_TRUE(CpuHas(Isa::kPortable));
  if (CpuHas(Isa::kAvx512)) EXPECT_TRUE(CpuHas(Isa::kAvx2));
  if (CpuHas(Isa::kAvx2)) EXPECT_TRUE(CpuHas(Isa::kSse2));
  EXPECT_EQ(std::string(IsaName(Isa::kAvx512)), "avx512f");
}

int Portable() { return 0; }
int Sse2() { return 1; }
int Avx2() { return 2; }
int Avx512() { return 3; }

TEST(SimdDispatchTest, PicksTheHighestLevelTheCpuHasAndPortableWithoutSimd) {
  using Fn = int (*)();
  static constexpr IsaVariant<Fn> kAll[] = {
      {Isa::kPortable, Portable}, {Isa::kSse2, Sse2}, {Isa::kAvx2, Avx2}, {Isa::kAvx512, Avx512}};
  const int expected = CpuInfoHas(Isa::kAvx512) ? 3 : CpuInfoHas(Isa::kAvx2) ? 2 : CpuInfoHas(Isa::kSse2) ? 1 : 0;
  EXPECT_EQ(PickVariant(kAll)(), expected);
  EXPECT_EQ(PickVariant(kAll, /*use_simd=*/false)(), 0);
  static constexpr IsaVariant<Fn> kPortableOnly[] = {{Isa::kPortable, Portable}};
  EXPECT_EQ(PickVariant(kPortableOnly)(), 0);
  // A kernel without an AVX-512 variant gets its AVX2 one on an AVX-512 CPU.
  static constexpr IsaVariant<Fn> kUpToAvx2[] = {{Isa::kPortable, Portable}, {Isa::kAvx2, Avx2}};
  EXPECT_EQ(PickVariant(kUpToAvx2)(), CpuInfoHas(Isa::kAvx2) ? 2 : 0);
}

}  // namespace
}  // namespace inspection
