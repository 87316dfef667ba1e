// ISO 25178-600 characteristics from material measures (see verification.h).
#include "core/metrology/verification.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace inspection {
namespace {

Status CheckMap(const cv::Mat& m, const char* name) {
  if (m.empty() || m.type() != CV_32FC1) return Status::InvalidArgument(std::string(name) + " must be a CV_32FC1 depth map");
  return Status::Ok();
}

// Least-squares plane z = c0 + c1 x + c2 y over the finite pixels (x, y in px).
bool FitPlane(const cv::Mat& z, double c[3]) {
  double s[3][3] = {}, r[3] = {};
  for (int y = 0; y < z.rows; ++y) {
    const float* row = z.ptr<float>(y);
    for (int x = 0; x < z.cols; ++x) {
      if (!std::isfinite(row[x])) continue;
      const double v[3] = {1.0, double(x), double(y)};
      for (int i = 0; i < 3; ++i) {
        r[i] += v[i] * row[x];
        for (int j = 0; j < 3; ++j) s[i][j] += v[i] * v[j];
      }
    }
  }
  cv::Matx33d a(s[0][0], s[0][1], s[0][2], s[1][0], s[1][1], s[1][2], s[2][0], s[2][1], s[2][2]);
  cv::Vec3d sol;
  if (!cv::solve(a, cv::Vec3d(r[0], r[1], r[2]), sol, cv::DECOMP_SVD)) return false;
  for (int i = 0; i < 3; ++i) c[i] = sol[i];
  return true;
}

cv::Mat Levelled(const cv::Mat& z) {
  double c[3] = {0, 0, 0};
  FitPlane(z, c);
  cv::Mat out = z.clone();
  for (int y = 0; y < z.rows; ++y) {
    float* row = out.ptr<float>(y);
    for (int x = 0; x < z.cols; ++x) row[x] = float(row[x] - (c[0] + c[1] * x + c[2] * y));
  }
  return out;
}

// RMS over the finite pixels, their count in *n.
double Rms(const cv::Mat& z, int64_t* n) {
  double ss = 0.0;
  *n = 0;
  for (int y = 0; y < z.rows; ++y) {
    const float* row = z.ptr<float>(y);
    for (int x = 0; x < z.cols; ++x) {
      if (std::isfinite(row[x])) {
        ss += double(row[x]) * row[x];
        ++*n;
      }
    }
  }
  return *n > 0 ? std::sqrt(ss / *n) : 0.0;
}

StatusOr<cv::Mat> PairDifference(const cv::Mat& a, const cv::Mat& b, bool mean) {
  INSPECT_RETURN_IF_ERROR(CheckMap(a, "a"));
  INSPECT_RETURN_IF_ERROR(CheckMap(b, "b"));
  if (a.size() != b.size()) return Status::InvalidArgument("a and b must have the same size");
  cv::Mat d(a.size(), CV_32FC1);
  int64_t both = 0;
  for (int y = 0; y < a.rows; ++y) {
    for (int x = 0; x < a.cols; ++x) {
      const float u = a.at<float>(y, x), v = b.at<float>(y, x);
      const bool ok = std::isfinite(u) && std::isfinite(v);
      d.at<float>(y, x) = ok ? (mean ? 0.5f * (u + v) : u - v) : std::numeric_limits<float>::quiet_NaN();
      both += ok;
    }
  }
  if (both < 100) return Status::InvalidArgument("a and b share only " + std::to_string(both) + " pixels with depth");
  return d;
}

}  // namespace

StatusOr<CharacteristicEstimate> MeasurementNoise(const cv::Mat& a, const cv::Mat& b, int correlation_px) {
  if (correlation_px < 1) return Status::InvalidArgument("correlation_px must be >= 1");
  INSPECT_ASSIGN_OR_RETURN(cv::Mat d, PairDifference(a, b, false));
  int64_t n = 0;
  // The plane takes what moved between the two scans (stage repeatability, a re-placed part).
  const double sq = Rms(Levelled(d), &n);
  const double n_eff = std::max(2.0, double(n) / (double(correlation_px) * correlation_px));
  CharacteristicEstimate e;
  e.value = sq / std::sqrt(2.0);
  e.standard_uncertainty = e.value / std::sqrt(2.0 * (n_eff - 1.0));  // s of a normal sample's s
  return e;
}

