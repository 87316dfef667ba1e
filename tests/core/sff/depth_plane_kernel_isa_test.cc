// Each instruction-set variant of the depth-plane row kernels against the portable one: the
// same operations in the same order (AVX2 without FMA), so every output is bitwise equal,
// including NaN / +inf depths (the selects) and rows shorter than and around the vector step.
// Then the kernels' sums against a direct per-pixel plane fit, so the portable one is right too.
#include "core/sff/internal/depth_plane_kernel.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "core/sff/depth_consistency.h"
#include "tests/core/util/isa_check.h"

namespace inspection::depth_plane_kernel {
namespace {

PlaneKernels VariantOf(Isa isa) { return isa == Isa::kAvx2 ? PlaneKernelsAvx2() : PlaneKernelsPortable(); }

template <typename T>
bool SameBits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

// A depth row of w pixels: a noisy slope with a NaN, +inf or -inf in about 1 of 8 pixels.
std::vector<float> DepthRow(int w, std::mt19937& rng) {
  std::uniform_real_distribution<float> depth(-40.f, 60.f);
  std::uniform_int_distribution<int> kind(0, 23);
  std::vector<float> row(size_t(w) + 1, 12345.f);  // one guard pixel the kernels must not read into output
  for (int x = 0; x < w; ++x) {
    const int k = kind(rng);
    row[size_t(x)] = k == 0   ? std::numeric_limits<float>::quiet_NaN()
                     : k == 1 ? std::numeric_limits<float>::infinity()
                     : k == 2 ? -std::numeric_limits<float>::infinity()
                              : 0.25f * x + depth(rng);
  }
  return row;
}

TEST(DepthPlaneKernelIsaTest, EveryIsaVariantMatchesPortableBitwise) {
  const std::vector<Isa> isas = testing_isa::IsasToCheck({Isa::kAvx2});
  std::mt19937 rng(17);
  int holes_seen = 0;
  for (Isa isa : isas) {
    const PlaneKernels port = PlaneKernelsPortable(), simd = VariantOf(isa);
    for (int w : {1, 2, 3, 4, 5, 7, 8, 9, 16, 31, 67, 640}) {
      for (int r : {1, 3, 7}) {
        const std::string what = std::string(IsaName(isa)) + " w " + std::to_string(w) + " r " + std::to_string(r);
        // Column sums: add three rows, remove one, from the same non-zero start.
        std::vector<std::vector<double>> a(5, std::vector<double>(size_t(w), 0.5)), b = a;
        for (int step = 0; step < 4; ++step) {
          const std::vector<float> row = DepthRow(w, rng);
          const double sign = step == 3 ? -1.0 : 1.0, yc = step - 1.5;
          port.add_depth_row(row.data(), w, 7.25, 0.5 * (w - 1), yc, sign, a[0].data(), a[1].data(), a[2].data(),
                             a[3].data(), a[4].data());
          simd.add_depth_row(row.data(), w, 7.25, 0.5 * (w - 1), yc, sign, b[0].data(), b[1].data(), b[2].data(),
                             b[3].data(), b[4].data());
        }
        for (int q = 0; q < 5; ++q) {
          EXPECT_TRUE(SameBits(a[size_t(q)], b[size_t(q)])) << what << " column sum " << q;
        }
        // An output row from prefix sums of those columns over the extended row.
        const int span = 2 * r + 1, ext = w + span;
        std::vector<std::vector<double>> prefix(5, std::vector<double>(size_t(ext), 0.0));
        for (int q = 0; q < 5; ++q)
          for (int i = 0; i + 1 < ext; ++i)
            prefix[size_t(q)][size_t(i) + 1] = prefix[size_t(q)][size_t(i)] + a[size_t(q)][size_t(i % w)];
        PlaneSums p;
        for (int q = 0; q < 5; ++q) p.q[q] = prefix[size_t(q)].data();
        std::vector<double> mean_xc(static_cast<size_t>(w)), var_x(static_cast<size_t>(w));
        for (int x = 0; x < w; ++x) mean_xc[size_t(x)] = 0.1 * x - 3, var_x[size_t(x)] = r * (r + 1) / 3.0 + 0.01 * x;
        const double n = double(span) * span;
        std::vector<float> o1(size_t(w) + 1, -9.f), sx1 = o1, sy1 = o1, o2 = o1, sx2 = o1, sy2 = o1;
        port.plane_row(p, w, r, n, mean_xc.data(), var_x.data(), 0.75, 4.5, o1.data(), sx1.data(), sy1.data());
        simd.plane_row(p, w, r, n, mean_xc.data(), var_x.data(), 0.75, 4.5, o2.data(), sx2.data(), sy2.data());
        EXPECT_TRUE(SameBits(o1, o2)) << what << " residual";
        EXPECT_TRUE(SameBits(sx1, sx2)) << what << " slope x";
        EXPECT_TRUE(SameBits(sy1, sy2)) << what << " slope y";
        EXPECT_EQ(o2[size_t(w)], -9.f) << what << ": wrote past the row";
        for (int x = 0; x < w; ++x) holes_seen += std::isinf(o1[size_t(x)]);
      }
    }
  }
  if (!isas.empty()) {
    EXPECT_GT(holes_seen, 0) << "the NaN / inf select was exercised";
  }
}

// The whole fit through the picked kernels against a per-pixel least-squares plane: the
// residual of a plane plus a bump, computed directly (windows inside the image).
TEST(DepthPlaneKernelIsaTest, PickedKernelsGiveTheDirectPlaneFit) {
  EXPECT_EQ(PickPlaneKernels().plane_row, (testing_isa::CpuInfoHas(Isa::kAvx2) ? PlaneKernelsAvx2()
                                                                               : PlaneKernelsPortable())
                                              .plane_row);
  const int w = 41, h = 23, r = 3;
  cv::Mat depth(h, w, CV_32FC1);
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0.f, 0.5f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) depth.at<float>(y, x) = 2.f + 0.3f * x - 0.2f * y + noise(rng);
  depth.at<float>(11, 20) = std::numeric_limits<float>::quiet_NaN();
  LocalDepthPlane plane;
  ASSERT_TRUE(FitLocalDepthPlanes(depth, r, &plane).ok());
  int checked = 0;
  for (int y = r; y < h - r; ++y) {
    for (int x = r; x < w - r; ++x) {
      bool hole = false;
      double sd = 0, sdd = 0, sxd = 0, syd = 0, sx = 0, sy = 0, sxx = 0, syy = 0;
      for (int j = -r; j <= r; ++j) {
        for (int i = -r; i <= r; ++i) {
          const double d = depth.at<float>(y + j, x + i);
          hole = hole || std::isnan(d);
          sd += d, sdd += d * d, sxd += i * d, syd += j * d, sx += i, sy += j, sxx += i * i, syy += j * j;
        }
      }
      const double n = (2 * r + 1) * (2 * r + 1), m = sd / n;
      const double vx = sxx / n - (sx / n) * (sx / n), vy = syy / n - (sy / n) * (sy / n);
      const double cx = sxd / n - (sx / n) * m, cy = syd / n - (sy / n) * m;
      const double res = std::sqrt(std::max(sdd / n - m * m - cx * cx / vx - cy * cy / vy, 0.0));
      if (hole) {
        EXPECT_TRUE(std::isinf(plane.residual_um.at<float>(y, x))) << x << "," << y;
        EXPECT_TRUE(std::isnan(plane.slope_x.at<float>(y, x))) << x << "," << y;
        continue;
      }
      EXPECT_NEAR(plane.residual_um.at<float>(y, x), res, 1e-4) << x << "," << y;
      EXPECT_NEAR(plane.slope_x.at<float>(y, x), cx / vx, 1e-4) << x << "," << y;
      EXPECT_NEAR(plane.slope_y.at<float>(y, x), cy / vy, 1e-4) << x << "," << y;
      ++checked;
    }
  }
  EXPECT_GT(checked, 400);
}

}  // namespace
}  // namespace inspection::depth_plane_kernel
