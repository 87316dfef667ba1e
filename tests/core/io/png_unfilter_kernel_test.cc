// Each instruction-set variant of the PNG Sub / Up unfilters against the portable one: the same
// bytes for random rows of every length around the 16-byte vector, separately and in place (out
// one filter byte before in, as the decoder lays rows out), and against the spec's definition.
#include "core/io/internal/png_unfilter_kernel.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "tests/core/util/isa_check.h"

namespace inspection::png_internal {
namespace {

TEST(PngUnfilterKernelTest, EveryIsaVariantMatchesPortable) {
  const std::vector<Isa> isas = testing_isa::IsasToCheck({Isa::kSse2});
  const PngUnfilterKernels port = PngUnfilterPortable();
  std::mt19937 rng(9);
  std::uniform_int_distribution<int> byte(0, 255);
  for (Isa isa : isas) {
    ASSERT_EQ(isa, Isa::kSse2);
    const PngUnfilterKernels simd = PngUnfilterSse2();
    for (size_t stride : {1, 2, 3, 15, 16, 17, 31, 32, 33, 47, 100, 3200}) {
      std::vector<unsigned char> in(stride), up(stride);
      for (auto& v : in) v = uint8_t(byte(rng));
      for (auto& v : up) v = uint8_t(byte(rng));
      const std::string what = std::string(IsaName(isa)) + " stride " + std::to_string(stride);
      for (int kind = 0; kind < 3; ++kind) {
        if (kind == 1 && stride % 2 != 0) continue;  // bpp 2: whole pixels
        std::vector<unsigned char> a(stride), b(stride);
        auto run = [&](const PngUnfilterKernels& k, const unsigned char* src, unsigned char* dst) {
          if (kind == 0) k.sub1(src, dst, stride);
          if (kind == 1) k.sub2(src, dst, stride);
          if (kind == 2) k.up(src, up.data(), dst, stride);
        };
        run(port, in.data(), a.data());
        run(simd, in.data(), b.data());
        EXPECT_EQ(a, b) << what << " kind " << kind;
        // In place: the filtered row one byte after where its result goes.
        std::vector<unsigned char> buf(stride + 1);
        std::memcpy(buf.data() + 1, in.data(), stride);
        run(simd, buf.data() + 1, buf.data());
        EXPECT_EQ(std::vector<unsigned char>(buf.begin(), buf.begin() + long(stride)), a) << what << " in place " << kind;
      }
    }
  }
}

TEST(PngUnfilterKernelTest, PortableFollowsTheSpec) {
  // Sub: Recon(x) = Filt(x) + Recon(x - bpp); Up: Recon(x) = Filt(x) + Prior(x), modulo 256.
  const std::vector<unsigned char> in = {10, 250, 7, 200, 1, 2};
  const std::vector<unsigned char> up = {255, 1, 2, 3, 250, 9};
  std::vector<unsigned char> out(6);
  const PngUnfilterKernels& k = PickPngUnfilter();
  k.sub1(in.data(), out.data(), 6);
  EXPECT_EQ(out, (std::vector<unsigned char>{10, 4, 11, 211, 212, 214}));
  k.sub2(in.data(), out.data(), 6);
  EXPECT_EQ(out, (std::vector<unsigned char>{10, 250, 17, 194, 18, 196}));
  k.up(in.data(), up.data(), out.data(), 6);
  EXPECT_EQ(out, (std::vector<unsigned char>{9, 251, 9, 203, 251, 11}));
}

}  // namespace
}  // namespace inspection::png_internal