StatusOr<CharacteristicEstimate> FlatnessDeviation(const cv::Mat& a, const cv::Mat& b, int correlation_px) {
  if (correlation_px < 1) return Status::InvalidArgument("correlation_px must be >= 1");
  INSPECT_ASSIGN_OR_RETURN(CharacteristicEstimate noise, MeasurementNoise(a, b, correlation_px));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat mean, PairDifference(a, b, true));
  const cv::Mat level = Levelled(mean);
  // Blocks of 4 x 4 correlation lengths: 16 independent noise samples each.
  const int k = 4 * correlation_px;
  int blocks = 0;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int y0 = 0; y0 + k <= level.rows; y0 += k) {
    for (int x0 = 0; x0 + k <= level.cols; x0 += k) {
      double s = 0.0;
      int c = 0;
      for (int y = y0; y < y0 + k; ++y) {
        for (int x = x0; x < x0 + k; ++x) {
          const float v = level.at<float>(y, x);
          if (std::isfinite(v)) {
            s += v;
            ++c;
          }
        }
      }
      if (c * 2 < k * k) continue;  // a block mostly without depth says little
      ++blocks;
      lo = std::min(lo, s / c);
      hi = std::max(hi, s / c);
    }
  }
  if (!(hi >= lo)) return Status::InvalidArgument("a and b: no block of the flat has enough depth");
  CharacteristicEstimate e;
  // A block mean of the two maps' mean keeps N_M / sqrt 2 / 4 of noise (16 independent samples);
  // the max and the min are each the extreme of many blocks, which the noise pushes outwards by
  // up to sqrt(2 ln blocks) of it.
  const double block_noise = noise.value / std::sqrt(2.0) / 4.0;
  e.value = hi - lo;
  e.standard_uncertainty = std::sqrt(2.0) * block_noise * std::sqrt(2.0 * std::log(std::max(2, blocks)));
  return e;
}

StatusOr<AmplificationLinearity> AmplificationAndLinearity(const std::vector<ResponsePoint>& points) {
  if (points.size() < 2) return Status::InvalidArgument("points: at least 2 step heights are needed");
  for (size_t i = 0; i < points.size(); ++i) {
    const ResponsePoint& p = points[i];
    if (!(p.measured_u_um > 0.0) || !(p.certified_u_um >= 0.0) || !std::isfinite(p.certified_um) ||
        !std::isfinite(p.measured_um)) {
      return Status::InvalidArgument("points[" + std::to_string(i) + "]: values finite, measured_u_um > 0");
    }
  }
  double alpha = 1.0, offset = 0.0;
  cv::Matx22d cov;
  for (int pass = 0; pass < 2; ++pass) {
    double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (const ResponsePoint& p : points) {
      const double w = 1.0 / (p.measured_u_um * p.measured_u_um + alpha * alpha * p.certified_u_um * p.certified_u_um);
      sw += w;
      sx += w * p.certified_um;
      sy += w * p.measured_um;
      sxx += w * p.certified_um * p.certified_um;
      sxy += w * p.certified_um * p.measured_um;
    }
    const double det = sw * sxx - sx * sx;
    if (!(det > 1e-12 * sw * sxx)) return Status::InvalidArgument("points: the certified heights must differ");
    alpha = (sw * sxy - sx * sy) / det;
    offset = (sxx * sy - sx * sxy) / det;
    cov = cv::Matx22d(sw / det, -sx / det, -sx / det, sxx / det);  // (alpha, offset)
  }
  AmplificationLinearity out;
  out.alpha_z = {alpha, std::sqrt(cov(0, 0))};
  out.offset_um = {offset, std::sqrt(cov(1, 1))};
  double worst = -1.0, worst_u = 0.0;
  for (const ResponsePoint& p : points) {
    const double r = std::abs(p.measured_um - (alpha * p.certified_um + offset));
    if (r > worst) {
      worst = r;
      worst_u = std::sqrt(p.measured_u_um * p.measured_u_um + alpha * alpha * p.certified_u_um * p.certified_u_um);
    }
  }
  out.l_z_um = {worst, worst_u};
  return out;
}

