// Each instruction-set variant of the NCC row kernel against the portable one, on patch sums of
// random 8-bit patches and on edge cases (flat patches, perfect correlation and anticorrelation,
// rows shorter than and around the AVX2 step of 8). The AVX2 variant takes the square root of the
// variance in float, the portable one in double: C and C sigma_w agree to 4 float ulp (relative
// 5e-7), the flat-patch decision exactly.
#include "core/sff/internal/ncc_row_kernel.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "tests/core/util/isa_check.h"

namespace inspection::ncc_kernel {
namespace {

NccRowFloatFn VariantOf(Isa isa) { return isa == Isa::kAvx2 ? NccRowFloatAvx2 : NccRowFloatPortable; }

struct RowSums {
  std::vector<float> sw, sww, swt, tsum, tinv;
};

// count pixels' sums over n-pixel patches; kind 0 random, 1 flat frame patch, 2 t = w - mean,
// 3 t = mean - w.
RowSums MakeRow(int count, int n, std::mt19937& rng) {
  RowSums r;
  std::uniform_int_distribution<int> grey(0, 255), kind(0, 5);
  std::normal_distribution<float> noise(0.f, 20.f);
  for (int x = 0; x < count; ++x) {
    const int k = kind(rng) % 4;
    std::vector<float> w(static_cast<size_t>(n)), t(static_cast<size_t>(n));
    const int flat = grey(rng);
    for (int i = 0; i < n; ++i) w[size_t(i)] = float(k == 1 ? flat : grey(rng));
    double mean = 0;
    for (float v : w) mean += v;
    mean /= n;
    for (int i = 0; i < n; ++i)
      t[size_t(i)] = k == 2 ? float(w[size_t(i)] - mean) : k == 3 ? float(mean - w[size_t(i)]) : noise(rng);
    float a = 0, b = 0, c = 0, st = 0, stt = 0;
    for (int i = 0; i < n; ++i) {
      a += w[size_t(i)], b += w[size_t(i)] * w[size_t(i)], c += w[size_t(i)] * t[size_t(i)];
      st += t[size_t(i)], stt += t[size_t(i)] * t[size_t(i)];
    }
    const float var_t = float(n) * stt - st * st;
    r.sw.push_back(a), r.sww.push_back(b), r.swt.push_back(c), r.tsum.push_back(st);
    r.tinv.push_back(var_t > 0 ? 1.0f / std::sqrt(var_t) : 0.0f);
  }
  return r;
}

TEST(NccRowKernelTest, EveryIsaVariantMatchesPortable) {
  const std::vector<Isa> isas = testing_isa::IsasToCheck({Isa::kAvx2});
  std::mt19937 rng(5);
  int flat_seen = 0, clamped_seen = 0;
  for (Isa isa : isas) {
    for (int n : {9, 49, 225}) {
      for (int count : {0, 1, 7, 8, 9, 16, 23, 200}) {
        const RowSums r = MakeRow(count, n, rng);
        std::vector<float> cp(size_t(count) + 1, -9.f), pp = cp, cv = cp, pv = cp;
        NccRowFloatPortable(r.sw.data(), r.sww.data(), r.swt.data(), r.tsum.data(), r.tinv.data(), n, count,
                            cp.data(), pp.data());
        VariantOf(isa)(r.sw.data(), r.sww.data(), r.swt.data(), r.tsum.data(), r.tinv.data(), n, count, cv.data(),
                       pv.data());
        for (int x = 0; x < count; ++x) {
          const std::string what = std::string(IsaName(isa)) + " n " + std::to_string(n) + " x " + std::to_string(x);
          EXPECT_EQ(cv[size_t(x)] == 0.f, cp[size_t(x)] == 0.f) << what;  // flat patch decided alike
          EXPECT_NEAR(cv[size_t(x)], cp[size_t(x)], 5e-7f * std::abs(cp[size_t(x)]) + 1e-30f) << what;
          EXPECT_NEAR(pv[size_t(x)], pp[size_t(x)], 5e-7f * std::abs(pp[size_t(x)]) + 1e-30f) << what;
          EXPECT_LE(std::abs(cv[size_t(x)]), 1.0f) << what;
          flat_seen += cp[size_t(x)] == 0.f;
          clamped_seen += std::abs(cp[size_t(x)]) > 0.9999f;
        }
        EXPECT_EQ(cv[size_t(count)], -9.f) << "wrote past the row";
        EXPECT_EQ(pv[size_t(count)], -9.f) << "wrote past the row";
      }
    }
  }
  if (!isas.empty()) {
    EXPECT_GT(flat_seen, 0);  // the edge cases were generated
    EXPECT_GT(clamped_seen, 0);
  }
}

// The patch-sum loops: element-wise sums in the same order in every variant, so exactly equal.
template <typename A>
void CheckPatchSums(Isa isa, std::mt19937& rng) {
  const PatchSumKernels<A> port = PatchSumsPortable<A>();
  const PatchSumKernels<A> simd = isa == Isa::kAvx2 ? PatchSumsAvx2<A>() : port;
  std::uniform_real_distribution<float> value(-300.f, 300.f);
  for (int count : {0, 1, 3, 4, 7, 8, 9, 16, 33, 257}) {
    for (int k : {1, 3, 7, 15}) {
      std::vector<A> v(static_cast<size_t>(count + k)), a(static_cast<size_t>(count) + 1, A(-9)), b = a;
      for (auto& x : v) x = A(value(rng)) / A(7);
      port.window_sums(v.data(), a.data(), count, k);
      simd.window_sums(v.data(), b.data(), count, k);
      EXPECT_EQ(a, b) << IsaName(isa) << " window sums count " << count << " k " << k;
    }
    std::vector<A> wo(static_cast<size_t>(count)), wn(static_cast<size_t>(count));
    std::vector<float> to(static_cast<size_t>(count)), tn(static_cast<size_t>(count));
    for (int c = 0; c < count; ++c) wo[c] = A(value(rng)), wn[c] = A(value(rng)), to[c] = value(rng), tn[c] = value(rng);
    std::vector<A> vw(size_t(count), A(1.5)), vww = vw, vwt = vw, vw2 = vw, vww2 = vw, vwt2 = vw;
    port.slide(wo.data(), wn.data(), to.data(), tn.data(), vw.data(), vww.data(), vwt.data(), count);
    simd.slide(wo.data(), wn.data(), to.data(), tn.data(), vw2.data(), vww2.data(), vwt2.data(), count);
    EXPECT_EQ(vw, vw2) << IsaName(isa) << " slide count " << count;
    EXPECT_EQ(vww, vww2) << IsaName(isa) << " slide count " << count;
    EXPECT_EQ(vwt, vwt2) << IsaName(isa) << " slide count " << count;
  }
}

TEST(NccRowKernelTest, PatchSumVariantsMatchPortableExactly) {
  std::mt19937 rng(13);
  for (Isa isa : testing_isa::IsasToCheck({Isa::kAvx2})) {
    CheckPatchSums<float>(isa, rng);
    CheckPatchSums<double>(isa, rng);
  }
  // Analytic: window sums of 1, 2, 3, 4, 5 with k = 3.
  const std::vector<float> v = {1, 2, 3, 4, 5};
  std::vector<float> out(3);
  PickPatchSums<float>().window_sums(v.data(), out.data(), 3, 3);
  EXPECT_EQ(out, (std::vector<float>{6, 9, 12}));
}

TEST(NccRowKernelTest, PortableOnAnalyticCases) {
  // Patch w = {0, 255} x 4 + {0}: t = w - mean gives C = 1; a flat patch gives 0.
  std::mt19937 rng(11);
  const RowSums r = MakeRow(64, 9, rng);
  std::vector<float> c(64), p(64);
  NccRowFloatPortable(r.sw.data(), r.sww.data(), r.swt.data(), r.tsum.data(), r.tinv.data(), 9, 64, c.data(),
                      p.data());
  for (int x = 0; x < 64; ++x) {
    const double var_w = 9.0 * r.sww[size_t(x)] - double(r.sw[size_t(x)]) * r.sw[size_t(x)];
    if (var_w == 0) EXPECT_EQ(c[size_t(x)], 0.f) << x;
  }
  EXPECT_EQ(PickNccRowFloat(), testing_isa::CpuInfoHas(Isa::kAvx2) ? NccRowFloatAvx2 : NccRowFloatPortable);
}

}  // namespace
}  // namespace inspection::ncc_kernel
