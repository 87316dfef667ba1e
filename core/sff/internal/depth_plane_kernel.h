// The row kernels of the local depth-plane fit (core/sff/depth_consistency.cc): the column sums
// of one depth row in or out of the window, and one output row (residual, slopes) from the
// prefix sums. Variants per instruction set (core/util/simd_dispatch.h): the loops below, written
// once, compiled portable (depth_plane_kernel_portable.cc) and for AVX2
// (depth_plane_kernel_avx2.cc, without FMA, so every product is rounded as in the portable code:
// the same sums to the last bit). These files are compiled with -fno-trapping-math (core/
// CMakeLists.txt), without which GCC keeps the NaN selects as branches and the loops scalar.
// Internal to core/sff.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/util/cpu_features.h"

namespace inspection::depth_plane_kernel {

// The window sums of FitLocalDepthPlanes, one plane array per quantity so that the row loops
// vectorise (with the NaN test as a select, not a branch).
struct PlaneSums {
  double* q[5];  // d, d^2, x d, y d, NaN count
};

// Adds (sign +1) or removes (-1) one depth row s (w pixels) to the column sums c0..c4;
// centre: the depth the sums are centred on, cx0 the image's centre column, yc the row's y
// relative to the image centre.
__attribute__((always_inline)) inline void AddDepthRowLoop(const float* __restrict s, int w, double centre, double cx0,
                                                           double yc, double sign, double* __restrict c0,
                                                           double* __restrict c1, double* __restrict c2,
                                                           double* __restrict c3, double* __restrict c4) {
  for (int x = 0; x < w; ++x) {
    // Both sides computed, then selected: no branch, so the loop vectorises (a NaN or inf
    // depth's d is computed and dropped).
    const double v = s[x], dv = v - centre;
    const bool finite = v - v == 0.0;  // std::isfinite (inf - inf and NaN - NaN are NaN)
    const double d = finite ? dv : 0.0;
    c0[x] += sign * d;
    c1[x] += sign * d * d;
    c2[x] += sign * (x - cx0) * d;
    c3[x] += sign * yc * d;
    c4[x] += finite ? 0.0 : sign;
  }
}

// One output row from the prefix sums over the extended row (lo at x, hi at x + 2r + 1);
// mean_xc: the window's mean x relative to the image centre, my the same for y; var_x, vy the
// windows' coordinate variances; n the window's pixel count. o: residual (+inf where the window
// holds a NaN), sx, sy: slopes (NaN there).
__attribute__((always_inline)) inline void PlaneRowLoop(const PlaneSums& prefix, int w, int r, double n,
                                                        const double* __restrict mean_xc,
                                                        const double* __restrict var_x, double my, double vy,
                                                        float* __restrict o, float* __restrict sx,
                                                        float* __restrict sy) {
  const double *p0 = prefix.q[0], *p1 = prefix.q[1], *p2 = prefix.q[2], *p3 = prefix.q[3], *p4 = prefix.q[4];
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  const int span = 2 * r + 1;
  for (int x = 0; x < w; ++x) {
    const bool holes = p4[x + span] - p4[x] > 0.5;
    const double m = (p0[x + span] - p0[x]) / n;
    const double var_d = (p1[x + span] - p1[x]) / n - m * m;
    const double cx = (p2[x + span] - p2[x]) / n - mean_xc[x] * m;
    const double cy = (p3[x + span] - p3[x]) / n - my * m;
    const double res = var_d - cx * cx / var_x[x] - cy * cy / vy;
    o[x] = holes ? inf : float(std::sqrt(std::max(res, 0.0)));
    sx[x] = holes ? nan : float(cx / var_x[x]);
    sy[x] = holes ? nan : float(cy / vy);
  }
}

struct PlaneKernels {
  void (*add_depth_row)(const float* s, int w, double centre, double cx0, double yc, double sign, double* c0,
                        double* c1, double* c2, double* c3, double* c4);
  void (*plane_row)(const PlaneSums& prefix, int w, int r, double n, const double* mean_xc, const double* var_x,
                    double my, double vy, float* o, float* sx, float* sy);
};

PlaneKernels PlaneKernelsPortable();
PlaneKernels PlaneKernelsAvx2();        // needs Isa::kAvx2 (x86-64 only)
const PlaneKernels& PickPlaneKernels();  // the variant for this CPU

}  // namespace inspection::depth_plane_kernel