StatusOr<CharacteristicEstimate> LateralAmplification(const cv::Mat& grating_um, double pixel_size_um,
                                                      double certified_pitch_um, int axis) {
  INSPECT_RETURN_IF_ERROR(CheckMap(grating_um, "grating"));
  if (!(pixel_size_um > 0.0) || !(certified_pitch_um > 0.0) || (axis != 0 && axis != 1)) {
    return Status::InvalidArgument("pixel_size_um and certified_pitch_um must be > 0, axis 0 (x) or 1 (y)");
  }
  const cv::Mat z = axis == 0 ? grating_um : cv::Mat(grating_um.t());
  // Mean profile along the axis (rows averaged), its linear trend removed.
  std::vector<double> prof(z.cols, 0.0);
  std::vector<int> cnt(z.cols, 0);
  for (int y = 0; y < z.rows; ++y) {
    for (int x = 0; x < z.cols; ++x) {
      const float v = z.at<float>(y, x);
      if (std::isfinite(v)) {
        prof[x] += v;
        ++cnt[x];
      }
    }
  }
  std::vector<double> xs, vs;
  for (int x = 0; x < z.cols; ++x) {
    if (cnt[x] > 0) {
      xs.push_back(x);
      vs.push_back(prof[x] / cnt[x]);
    }
  }
  if (xs.size() < 8) return Status::InvalidArgument("grating: too few columns with depth");
  double mx = 0, mv = 0;
  for (size_t i = 0; i < xs.size(); ++i) {
    mx += xs[i];
    mv += vs[i];
  }
  mx /= xs.size();
  mv /= xs.size();
  double sxv = 0, sxx = 0;
  for (size_t i = 0; i < xs.size(); ++i) {
    sxv += (xs[i] - mx) * (vs[i] - mv);
    sxx += (xs[i] - mx) * (xs[i] - mx);
  }
  const double slope = sxv / sxx;
  for (size_t i = 0; i < xs.size(); ++i) vs[i] -= mv + slope * (xs[i] - mx);
  // Rising zero crossings, linearly interpolated; hysteresis at 30 % of the profile's RMS so the
  // noise near zero does not count as crossings.
  double rms = 0.0;
  for (double v : vs) rms += v * v;
  rms = std::sqrt(rms / vs.size());
  const double hysteresis = 0.3 * rms;
  // Rising and falling crossings apart: a residual trend (the detrending of a non-whole number of
  // periods leaves one) moves the rising ones one way along x and the falling ones the other, so
  // the mean of their two periods cancels it to first order.
  std::vector<double> rises, falls;
  bool armed_rise = false, armed_fall = false;
  for (size_t i = 1; i < xs.size(); ++i) {
    if (vs[i - 1] < -hysteresis) armed_rise = true;
    if (vs[i - 1] > hysteresis) armed_fall = true;
    if (xs[i] - xs[i - 1] != 1.0) continue;
    const double at = xs[i - 1] + (-vs[i - 1]) / (vs[i] - vs[i - 1]);
    if (armed_rise && vs[i - 1] < 0.0 && vs[i] >= 0.0) {
      rises.push_back(at);
      armed_rise = false;
    }
    if (armed_fall && vs[i - 1] > 0.0 && vs[i] <= 0.0) {
      falls.push_back(at);
      armed_fall = false;
    }
  }
  if (rises.size() < 4 || falls.size() < 4) {
    return Status::InvalidArgument("grating: fewer than 3 periods along the axis in the field");
  }
  // Period: least-squares slope of crossing position against crossing number, per kind.
  auto slope_of = [](const std::vector<double>& c, double* u) {
    const int k = int(c.size());
    const double mi = (k - 1) / 2.0;
    double mr = 0;
    for (double r : c) mr += r;
    mr /= k;
    double sir = 0, sii = 0;
    for (int i = 0; i < k; ++i) {
      sir += (i - mi) * (c[i] - mr);
      sii += (i - mi) * (i - mi);
    }
    const double period = sir / sii;
    double ss = 0;
    for (int i = 0; i < k; ++i) {
      const double r = c[i] - (mr + period * (i - mi));
      ss += r * r;
    }
    // Residual scatter of the crossings (at least a 1/sqrt(12) px quantisation floor) through the
    // slope's standard error.
    const double sigma_px = std::max(std::sqrt(ss / std::max(1, k - 2)), 1.0 / std::sqrt(12.0));
    *u = sigma_px / std::sqrt(sii);
    return period;
  };
  double u_rise = 0, u_fall = 0;
  const double p_rise = slope_of(rises, &u_rise), p_fall = slope_of(falls, &u_fall);
  const double period_px = 0.5 * (p_rise + p_fall);
  const double u_period_px = 0.5 * std::hypot(u_rise, u_fall);
  CharacteristicEstimate e;
  e.value = period_px * pixel_size_um / certified_pitch_um;
  e.standard_uncertainty = u_period_px * pixel_size_um / certified_pitch_um;
  return e;
}

