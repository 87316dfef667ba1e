// Normalised FGS of weighted depth moments with the all-in-focus image as guide, optionally local
// planes and a robust reweighting (core/sff/dense_depth.h).
#include "core/sff/dense_depth.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/edge_filter.hpp>
#include <vector>

#include "core/sff/depth_fill.h"

namespace inspection {

Status DenseDepthOptions::Validate() const {
  if (!(lambda > 0.0 && std::isfinite(lambda))) return Status::InvalidArgument("dense.lambda must be > 0");
  if (!(sigma_color > 0.0 && std::isfinite(sigma_color))) {
    return Status::InvalidArgument("dense.sigma_color must be > 0");
  }
  if (!(plane_ridge_px >= 0.0 && std::isfinite(plane_ridge_px))) {
    return Status::InvalidArgument("dense.plane_ridge_px must be >= 0");
  }
  if (!(fallback_support >= 0.0 && std::isfinite(fallback_support))) {
    return Status::InvalidArgument("dense.fallback_support must be >= 0");
  }
  if (fallback_support > 0.0 && !(fallback_sigma_color > 0.0 && std::isfinite(fallback_sigma_color))) {
    return Status::InvalidArgument("dense.fallback_sigma_color must be > 0");
  }
  if (halo_radius_px < 0 || halo_radius_px > 64) {
    return Status::InvalidArgument("dense.halo_radius_px must be between 0 and 64");
  }
  if (robust_iterations < 0 || robust_iterations > 10) {
    return Status::InvalidArgument("dense.robust_iterations must be between 0 and 10");
  }
  if (!(reject_scale >= 0.0 && std::isfinite(reject_scale))) {
    return Status::InvalidArgument("dense.reject_scale must be >= 0");
  }
  if (!(robust_scale > 0.0 && std::isfinite(robust_scale))) {
    return Status::InvalidArgument("dense.robust_scale must be > 0");
  }
  if (solve_downscale < 0 || solve_downscale > 16) {
    return Status::InvalidArgument("dense.solve_downscale must be between 0 (auto) and 16");
  }
  if (!(auto_solve_max_pixels >= 1.0 && std::isfinite(auto_solve_max_pixels))) {
    return Status::InvalidArgument("dense.auto_solve_max_pixels must be >= 1");
  }
  if (!(upsample_sigma_color > 0.0 && std::isfinite(upsample_sigma_color))) {
    return Status::InvalidArgument("dense.upsample_sigma_color must be > 0");
  }
  return Status::Ok();
}

namespace {

// FGS takes an 8-bit guide only.
cv::Mat Guide8(const cv::Mat& guide) {
  cv::Mat g8;
  switch (guide.depth()) {
    case CV_8U: g8 = guide; break;
    case CV_16U: guide.convertTo(g8, CV_8U, 1.0 / 257.0); break;
    default: guide.convertTo(g8, CV_8U, 255.0); break;  // float in [0, 1]
  }
  if (g8.channels() == 4) cv::cvtColor(g8, g8, cv::COLOR_BGRA2BGR);
  return g8;
}

// Own guide texture / the strongest within `radius` (CV_32FC1 in [0, 1]).
cv::Mat HaloFactor(const cv::Mat& guide8, int radius) {
  cv::Mat grey;
  if (guide8.channels() == 3)
    cv::cvtColor(guide8, grey, cv::COLOR_BGR2GRAY);
  else
    grey = guide8;
  cv::Mat gx, gy;
  cv::Sobel(grey, gx, CV_32F, 1, 0);
  cv::Sobel(grey, gy, CV_32F, 0, 1);
  cv::Mat energy = gx.mul(gx) + gy.mul(gy);
  cv::boxFilter(energy, energy, -1, cv::Size(3, 3));
  cv::Mat strongest;
  cv::dilate(energy, strongest, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * radius + 1, 2 * radius + 1)));
  // The floor: a patch flat all round (no edge to borrow from) keeps its weight.
  cv::Mat factor = energy / cv::max(strongest, 1.f);
  factor.setTo(1.f, strongest < 1.f);
  return factor;
}

