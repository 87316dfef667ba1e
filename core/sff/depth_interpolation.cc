// Depth interpolation of thesis 3.1.4 (eq. 3.23-3.34) for non-uniform z, and the peak confidence.
#include "core/sff/depth_interpolation.h"

#include <algorithm>
#include <cmath>

namespace inspection {

FocusPeak GaussianPeak(double z1, double z2, double z3, double f1, double f2, double f3) {
  FocusPeak p;
  p.z_um = z2;
  p.height = f2;
  if (!(f1 > 0.0 && f2 > 0.0 && f3 > 0.0)) return p;
  const double u1 = z1 - z2, u3 = z3 - z2;
  const double a = std::log(f2 / f1), b = std::log(f2 / f3);
  const double den = a * u3 - b * u1;
  // At a strict sampled maximum a, b >= 0 and u1, u3 have opposite signs, so den has the sign of
  // u3 and is non-zero unless the curve is flat over all three samples.
  if (!(std::abs(den) > 0.0) || !std::isfinite(den)) return p;
  const double mu = (a * u3 * u3 - b * u1 * u1) / (2.0 * den);
  const double var = u1 * u3 * (u1 - u3) / (2.0 * den);
  if (!std::isfinite(mu) || !(var > 0.0)) return p;
  // The vertex of a concave parabola through a sampled maximum lies between the outer samples.
  const double lo = std::min(u1, u3), hi = std::max(u1, u3);
  if (mu < lo || mu > hi) return p;
  p.z_um = z2 + mu;
  p.sigma_um = std::sqrt(var);
  p.height = f2 * std::exp(0.5 * mu * mu / var);  // eq. 3.34
  p.interpolated = true;
  return p;
}

namespace {

// Least-squares line f = slope * z + intercept through n >= 2 points.
bool FitLine(const double* z, const double* f, int n, double* slope, double* intercept) {
  double mz = 0, mf = 0;
  for (int i = 0; i < n; ++i) {
    mz += z[i];
    mf += f[i];
  }
  mz /= n;
  mf /= n;
  double szz = 0, szf = 0;
  for (int i = 0; i < n; ++i) {
    szz += (z[i] - mz) * (z[i] - mz);
    szf += (z[i] - mz) * (f[i] - mf);
  }
  if (!(szz > 0.0)) return false;
  *slope = szf / szz;
  *intercept = mf - *slope * mz;
  return true;
}

}  // namespace

FocusPeak LineFitPeak(const double* z, const double* f, int before, int after) {
  FocusPeak p;
  const int m = before, count = before + after + 1;
  p.z_um = z[m];
  p.height = f[m];
  if (before < 1 || after < 1) return p;
  double s1, c1, s2, c2;
  if (!FitLine(z, f, before + 1, &s1, &c1) || !FitLine(z + m, f + m, after + 1, &s2, &c2)) return p;
  if (!(std::abs(s1 - s2) > 0.0)) return p;
  const double zi = (c2 - c1) / (s1 - s2);  // d_i: intersection of the two lines
  if (!std::isfinite(zi)) return p;
  // d_c: sample other than d_max closest to d_i (eq. 3.27).
  int c = -1;
  for (int i = 0; i < count; ++i) {
    if (i == m) continue;
    if (c < 0 || std::abs(z[i] - zi) < std::abs(z[c] - zi)) c = i;
  }
  const double d1 = std::abs(zi - z[c]), d2 = std::abs(zi - z[m]), dsum = d1 + d2;  // eq. 3.27-3.28
  if (!(dsum > 0.0)) return p;
  p.z_um = (d2 / dsum) * z[c] + (d1 / dsum) * z[m];  // eq. 3.29
  p.interpolated = true;
  return p;
}

FocusPeak InterpolatePeak(DepthInterpolation method, const double* z, const double* f, int before, int after) {
  switch (method) {
    case DepthInterpolation::kMaximum:
      break;
    case DepthInterpolation::kLineFit:
      return LineFitPeak(z, f, before, after);
    case DepthInterpolation::kGaussian:
      if (before >= 1 && after >= 1) {
        const int m = before;
        return GaussianPeak(z[m - 1], z[m], z[m + 1], f[m - 1], f[m], f[m + 1]);
      }
      break;
    case DepthInterpolation::kDefocusParabola:
      if (before >= 1 && after >= 1) {
        const int m = before;
        FocusPeak p;
        p.z_um = DefocusParabolaPeakZ(z[m - 1], z[m], z[m + 1], f[m - 1], f[m], f[m + 1]);
        p.height = f[m];
        p.interpolated = p.z_um != z[m];
        return p;
      }
      break;
  }
  FocusPeak p;
  p.z_um = z[before];
  p.height = f[before];
  return p;
}

FocusPeak InterpolateFocusCurve(DepthInterpolation method, const std::vector<double>& z_um,
                                const std::vector<double>& f, int linefit_half_width) {
  const int n = int(std::min(z_um.size(), f.size()));
  if (n == 0) return {};
  const int m = int(std::max_element(f.begin(), f.begin() + n) - f.begin());
  const int half = method == DepthInterpolation::kLineFit ? std::max(linefit_half_width, 1) : 1;
  const int before = std::min(half, m), after = std::min(half, n - 1 - m);
  return InterpolatePeak(method, z_um.data() + (m - before), f.data() + (m - before), before, after);
}

}  // namespace inspection
