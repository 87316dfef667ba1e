// Each instruction-set variant of the frame statistics' row sums against the portable one: exact
// equality (integer sums) on random runs, lengths around the vector widths, the longest run, and
// all-dark / all-saturated rows with and without an underexposure threshold.
#include "core/io/internal/frame_stats_kernel.h"

#include <gtest/gtest.h>

#include <random>
#include <string>
#include <vector>

#include "tests/core/util/isa_check.h"

namespace inspection::frame_stats_internal {
namespace {

void ExpectSame(const RunSums& a, const RunSums& b, const std::string& what) {
  EXPECT_EQ(a.sum, b.sum) << what;
  EXPECT_EQ(a.sum2, b.sum2) << what;
  EXPECT_EQ(a.saturated, b.saturated) << what;
  EXPECT_EQ(a.under, b.under) << what;
}

const std::vector<int> kLengths = {0, 1, 15, 16, 17, 31, 32, 33, 63, 100, 1600, kRun};

TEST(FrameStatsKernelTest, Sse2EightBitMatchesPortable) {
  const std::vector<Isa> isas = testing_isa::IsasToCheck({Isa::kSse2});
  std::mt19937 rng(1);
  std::uniform_int_distribution<int> byte(0, 255);
  for (Isa isa : isas) {
    ASSERT_EQ(isa, Isa::kSse2);
    for (int n : kLengths) {
      for (int fill : {-1, 0, 255, 4}) {
        std::vector<uint8_t> p(size_t(n) + 1);
        for (auto& v : p) v = uint8_t(fill < 0 ? byte(rng) : fill);
        for (uint8_t under : {uint8_t(0), uint8_t(1), uint8_t(5), uint8_t(255)}) {
          const std::string what = "n " + std::to_string(n) + " fill " + std::to_string(fill) + " under " +
                                   std::to_string(under);
          ExpectSame(SumRun8Sse2(p.data(), n, under), SumRun8Portable(p.data(), n, under), what);
        }
      }
    }
  }
  // The analytic case: 255 in every pixel of the longest run.
  std::vector<uint8_t> full(size_t(kRun), 255);
  const RunSums s = PickSumRun8()(full.data(), kRun, 5);
  EXPECT_EQ(s.sum, uint32_t(255) * kRun);
  EXPECT_EQ(s.sum2, uint64_t(255 * 255) * kRun);
  EXPECT_EQ(s.saturated, uint32_t(kRun));
  EXPECT_EQ(s.under, 0u);
}

TEST(FrameStatsKernelTest, Avx2SixteenBitMatchesPortable) {
  const std::vector<Isa> isas = testing_isa::IsasToCheck({Isa::kAvx2});
  std::mt19937 rng(2);
  std::uniform_int_distribution<int> word(0, 65535);
  for (Isa isa : isas) {
    ASSERT_EQ(isa, Isa::kAvx2);
    for (int n : kLengths) {
      for (int fill : {-1, 0, 65535, 4095}) {
        std::vector<uint16_t> p(size_t(n) + 1);
        for (auto& v : p) v = uint16_t(fill < 0 ? word(rng) : fill);
        for (auto [sat, under] : {std::pair<uint16_t, uint16_t>{65535, 1310}, {4095, 81}, {1023, 0}}) {
          const std::string what = "n " + std::to_string(n) + " fill " + std::to_string(fill) + " sat " +
                                   std::to_string(sat);
          ExpectSame(SumRun16Avx2(p.data(), n, sat, under), SumRun16Portable(p.data(), n, sat, under), what);
        }
      }
    }
  }
  std::vector<uint16_t> full(size_t(kRun), 65535);
  const RunSums s = PickSumRun16()(full.data(), kRun, 65535, 1310);
  EXPECT_EQ(s.sum, uint32_t(65535) * uint32_t(kRun));
  EXPECT_EQ(s.sum2, uint64_t(65535) * 65535 * kRun);
  EXPECT_EQ(s.saturated, uint32_t(kRun));
}

}  // namespace
}  // namespace inspection::frame_stats_internal