// The k x k block means of an 8-bit image (the last blocks of a row or column partial).
cv::Mat BlockMean(const cv::Mat& img8, int k, const cv::Size& size) {
  const int cn = img8.channels();
  cv::Mat out(size, img8.type());
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& range) {
    std::vector<uint32_t> sum(size_t(size.width * cn)), cnt(size_t(size.width));
    for (int by = range.start; by < range.end; ++by) {
      std::fill(sum.begin(), sum.end(), 0u);
      std::fill(cnt.begin(), cnt.end(), 0u);
      for (int y = by * k; y < std::min(img8.rows, (by + 1) * k); ++y) {
        const uint8_t* p = img8.ptr<uint8_t>(y);
        for (int x = 0; x < img8.cols; ++x) {
          const int bx = x / k;
          ++cnt[size_t(bx)];
          for (int c = 0; c < cn; ++c) sum[size_t(bx * cn + c)] += p[x * cn + c];
        }
      }
      uint8_t* o = out.ptr<uint8_t>(by);
      for (int bx = 0; bx < size.width; ++bx)
        for (int c = 0; c < cn; ++c)
          o[bx * cn + c] = uint8_t((sum[size_t(bx * cn + c)] + cnt[size_t(bx)] / 2) / cnt[size_t(bx)]);
    }
  });
  return out;
}