StatusOr<CharacteristicEstimate> SinusoidAmplitudeAlongX(const cv::Mat& map_um, int correlation_px) {
  INSPECT_RETURN_IF_ERROR(CheckMap(map_um, "map"));
  if (correlation_px < 1) return Status::InvalidArgument("correlation_px must be >= 1");
  std::vector<double> prof;
  std::vector<double> var;
  for (int x = 0; x < map_um.cols; ++x) {
    double s = 0, ss = 0;
    int c = 0;
    for (int y = 0; y < map_um.rows; ++y) {
      const float v = map_um.at<float>(y, x);
      if (std::isfinite(v)) {
        s += v;
        ss += double(v) * v;
        ++c;
      }
    }
    if (c < 2) continue;
    prof.push_back(s / c);
    var.push_back(std::max(0.0, ss / c - (s / c) * (s / c)));
  }
  if (prof.size() < 8) return Status::InvalidArgument("map: too few columns with depth");
  const int n = int(prof.size());
  double mx = (n - 1) / 2.0, mv = 0;
  for (double v : prof) mv += v;
  mv /= n;
  double sxv = 0, sxx = 0;
  for (int i = 0; i < n; ++i) {
    sxv += (i - mx) * (prof[i] - mv);
    sxx += (i - mx) * (i - mx);
  }
  const double slope = sxv / sxx;
  double ss = 0, mean_var = 0;
  for (int i = 0; i < n; ++i) {
    const double r = prof[i] - (mv + slope * (i - mx));
    ss += r * r;
  }
  for (double v : var) mean_var += v;
  mean_var /= n;
  CharacteristicEstimate e;
  e.value = std::sqrt(2.0 * ss / n);
  // The column means keep the within-column scatter / sqrt(independent rows); the amplitude of
  // n / correlation_px independent profile samples carries that over sqrt of their number.
  const double rows_eff = std::max(1.0, double(map_um.rows) / correlation_px);
  const double profile_noise = std::sqrt(mean_var / rows_eff);
  e.standard_uncertainty = profile_noise * std::sqrt(2.0 / std::max(1.0, double(n) / correlation_px));
  return e;
}

StatusOr<CharacteristicEstimate> TopographicSpatialResolution(std::vector<TransferPoint> points) {
  for (size_t i = 0; i < points.size(); ++i) {
    if (!(points[i].period_um > 0.0) || !(points[i].certified_amplitude_um > 0.0)) {
      return Status::InvalidArgument("points[" + std::to_string(i) + "]: period and certified amplitude must be > 0");
    }
  }
  std::sort(points.begin(), points.end(), [](const auto& a, const auto& b) { return a.period_um < b.period_um; });
  for (size_t i = 1; i < points.size(); ++i) {
    const TransferPoint &p = points[i - 1], &q = points[i];
    const double tp = p.measured_amplitude_um / p.certified_amplitude_um;
    const double tq = q.measured_amplitude_um / q.certified_amplitude_um;
    if (tp < 0.5 && tq >= 0.5) {
      const double f = (0.5 - tp) / (tq - tp);
      CharacteristicEstimate e;
      e.value = p.period_um + f * (q.period_um - p.period_um);
      // Through the interpolation: d W_R / d t_p and d W_R / d t_q.
      const double dw = q.period_um - p.period_um;
      const double up = p.measured_amplitude_u_um / p.certified_amplitude_um;
      const double uq = q.measured_amplitude_u_um / q.certified_amplitude_um;
      const double dtp = dw * (0.5 - tq) / ((tq - tp) * (tq - tp));
      const double dtq = dw * (tp - 0.5) / ((tq - tp) * (tq - tp));
      e.standard_uncertainty = std::sqrt(dtp * dtp * up * up + dtq * dtq * uq * uq);
      return e;
    }
  }
  return Status::FailedPrecondition("points: no two sinusoids bracket 50 % amplitude transfer");
}

