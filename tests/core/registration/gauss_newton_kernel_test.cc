// Each instruction-set variant of the Gauss-Newton row sums against the portable one, on random
// rows and on run lengths around the AVX2 block of 8 pixels. The AVX2 variant sums blocks in
// float lanes: its sums match the portable double sums to float rounding (stated below); runs
// shorter than a block, and the pixel count, match exactly.
#include "core/registration/internal/gauss_newton_kernel.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "tests/core/util/isa_check.h"

namespace inspection::registration_internal {
namespace {

GaussNewtonRowFn VariantOf(Isa isa) { return isa == Isa::kAvx2 ? GaussNewtonRowAvx2 : GaussNewtonRowPortable; }

struct Rows {
  std::vector<float> up, mid, dn, ref;
  explicit Rows(int w, std::mt19937& rng) : up(size_t(w)), mid(size_t(w)), dn(size_t(w)), ref(size_t(w)) {
    std::uniform_real_distribution<float> grey(0.f, 1.f);
    for (int x = 0; x < w; ++x) up[x] = grey(rng), mid[x] = grey(rng), dn[x] = grey(rng), ref[x] = grey(rng);
  }
};

// Every sum's difference within `rel` of the sum of the absolute terms' bound (the pixels times
// the largest term, |j| <= 2.5 and |r| <= 2.5 here): float lanes keep ~7 digits per addition.
void ExpectNear(const NormalSums& a, const NormalSums& b, double bound, const std::string& what) {
  EXPECT_EQ(a.n, b.n) << what;
  for (int i = 0; i < 6; ++i) {
    EXPECT_NEAR(a.gs[i], b.gs[i], bound) << what << " gs " << i;
    for (int k = i; k < 6; ++k) EXPECT_NEAR(a.hs[i][k], b.hs[i][k], bound) << what << " hs " << i << k;
  }
  for (int i = 0; i < 5; ++i) EXPECT_NEAR(a.s5[i], b.s5[i], bound) << what << " s5 " << i;
}

void ExpectEqual(const NormalSums& a, const NormalSums& b, const std::string& what) {
  EXPECT_EQ(a.n, b.n) << what;
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(a.gs[i], b.gs[i]) << what << " gs " << i;
    for (int k = i; k < 6; ++k) EXPECT_EQ(a.hs[i][k], b.hs[i][k]) << what << " hs " << i << k;
  }
  for (int i = 0; i < 5; ++i) EXPECT_EQ(a.s5[i], b.s5[i]) << what << " s5 " << i;
}

TEST(GaussNewtonKernelTest, EveryIsaVariantMatchesPortable) {
  const std::vector<Isa> isas = testing_isa::IsasToCheck({Isa::kAvx2});
  std::mt19937 rng(20261201);
  for (Isa isa : isas) {
    const GaussNewtonRowFn simd = VariantOf(isa);
    for (int len : {0, 1, 7, 8, 9, 15, 16, 17, 31, 33, 100, 1598}) {
      const int w = len + 2;
      Rows r(w, rng);
      for (const double gain : {1.0, 0.83, 1.27}) {
        const GaussNewtonRow row{r.mid.data(), r.up.data(), r.dn.data(), r.ref.data(), 1, len, 0.5 * (w - 1),
                                 0.5 * w, 0.31, gain, -0.05};
        NormalSums port, vec;
        // Non-zero starting sums: the variants add to what the earlier rows left.
        port.hs[0][0] = vec.hs[0][0] = 3.5, port.s5[2] = vec.s5[2] = -1.25, port.n = vec.n = 11;
        GaussNewtonRowPortable(row, &port);
        simd(row, &vec);
        const std::string what = std::string(IsaName(isa)) + " len " + std::to_string(len);
        ASSERT_EQ(port.n, 11 + len) << what;
        if (len < 8)
          ExpectEqual(vec, port, what);  // no whole block: the portable loop alone
        else
          ExpectNear(vec, port, 1e-6 * 6.25 * len, what);
      }
    }
  }
}

TEST(GaussNewtonKernelTest, EmptyRunAddsNothing) {
  std::mt19937 rng(7);
  Rows r(20, rng);
  for (GaussNewtonRowFn fn : {GaussNewtonRowPortable, PickGaussNewtonRow(true), PickGaussNewtonRow(false)}) {
    const GaussNewtonRow row{r.mid.data(), r.up.data(), r.dn.data(), r.ref.data(), 10, 9, 9.5, 10.0, 0.0, 1.0, 0.0};
    NormalSums s;
    s.gs[3] = 2.0;
    fn(row, &s);
    EXPECT_EQ(s.n, 0);
    EXPECT_EQ(s.gs[3], 2.0);
    EXPECT_EQ(s.hs[0][0], 0.0);
  }
  EXPECT_EQ(PickGaussNewtonRow(false), GaussNewtonRowPortable);
  EXPECT_EQ(PickGaussNewtonRow(true), testing_isa::CpuInfoHas(Isa::kAvx2) ? GaussNewtonRowAvx2 : GaussNewtonRowPortable);
}

// A perfectly matched row (frame = reference, gain 1, offset 0): zero residual, so the gradient
// sums J^T r are 0 in every variant, and the correlation sums sw = st, sww = stt = swt.
TEST(GaussNewtonKernelTest, MatchedRowHasZeroGradientInEveryVariant) {
  std::mt19937 rng(3);
  Rows r(66, rng);
  r.ref = r.mid;
  std::vector<GaussNewtonRowFn> fns{GaussNewtonRowPortable};
  for (Isa isa : testing_isa::IsasToCheck({Isa::kAvx2})) fns.push_back(VariantOf(isa));
  for (GaussNewtonRowFn fn : fns) {
    const GaussNewtonRow row{r.mid.data(), r.up.data(), r.dn.data(), r.ref.data(), 1, 64, 32.5, 33.0, -0.2, 1.0, 0.0};
    NormalSums s;
    fn(row, &s);
    for (int i = 0; i < 6; ++i) EXPECT_EQ(s.gs[i], 0.0) << i;
    EXPECT_NEAR(s.s5[0], s.s5[1], 1e-9);
    EXPECT_NEAR(s.s5[2], s.s5[4], 1e-9);
    EXPECT_NEAR(s.hs[5][5], 64.0, 0.0);
  }
}

}  // namespace
}  // namespace inspection::registration_internal