// Flat segments of the guide (connected pixels whose grey gradient stays below `gradient` levels
// per pixel, at least min_area pixels) and one robust plane per segment fitted to the
// measurements on it and within `band` pixels of it. Returns the plane's (centred) depth on every
// pixel of a segment that has one, NaN elsewhere. An untextured region is one surface more often
// than not (a wall, the sky, a painted part): its depth continues that of the edges around it,
// and the Cauchy-weighted fit lets the majority of its rim win over the minority that belongs to
// an occluder in front of it.
cv::Mat SegmentPlanes(const cv::Mat& guide_s, const cv::Mat& centred, const cv::Mat& w, double gradient, int band,
                      int min_area, double ridge_px, double robust_scale, double min_scale) {
  cv::Mat grey;
  if (guide_s.channels() == 3)
    cv::cvtColor(guide_s, grey, cv::COLOR_BGR2GRAY);
  else
    grey = guide_s;
  cv::Mat g32, gx, gy;
  grey.convertTo(g32, CV_32F);
  cv::GaussianBlur(g32, g32, cv::Size(0, 0), 1.0);
  cv::Sobel(g32, gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(g32, gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  cv::Mat mag;
  cv::magnitude(gx, gy, mag);
  const cv::Mat flat = mag < float(gradient);
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(flat, labels, stats, centroids, 4, CV_32S);
  const int rows = w.rows, cols = w.cols;
  cv::Mat out(w.size(), CV_32FC1, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  struct Sample {
    float u, v, d, w;
  };
  std::vector<int> slot(size_t(n), -1);
  std::vector<std::vector<Sample>> samples;
  for (int l = 1; l < n; ++l)
    if (stats.at<int>(l, cv::CC_STAT_AREA) >= min_area) {
      slot[size_t(l)] = int(samples.size());
      samples.emplace_back();
    }
  if (samples.empty()) return out;
  const float scale = 2.f / float(std::max(rows, cols));
  std::vector<int> seen;
  for (int y = 0; y < rows; ++y) {
    const float* pw = w.ptr<float>(y);
    const float* pc = centred.ptr<float>(y);
    for (int x = 0; x < cols; ++x) {
      if (!(pw[x] > 0.f)) continue;
      seen.clear();
      for (int yy = std::max(0, y - band); yy <= std::min(rows - 1, y + band); ++yy) {
        const int* lab = labels.ptr<int>(yy);
        for (int xx = std::max(0, x - band); xx <= std::min(cols - 1, x + band); ++xx) {
          const int s = slot[size_t(lab[xx])];
          if (s >= 0 && std::find(seen.begin(), seen.end(), s) == seen.end()) seen.push_back(s);
        }
      }
      for (int s : seen) samples[size_t(s)].push_back({float(x) * scale, float(y) * scale, pc[x], pw[x]});
    }
  }
  std::vector<double> plane(3 * samples.size(), std::numeric_limits<double>::quiet_NaN());
  const double r2 = (ridge_px * scale) * (ridge_px * scale);
  for (size_t s = 0; s < samples.size(); ++s) {
    const std::vector<Sample>& v = samples[s];
    if (v.size() < 16) continue;
    std::vector<double> wt(v.size());
    for (size_t i = 0; i < v.size(); ++i) wt[i] = v[i].w;
    double u0 = 0, v0 = 0, sw0 = 0;
    for (size_t i = 0; i < v.size(); ++i) {
      u0 += wt[i] * v[i].u;
      v0 += wt[i] * v[i].v;
      sw0 += wt[i];
    }
    u0 /= sw0;
    v0 /= sw0;
    double a = 0, b = 0, c = 0;
    bool ok = false;
    for (int it = 0; it < 6; ++it) {
      // Weighted least squares of d = a + b (u - u0) + c (v - v0), the slope ridged.
      double s0 = 0, su = 0, sv = 0, suu = 0, suv = 0, svv = 0, sd = 0, sdu = 0, sdv = 0;
      for (size_t i = 0; i < v.size(); ++i) {
        const double q = wt[i], du = v[i].u - u0, dv = v[i].v - v0, d = v[i].d;
        s0 += q, su += q * du, sv += q * dv, suu += q * du * du, suv += q * du * dv, svv += q * dv * dv;
        sd += q * d, sdu += q * d * du, sdv += q * d * dv;
      }
      if (!(s0 > 0)) break;
      suu += r2 * s0;
      svv += r2 * s0;
      const cv::Matx33d A(s0, su, sv, su, suu, suv, sv, suv, svv);
      const cv::Vec3d rhs(sd, sdu, sdv);
      cv::Vec3d x;
      if (!cv::solve(A, rhs, x, cv::DECOMP_CHOLESKY)) break;
      a = x[0], b = x[1], c = x[2];
      ok = true;
      std::vector<double> res(v.size());
      for (size_t i = 0; i < v.size(); ++i) res[i] = std::abs(v[i].d - (a + b * (v[i].u - u0) + c * (v[i].v - v0)));
      std::vector<double> sorted = res;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
      const double sc = std::max(robust_scale * 1.4826 * sorted[sorted.size() / 2], min_scale);
      for (size_t i = 0; i < v.size(); ++i) {
        const double r = res[i] / sc;
        wt[i] = v[i].w / (1.0 + r * r);
      }
    }
    if (!ok) continue;
    plane[3 * s] = a - b * u0 - c * v0;
    plane[3 * s + 1] = b;
    plane[3 * s + 2] = c;
  }
  for (int y = 0; y < rows; ++y) {
    const int* lab = labels.ptr<int>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < cols; ++x) {
      const int s = slot[size_t(lab[x])];
      if (s < 0 || !(plane[3 * size_t(s)] == plane[3 * size_t(s)])) continue;
      o[x] = float(plane[3 * size_t(s)] + plane[3 * size_t(s) + 1] * x * scale + plane[3 * size_t(s) + 2] * y * scale);
    }
  }
  return out;
}

// The edge-aware filter, plus (fallback) the weakly edge-aware one times its weight: where the
// first's support vanishes (a region with no measurement inside whose rim is all guide edges)
// the second's wider reach decides.
struct Smoother {
  cv::Ptr<cv::ximgproc::FastGlobalSmootherFilter> fgs, fallback;
  double fallback_weight = 0.0;
  void filter(const cv::Mat& src, cv::Mat& dst) const {
    fgs->filter(src, dst);
    if (fallback) {
      cv::Mat f;
      fallback->filter(src, f);
      cv::scaleAdd(f, fallback_weight, dst, dst);
    }
  }
};

// One weighted fit: fit = the model's value at every pixel, den = F(w). spread (optional): the
// weighted RMS residual of the measured depths the fit draws on about the model at the pixel,
// sqrt(F(w (d - model)^2) / F(w)), from one more filtered moment, F(w d^2).
void Fit(cv::ximgproc::FastGlobalSmootherFilter& fgs, const cv::Mat& centred, const cv::Mat& w, bool planes, double ridge, cv::Mat* fit,
         cv::Mat* den, cv::Mat* spread = nullptr) {
  const cv::Mat wd = centred.mul(w);  // 0 where unmeasured (w = 0, centred = 0)
  fgs.filter(w, *den);
  cv::Mat num, mdd;
  fgs.filter(wd, num);
  if (spread) fgs.filter(wd.mul(centred), mdd);
  if (!planes) {
    *fit = num / cv::max(*den, 1e-30f);
    if (spread) {
      cv::Mat var = mdd / cv::max(*den, 1e-30f) - fit->mul(*fit);
      cv::sqrt(cv::max(var, 0.f), *spread);
    }
    return;
  }
  // Coordinates scaled to about [-1, 1] so that the float moments keep their precision.
  const int rows = w.rows, cols = w.cols;
  const double scale = 2.0 / std::max(rows, cols);
  cv::Mat u(w.size(), CV_32FC1), v(w.size(), CV_32FC1);
  for (int y = 0; y < rows; ++y) {
    float* pu = u.ptr<float>(y);
    float* pv = v.ptr<float>(y);
    for (int x = 0; x < cols; ++x) {
      pu[x] = float((x - 0.5 * cols) * scale);
      pv[x] = float((y - 0.5 * rows) * scale);
    }
  }
  const cv::Mat wu = w.mul(u), wv = w.mul(v);
  cv::Mat mu, mv, muu, muv, mvv, mdu, mdv;
  fgs.filter(wu, mu);
  fgs.filter(wv, mv);
  fgs.filter(wu.mul(u), muu);
  fgs.filter(wu.mul(v), muv);
  fgs.filter(wv.mul(v), mvv);
  fgs.filter(wd.mul(u), mdu);
  fgs.filter(wd.mul(v), mdv);
  const double r2 = (ridge * scale) * (ridge * scale);
  fit->create(w.size(), CV_32FC1);
  if (spread) spread->create(w.size(), CV_32FC1);
  cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range) {
    for (int y = range.start; y < range.end; ++y) {
      const float *m0 = den->ptr<float>(y), *m1 = num.ptr<float>(y), *a_u = mu.ptr<float>(y),
                  *a_v = mv.ptr<float>(y), *a_uu = muu.ptr<float>(y), *a_uv = muv.ptr<float>(y),
                  *a_vv = mvv.ptr<float>(y), *b_u = mdu.ptr<float>(y), *b_v = mdv.ptr<float>(y),
                  *pu = u.ptr<float>(y), *pv = v.ptr<float>(y);
      const float* a_dd = spread ? mdd.ptr<float>(y) : nullptr;
      float* out = fit->ptr<float>(y);
      float* sp = spread ? spread->ptr<float>(y) : nullptr;
      for (int x = 0; x < cols; ++x) {
        const double s0 = m0[x];
        if (!(s0 > 1e-30)) {
          out[x] = 0.f;
          if (sp) sp[x] = 0.f;
          continue;
        }
        // Moments about the pixel itself: its depth is the plane's intercept.
        const double up = pu[x], vp = pv[x];
        const double su = a_u[x] - up * s0, sv = a_v[x] - vp * s0;
        const double suu = a_uu[x] - 2 * up * a_u[x] + up * up * s0 + r2 * s0;
        const double svv = a_vv[x] - 2 * vp * a_v[x] + vp * vp * s0 + r2 * s0;
        const double suv = a_uv[x] - up * a_v[x] - vp * a_u[x] + up * vp * s0;
        const double b0 = m1[x], bu = b_u[x] - up * m1[x], bv = b_v[x] - vp * m1[x];
        // Cramer's rule on [s0 su sv; su suu suv; sv suv svv] (a b c)' = (b0 bu bv)'.
        const double c00 = suu * svv - suv * suv, c01 = su * svv - suv * sv, c02 = su * suv - suu * sv;
        const double det = s0 * c00 - su * c01 + sv * c02;
        if (!(std::abs(det) > 1e-12 * s0 * s0 * s0 * r2 * r2) || !std::isfinite(det)) {
          out[x] = float(b0 / s0);
          if (sp) sp[x] = float(std::sqrt(std::max(a_dd[x] / s0 - (b0 / s0) * (b0 / s0), 0.0)));
          continue;
        }
        const double det_a = b0 * c00 - su * (bu * svv - suv * bv) + sv * (bu * suv - suu * bv);
        out[x] = float(det_a / det);
        if (sp) {
          // The residual about the best plane of the data, sum w (d - a - b u - c v)^2 at the
          // least-squares (a, b, c) = S_dd - (a, b, c) . (b0, bu, bv): without the ridge, which
          // shrinks the slope as a prior, not as data (with it a tilted plane would leave a
          // residual), unless the moments alone are near singular (a strip of measurements).
          const double quu = suu - r2 * s0, qvv = svv - r2 * s0;
          const double e00 = quu * qvv - suv * suv, e01 = su * qvv - suv * sv, e02 = su * suv - quu * sv;
          const double det0 = s0 * e00 - su * e01 + sv * e02;
          const bool plain = std::abs(det0) > 1e-6 * std::abs(det) && std::isfinite(det0);
          const double pu = plain ? quu : suu, pv = plain ? qvv : svv, d = plain ? det0 : det;
          const double f00 = pu * pv - suv * suv, f01 = su * pv - suv * sv, f02 = su * suv - pu * sv;
          const double a = (b0 * f00 - su * (bu * pv - suv * bv) + sv * (bu * suv - pu * bv)) / d;
          const double b = (s0 * (bu * pv - suv * bv) - b0 * f01 + sv * (su * bv - bu * sv)) / d;
          const double c = (s0 * (pu * bv - bu * suv) - su * (su * bv - bu * sv) + b0 * f02) / d;
          const double ss = a_dd[x] - 2.0 * (a * b0 + b * bu + c * bv) + a * a * s0 + b * b * quu + c * c * qvv +
                            2.0 * (a * b * su + a * c * sv + b * c * suv);
          sp[x] = float(std::sqrt(std::max(ss / s0, 0.0)));
        }
      }
    }
  });
}

}  // namespace