StatusOr<CharacteristicEstimate> GrooveDepth(const cv::Mat& map_um, int correlation_px) {
  INSPECT_RETURN_IF_ERROR(CheckMap(map_um, "map"));
  if (correlation_px < 1) return Status::InvalidArgument("correlation_px must be >= 1");
  const int w = map_um.cols;
  if (w < 18) return Status::InvalidArgument("map must be at least 18 px wide");
  const double third = w / 3.0, margin = third / 6.0;
  auto land = [&](int x) {
    return (x >= margin && x < third - margin) || (x >= 2.0 * third + margin && x < w - margin);
  };
  auto bottom = [&](int x) { return x >= third + third / 3.0 && x < 2.0 * third - third / 3.0; };
  // Plane through the lands.
  double s[3][3] = {}, r[3] = {};
  int64_t n_land = 0, n_bottom = 0;
  for (int y = 0; y < map_um.rows; ++y) {
    const float* row = map_um.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      if (!std::isfinite(row[x])) continue;
      if (bottom(x)) ++n_bottom;
      if (!land(x)) continue;
      ++n_land;
      const double v[3] = {1.0, double(x), double(y)};
      for (int i = 0; i < 3; ++i) {
        r[i] += v[i] * row[x];
        for (int j = 0; j < 3; ++j) s[i][j] += v[i] * v[j];
      }
    }
  }
  if (n_land < 100 || n_bottom < 100) {
    return Status::InvalidArgument("map: fewer than 100 pixels with depth on the lands or the groove's bottom");
  }
  cv::Matx33d a(s[0][0], s[0][1], s[0][2], s[1][0], s[1][1], s[1][2], s[2][0], s[2][1], s[2][2]);
  cv::Vec3d c;
  if (!cv::solve(a, cv::Vec3d(r[0], r[1], r[2]), c, cv::DECOMP_SVD)) {
    return Status::InvalidArgument("map: the lands do not fix a plane");
  }
  double land_ss = 0.0, depth_sum = 0.0, depth_ss = 0.0;
  for (int y = 0; y < map_um.rows; ++y) {
    const float* row = map_um.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      if (!std::isfinite(row[x])) continue;
      const double d = c[0] + c[1] * x + c[2] * y - row[x];
      if (land(x)) land_ss += d * d;
      if (bottom(x)) {
        depth_sum += d;
        depth_ss += d * d;
      }
    }
  }
  const double depth = depth_sum / double(n_bottom);
  const double var_land = land_ss / double(n_land);
  const double var_bottom = std::max(0.0, depth_ss / double(n_bottom) - depth * depth);
  const double k2 = double(correlation_px) * correlation_px;
  CharacteristicEstimate e;
  e.value = depth;
  e.standard_uncertainty = std::sqrt(var_land / std::max(1.0, n_land / k2) + var_bottom / std::max(1.0, n_bottom / k2));
  return e;
}

StatusOr<CharacteristicEstimate> SinusoidFundamentalAlongX(const cv::Mat& map_um, double pixel_size_um,
                                                           double period_um, int correlation_px) {
  INSPECT_RETURN_IF_ERROR(CheckMap(map_um, "map"));
  if (correlation_px < 1) return Status::InvalidArgument("correlation_px must be >= 1");
  if (!(pixel_size_um > 0.0) || !(period_um > 0.0)) {
    return Status::InvalidArgument("pixel_size_um and period_um must be > 0");
  }
  std::vector<double> xs, prof;
  for (int x = 0; x < map_um.cols; ++x) {
    double s = 0;
    int c = 0;
    for (int y = 0; y < map_um.rows; ++y) {
      const float v = map_um.at<float>(y, x);
      if (std::isfinite(v)) {
        s += v;
        ++c;
      }
    }
    if (c < 2) continue;
    xs.push_back(x);
    prof.push_back(s / c);
  }
  const double period_px = period_um / pixel_size_um;
  if (xs.size() < 8 || (xs.back() - xs.front()) < 2.0 * period_px) {
    return Status::InvalidArgument("map: fewer than 2 periods with depth along x");
  }
  const int n = int(xs.size());
  // Least squares of a + b x + c sin + d cos at each trial period; the best fit's amplitude.
  double best_amp = 0.0, best_rss = std::numeric_limits<double>::infinity();
  for (double f = 0.85; f <= 1.15 + 1e-9; f += 0.0025) {
    const double k = 2.0 * CV_PI / (period_px * f);
    cv::Matx44d a = cv::Matx44d::zeros();
    cv::Vec4d r(0, 0, 0, 0);
    for (int i = 0; i < n; ++i) {
      const double v[4] = {1.0, xs[i], std::sin(k * xs[i]), std::cos(k * xs[i])};
      for (int p = 0; p < 4; ++p) {
        r[p] += v[p] * prof[i];
        for (int q = 0; q < 4; ++q) a(p, q) += v[p] * v[q];
      }
    }
    cv::Vec4d c;
    if (!cv::solve(a, r, c, cv::DECOMP_SVD)) continue;
    double rss = 0.0;
    for (int i = 0; i < n; ++i) {
      const double e = prof[i] - (c[0] + c[1] * xs[i] + c[2] * std::sin(k * xs[i]) + c[3] * std::cos(k * xs[i]));
      rss += e * e;
    }
    if (rss < best_rss) {
      best_rss = rss;
      best_amp = std::hypot(c[2], c[3]);
    }
  }
  CharacteristicEstimate e;
  e.value = best_amp;
  // A sinusoid's amplitude from n / correlation_px independent samples of residual scatter s:
  // u = s sqrt(2 / samples).
  const double s = std::sqrt(best_rss / std::max(1, n - 4));
  e.standard_uncertainty = s * std::sqrt(2.0 / std::max(1.0, double(n) / correlation_px));
  return e;
}

}  // namespace inspection