int DenseSolveDownscale(const cv::Size& size, const DenseDepthOptions& options) {
  if (options.solve_downscale > 0) return options.solve_downscale;
  int k = 1;
  while (k < 8 && double(size.width / k) * double(size.height / k) > options.auto_solve_max_pixels) k *= 2;
  return k;
}

StatusOr<DenseDepth> DensifyDepthWithSupport(const cv::Mat& depth_um, const cv::Mat& confidence,
                                             const cv::Mat& guide, const DenseDepthOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.empty() || depth_um.type() != CV_32FC1) return Status::InvalidArgument("depth_um must be CV_32FC1");
  if (!confidence.empty() && (confidence.type() != CV_32FC1 || confidence.size() != depth_um.size())) {
    return Status::InvalidArgument("confidence must be CV_32FC1 of the depth map's size");
  }
  if (guide.empty() || guide.size() != depth_um.size() || (guide.channels() != 1 && guide.channels() != 3)) {
    return Status::InvalidArgument("guide must be the all-in-focus image (1 or 3 channels) of the depth map's size");
  }
  const int rows = depth_um.rows, cols = depth_um.cols;
  const cv::Mat guide8 = Guide8(guide);
  const cv::Mat halo = options.halo_radius_px > 0 ? HaloFactor(guide8, options.halo_radius_px) : cv::Mat();
  // The solve grid: above auto_solve_max_pixels the fit runs on a k-times reduced grid (block
  // means of w and w d, the guide's block mean as guide), with the smoothness and the ridge
  // scaled to the same reach in full-resolution pixels, and comes back by joint bilateral
  // upsampling with the full-resolution guide: FGS's cost is linear in the pixels and the fit is
  // smooth wherever the guide is, so the reduced grid loses little but across fine structure.
  const int k = DenseSolveDownscale(depth_um.size(), options);
  const cv::Size solve_size((cols + k - 1) / k, (rows + k - 1) / k);

  // Weights: the measured pixels' confidence (floored so that a measured pixel always counts),
  // 0 where nothing was measured. One parallel pass over the solve grid's rows of blocks: the
  // blocks' weight sums and weighted depth sums, and the measured range, sum and count.
  struct Stats {
    double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity(), sum = 0;
    int64_t n = 0;
  };
  std::vector<Stats> part(static_cast<size_t>(solve_size.height));
  cv::Mat w(solve_size, CV_32FC1), wz(solve_size, CV_64FC1);
  cv::parallel_for_(cv::Range(0, solve_size.height), [&](const cv::Range& range) {
    std::vector<double> sw(size_t(solve_size.width)), swz(size_t(solve_size.width)), cnt(size_t(solve_size.width));
    for (int by = range.start; by < range.end; ++by) {
      std::fill(sw.begin(), sw.end(), 0.0);
      std::fill(swz.begin(), swz.end(), 0.0);
      std::fill(cnt.begin(), cnt.end(), 0.0);
      Stats st;
      for (int y = by * k; y < std::min(rows, (by + 1) * k); ++y) {
        const float* z = depth_um.ptr<float>(y);
        const float* c = confidence.empty() ? nullptr : confidence.ptr<float>(y);
        const float* h = halo.empty() ? nullptr : halo.ptr<float>(y);
        for (int x = 0; x < cols; ++x) {
          const size_t bx = size_t(x / k);
          cnt[bx] += 1.0;
          if (!(z[x] == z[x])) continue;
          float a = c ? std::min(std::max(c[x], 1e-3f), 1.f) : 1.f;
          if (h) a *= h[x];
          sw[bx] += a;
          swz[bx] += double(a) * z[x];
          st.lo = std::min(st.lo, double(z[x]));
          st.hi = std::max(st.hi, double(z[x]));
          st.sum += z[x];
          ++st.n;
        }
      }
      float* pw = w.ptr<float>(by);
      double* pz = wz.ptr<double>(by);
      for (int bx = 0; bx < solve_size.width; ++bx) {
        pw[bx] = float(sw[size_t(bx)] / cnt[size_t(bx)]);
        pz[bx] = sw[size_t(bx)] > 0.0 ? swz[size_t(bx)] / sw[size_t(bx)] : 0.0;
      }
      part[size_t(by)] = st;
    }
  });
  Stats all;
  for (const Stats& st : part) {
    all.lo = std::min(all.lo, st.lo);
    all.hi = std::max(all.hi, st.hi);
    all.sum += st.sum;
    all.n += st.n;
  }
  DenseDepth out;
  if (all.n == 0) {
    out.depth_um = depth_um.clone();
    out.inferred = cv::Mat(depth_um.size(), CV_8UC1, cv::Scalar(255));
    out.support = cv::Mat(depth_um.size(), CV_32FC1, cv::Scalar(0));
    out.agreement = out.support.clone();
    out.spread_um = out.support.clone();
    return out;
  }
  const double lo_um = all.lo, hi_um = all.hi, mean_um = all.sum / double(all.n);
  // Depth relative to its mean so that the float filter keeps its precision.
  cv::Mat centred(solve_size, CV_32FC1);
  for (int by = 0; by < solve_size.height; ++by) {
    const float* pw = w.ptr<float>(by);
    const double* pz = wz.ptr<double>(by);
    float* c = centred.ptr<float>(by);
    for (int bx = 0; bx < solve_size.width; ++bx) c[bx] = pw[bx] > 0.f ? float(pz[bx] - mean_um) : 0.f;
  }
  cv::Mat guide_s = k == 1 ? guide8 : BlockMean(guide8, k, solve_size);
  const cv::Mat measured_s = w > 0.f;
  const cv::Mat w_init = w;
  const double lambda = options.lambda / double(k * k), ridge = options.plane_ridge_px / double(k);

  cv::Ptr<cv::ximgproc::FastGlobalSmootherFilter> fgs =
      cv::ximgproc::createFastGlobalSmootherFilter(guide_s, lambda, options.sigma_color);
  cv::Mat fit, den, spread;
  // The Cauchy scale from the measured pixels' residuals to the fit: robust_scale x 1.4826 x
  // their median absolute value, at least 1e-3 of the measured depth range.
  auto CauchyScale = [&](double multiple) {
    std::vector<float> abs_res;
    abs_res.reserve(size_t(cv::countNonZero(measured_s)));
    for (int y = 0; y < fit.rows; ++y) {
      const uint8_t* m = measured_s.ptr<uint8_t>(y);
      const float *c = centred.ptr<float>(y), *f = fit.ptr<float>(y);
      for (int x = 0; x < fit.cols; ++x)
        if (m[x]) abs_res.push_back(std::abs(c[x] - f[x]));
    }
    std::nth_element(abs_res.begin(), abs_res.begin() + abs_res.size() / 2, abs_res.end());
    const double sigma = 1.4826 * abs_res[abs_res.size() / 2];
    return std::max(multiple * sigma, 1e-3 * std::max(hi_um - lo_um, 1e-30));
  };
  for (int it = 0;; ++it) {
    Fit(*fgs, centred, w, options.local_planes, ridge, &fit, &den,
        it == options.robust_iterations ? &spread : nullptr);
    if (it == options.robust_iterations) break;
    const double cauchy = CauchyScale(options.robust_scale);
    w = cv::Mat(w_init.size(), CV_32FC1);
    const float inv = float(1.0 / cauchy);
    for (int y = 0; y < fit.rows; ++y) {
      const float *c = centred.ptr<float>(y), *f = fit.ptr<float>(y), *a = w_init.ptr<float>(y);
      float* b = w.ptr<float>(y);
      for (int x = 0; x < fit.cols; ++x) {
        const float r = (c[x] - f[x]) * inv;
        b[x] = a[x] / (1.f + r * r);
      }
    }
  }
  // Agreement and the outlier test against the final edge-aware fit.
  const double cauchy = CauchyScale(options.robust_scale);
  // The outlier test: with the robust fit at its Cauchy scale, else at reject_scale (0: none).
  const bool reject = options.robust_iterations > 0 || options.reject_scale > 0.0;
  const double reject_limit = options.robust_iterations > 0 ? cauchy
                              : options.reject_scale > 0.0 ? CauchyScale(options.reject_scale)
                                                           : 1.0;
  // Residuals (robust fit, the outlier test) refer to the edge-aware fit alone; the fallback
  // only takes over where that fit has no support: fit = t fit + (1 - t) fallback.
  cv::Mat fit_edge = fit, reach = den;  // reach: where either fit has support
  if (options.fallback_support > 0.0) {
    cv::Ptr<cv::ximgproc::FastGlobalSmootherFilter> wide =
        cv::ximgproc::createFastGlobalSmootherFilter(guide_s, lambda, options.fallback_sigma_color);
    cv::Mat fit_wide, den_wide;
    Fit(*wide, centred, w, options.local_planes, ridge, &fit_wide, &den_wide);
    cv::Mat seg;
    if (options.segment_planes) {
      seg = SegmentPlanes(guide_s, centred, w, options.segment_gradient, std::max(1, options.segment_band_px / k),
                          std::max(16, int(options.segment_min_fraction * double(solve_size.area()))),
                          options.plane_ridge_px / k, options.robust_scale, 1e-3 * std::max(hi_um - lo_um, 1e-30));
    }
    // Relative support r = F(w) / F_wide(w): about 1 wherever measurements are spread alike for
    // both (sparse or dense), near 0 inside a region the edges wall off from them.
    fit = cv::Mat(solve_size, CV_32FC1);
    reach = cv::Mat(solve_size, CV_32FC1);
    const float tau2 = float(options.fallback_support * options.fallback_support);
    for (int y = 0; y < solve_size.height; ++y) {
      const float *fe = fit_edge.ptr<float>(y), *fw = fit_wide.ptr<float>(y), *d = den.ptr<float>(y),
                  *dw = den_wide.ptr<float>(y);
      float *f = fit.ptr<float>(y), *r = reach.ptr<float>(y);
      const float* sp = seg.empty() ? nullptr : seg.ptr<float>(y);
      for (int x = 0; x < solve_size.width; ++x) {
        const float rel = d[x] / std::max(dw[x], 1e-30f), rel2 = rel * rel;
        float t = rel2 / (rel2 + tau2);
        // A flat segment's plane stands in for the fallback on it.
        const bool on_segment = sp && sp[x] == sp[x];
        if (on_segment && options.segment_override) t = 0.f;
        f[x] = t * fe[x] + (1.f - t) * (on_segment ? sp[x] : fw[x]);
        r[x] = std::max(d[x], dw[x]);
      }
    }
  }

  double max_den = 0.0;
  cv::minMaxLoc(reach, nullptr, &max_den);
  const float min_den = float(1e-6 * max_den);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  out.depth_um.create(depth_um.size(), CV_32FC1);
  out.inferred.create(depth_um.size(), CV_8UC1);
  out.support.create(depth_um.size(), CV_32FC1);
  out.agreement.create(depth_um.size(), CV_32FC1);
  out.spread_um.create(depth_um.size(), CV_32FC1);
  // Joint bilateral upsampling (k > 1): the 2 x 2 solve-grid neighbours of a pixel, bilinear
  // weights times a Gaussian of the colour difference between the pixel's guide and the
  // neighbour's block mean, so that a pixel takes the fit of the side of an edge it belongs to.
  // The five fields the final pass reads, interleaved: fit, edge-aware fit, support, reach, spread.
  using Vec5f = cv::Vec<float, 5>;
  cv::Mat fields;
  cv::merge(std::vector<cv::Mat>{fit, fit_edge, den, reach, spread}, fields);
  const int channels = guide8.channels();
  const double inv_two_s2 = 1.0 / (2.0 * options.upsample_sigma_color * options.upsample_sigma_color);
  float range_lut[511];  // the Gaussian of one channel's difference, -255..255
  for (int d = -255; d <= 255; ++d) range_lut[d + 255] = float(std::exp(-double(d * d) * inv_two_s2));
  // Per column: the two blocks whose centres bracket it and their bilinear weights.
  struct Tap {
    int i0, i1;
    float w0, w1;
  };
  auto Taps = [&](int n, int blocks) {
    std::vector<Tap> t(static_cast<size_t>(n));
    for (int x = 0; x < n; ++x) {
      const float c = std::max(0.f, (float(x) - 0.5f * float(k - 1)) / float(k));
      const int i0 = std::min(int(c), blocks - 1), i1 = std::min(i0 + 1, blocks - 1);
      const float f = i1 == i0 ? 0.f : c - float(i0);
      t[size_t(x)] = {i0, i1, 1.f - f, f};
    }
    return t;
  };
  const std::vector<Tap> col_taps = Taps(cols, solve_size.width), row_taps = Taps(rows, solve_size.height);
  const float mean_f = float(mean_um), lo_f = float(lo_um), hi_f = float(hi_um), inv_cauchy = float(1.0 / cauchy);
  const float inv_limit = float(1.0 / reject_limit);
  std::atomic<bool> unreached{false};
  cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range) {
    for (int y = range.start; y < range.end; ++y) {
      const float* z = depth_um.ptr<float>(y);
      const uint8_t* g = guide8.ptr<uint8_t>(y);
      float* o = out.depth_um.ptr<float>(y);
      uint8_t* inf = out.inferred.ptr<uint8_t>(y);
      float* agree = out.agreement.ptr<float>(y);
      float* sup = out.support.ptr<float>(y);
      float* spr = out.spread_um.ptr<float>(y);
      const Tap& ty = row_taps[size_t(y)];
      const Vec5f* fr[2] = {fields.ptr<Vec5f>(k == 1 ? y : ty.i0), fields.ptr<Vec5f>(k == 1 ? y : ty.i1)};
      const uint8_t* gr[2] = {guide_s.ptr<uint8_t>(k == 1 ? y : ty.i0), guide_s.ptr<uint8_t>(k == 1 ? y : ty.i1)};
      const float wy[2] = {ty.w0, ty.w1};
      bool row_unreached = false;
      for (int x = 0; x < cols; ++x) {
        const bool m = z[x] == z[x];
        const bool kept = options.keep_measured && m;
        // f, fe, support, reach; a kept measurement needs only fe (agreement, outlier test)
        // and the support.
        float f, fe, dn, rc, sd;
        if (k == 1) {
          const Vec5f& v = fr[0][x];
          f = v[0], fe = v[1], dn = v[2], rc = v[3], sd = v[4];
        } else {
          const Tap& tx = col_taps[size_t(x)];
          const Vec5f* q[4] = {fr[0] + tx.i0, fr[0] + tx.i1, fr[1] + tx.i0, fr[1] + tx.i1};
          const uint8_t* gq[4] = {gr[0] + tx.i0 * channels, gr[0] + tx.i1 * channels, gr[1] + tx.i0 * channels,
                                  gr[1] + tx.i1 * channels};
          const float bl[4] = {wy[0] * tx.w0, wy[0] * tx.w1, wy[1] * tx.w0, wy[1] * tx.w1};
          const uint8_t* gp = g + x * channels;
          float wt[4], sw = 0.f;
          for (int t = 0; t < 4; ++t) {
            float range_w = range_lut[int(gp[0]) - int(gq[t][0]) + 255];
            for (int ch = 1; ch < channels; ++ch) range_w *= range_lut[int(gp[ch]) - int(gq[t][ch]) + 255];
            // Bilinear weight, floored so that a pixel unlike all four still gets their mean.
            wt[t] = (bl[t] + 1e-3f) * range_w + 1e-20f;
            sw += wt[t];
          }
          const float inv = 1.f / sw;
          fe = inv * (wt[0] * (*q[0])[1] + wt[1] * (*q[1])[1] + wt[2] * (*q[2])[1] + wt[3] * (*q[3])[1]);
          dn = inv * (wt[0] * (*q[0])[2] + wt[1] * (*q[1])[2] + wt[2] * (*q[2])[2] + wt[3] * (*q[3])[2]);
          sd = inv * (wt[0] * (*q[0])[4] + wt[1] * (*q[1])[4] + wt[2] * (*q[2])[4] + wt[3] * (*q[3])[4]);
          if (kept && !reject) {
            f = fe;
            rc = dn;
          } else {
            f = inv * (wt[0] * (*q[0])[0] + wt[1] * (*q[1])[0] + wt[2] * (*q[2])[0] + wt[3] * (*q[3])[0]);
            rc = inv * (wt[0] * (*q[0])[3] + wt[1] * (*q[1])[3] + wt[2] * (*q[2])[3] + wt[3] * (*q[3])[3]);
          }
        }
        sup[x] = std::min(std::max(dn, 0.f), 1.f);
        spr[x] = sd;
        const float c = m ? z[x] - mean_f : 0.f;
        const float r = (c - fe) * inv_cauchy;
        const bool outlier = reject && m && std::abs((c - fe) * inv_limit) > 1.f;
        agree[x] = m ? 1.f / (1.f + r * r) : 0.f;
        if (kept && (!outlier || options.keep_rejected_depth)) {
          o[x] = z[x];
          inf[x] = outlier ? 255 : 0;
        } else if (rc > min_den) {
          // A plane extrapolated far from its support can overshoot: no deeper or nearer than
          // anything measured.
          o[x] = std::clamp(f + mean_f, lo_f, hi_f);
          inf[x] = m && !outlier ? 0 : 255;
        } else {
          o[x] = nan;
          inf[x] = 255;
          row_unreached = true;
        }
      }
      if (row_unreached) unreached = true;
    }
  });
  if (unreached) {
    INSPECT_ASSIGN_OR_RETURN(out.depth_um, FillDepth(out.depth_um, cv::Mat(), guide, DepthFillOptions{}));
  }
  return out;
}

StatusOr<cv::Mat> DensifyDepth(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& guide,
                               const DenseDepthOptions& options) {
  INSPECT_ASSIGN_OR_RETURN(DenseDepth d, DensifyDepthWithSupport(depth_um, confidence, guide, options));
  return d.depth_um;
}

}  // namespace inspection
