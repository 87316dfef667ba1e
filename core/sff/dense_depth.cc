// Normalised FGS of weighted depth moments with the all-in-focus image as guide, optionally local
// planes and a robust reweighting (core/sff/dense_depth.h).
#include "core/sff/dense_depth.h"

#include <algorithm>
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
  if (!(robust_scale > 0.0 && std::isfinite(robust_scale))) {
    return Status::InvalidArgument("dense.robust_scale must be > 0");
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

// One weighted fit: fit = the model's value at every pixel, den = F(w).
// One weighted fit: fit = the model's value at every pixel, den = F(w).
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

// One weighted fit: fit = the model's value at every pixel, den = F(w).
void Fit(cv::ximgproc::FastGlobalSmootherFilter& fgs, const cv::Mat& centred, const cv::Mat& w, bool planes, double ridge, cv::Mat* fit,
         cv::Mat* den) {
  const cv::Mat wd = centred.mul(w);  // 0 where unmeasured (w = 0, centred = 0)
  fgs.filter(w, *den);
  cv::Mat num;
  fgs.filter(wd, num);
  if (!planes) {
    *fit = num / cv::max(*den, 1e-30f);
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
  cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range) {
    for (int y = range.start; y < range.end; ++y) {
      const float *m0 = den->ptr<float>(y), *m1 = num.ptr<float>(y), *a_u = mu.ptr<float>(y),
                  *a_v = mv.ptr<float>(y), *a_uu = muu.ptr<float>(y), *a_uv = muv.ptr<float>(y),
                  *a_vv = mvv.ptr<float>(y), *b_u = mdu.ptr<float>(y), *b_v = mdv.ptr<float>(y),
                  *pu = u.ptr<float>(y), *pv = v.ptr<float>(y);
      float* out = fit->ptr<float>(y);
      for (int x = 0; x < cols; ++x) {
        const double s0 = m0[x];
        if (!(s0 > 1e-30)) {
          out[x] = 0.f;
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
          continue;
        }
        const double det_a = b0 * c00 - su * (bu * svv - suv * bv) + sv * (bu * suv - suu * bv);
        out[x] = float(det_a / det);
      }
    }
  });
}

}  // namespace

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
  const cv::Mat measured = depth_um == depth_um;
  DenseDepth out;
  if (cv::countNonZero(measured) == 0) {
    out.depth_um = depth_um.clone();
    out.inferred = cv::Mat(depth_um.size(), CV_8UC1, cv::Scalar(255));
    out.support = cv::Mat(depth_um.size(), CV_32FC1, cv::Scalar(0));
    out.agreement = out.support.clone();
    return out;
  }

  // Weights: the measured pixels' confidence (floored so that a measured pixel always counts),
  // 0 where nothing was measured; depth relative to its mean so the float filter keeps precision.
  cv::Mat w0(depth_um.size(), CV_32FC1, cv::Scalar(0));
  if (confidence.empty()) {
    w0.setTo(1.f, measured);
  } else {
    cv::Mat floored = cv::min(cv::max(confidence, 1e-3f), 1.f);
    floored.copyTo(w0, measured);
  }
  double lo_um = 0, hi_um = 0;
  cv::minMaxLoc(depth_um, &lo_um, &hi_um, nullptr, nullptr, measured);
  const double mean_um = cv::mean(depth_um, measured)[0];
  cv::Mat centred(depth_um.size(), CV_32FC1, cv::Scalar(0));
  cv::Mat(depth_um - mean_um).copyTo(centred, measured);

  const cv::Mat guide8 = Guide8(guide);
  if (options.halo_radius_px > 0) w0 = w0.mul(HaloFactor(guide8, options.halo_radius_px));
  cv::Ptr<cv::ximgproc::FastGlobalSmootherFilter> fgs =
      cv::ximgproc::createFastGlobalSmootherFilter(guide8, options.lambda, options.sigma_color);
  cv::Mat w = w0, fit, den;
  // The Cauchy scale from the measured pixels' residuals to the fit: robust_scale x 1.4826 x
  // their median absolute value, at least 1e-3 of the measured range.
  auto CauchyScale = [&]() {
    std::vector<float> abs_res;
    abs_res.reserve(size_t(cv::countNonZero(measured)));
    for (int y = 0; y < fit.rows; ++y) {
      const uint8_t* m = measured.ptr<uint8_t>(y);
      const float *c = centred.ptr<float>(y), *f = fit.ptr<float>(y);
      for (int x = 0; x < fit.cols; ++x)
        if (m[x]) abs_res.push_back(std::abs(c[x] - f[x]));
    }
    std::nth_element(abs_res.begin(), abs_res.begin() + abs_res.size() / 2, abs_res.end());
    const double sigma = 1.4826 * abs_res[abs_res.size() / 2];
    return std::max(options.robust_scale * sigma, 1e-3 * std::max(hi_um - lo_um, 1e-30));
  };
  for (int it = 0;; ++it) {
    Fit(*fgs, centred, w, options.local_planes, options.plane_ridge_px, &fit, &den);
    if (it == options.robust_iterations) break;
    const double cauchy = CauchyScale();
    w = cv::Mat(w0.size(), CV_32FC1);
    const float inv = float(1.0 / cauchy);
    for (int y = 0; y < fit.rows; ++y) {
      const float *c = centred.ptr<float>(y), *f = fit.ptr<float>(y), *a = w0.ptr<float>(y);
      float* b = w.ptr<float>(y);
      for (int x = 0; x < fit.cols; ++x) {
        const float r = (c[x] - f[x]) * inv;
        b[x] = a[x] / (1.f + r * r);
      }
    }
  }
  // Agreement (and, with the robust fit, the outlier test) against the final edge-aware fit.
  const double cauchy = CauchyScale();
  const bool reject = options.robust_iterations > 0;
  // Residuals (robust fit, the outlier test) refer to the edge-aware fit alone; the fallback
  // only takes over where that fit has no support: fit = t fit + (1 - t) fallback.
  cv::Mat fit_edge = fit, reach = den;  // reach: where either fit has support
  if (options.fallback_support > 0.0) {
    cv::Ptr<cv::ximgproc::FastGlobalSmootherFilter> wide =
        cv::ximgproc::createFastGlobalSmootherFilter(guide8, options.lambda, options.fallback_sigma_color);
    cv::Mat fit_wide, den_wide;
    Fit(*wide, centred, w, options.local_planes, options.plane_ridge_px, &fit_wide, &den_wide);
    // Relative support r = F(w) / F_wide(w): about 1 wherever measurements are spread alike for
    // both (sparse or dense), near 0 inside a region the edges wall off from them.
    const cv::Mat r = den / cv::max(den_wide, 1e-30f);
    const cv::Mat r2 = r.mul(r);
    const float tau = float(options.fallback_support);
    const cv::Mat t = r2 / (r2 + tau * tau);
    fit = t.mul(fit_edge) + (1.0 - t).mul(fit_wide);
    reach = cv::max(den, den_wide);
  }

  double max_den = 0.0;
  cv::minMaxLoc(reach, nullptr, &max_den);
  const float min_den = float(1e-6 * max_den);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  out.depth_um.create(depth_um.size(), CV_32FC1);
  out.inferred.create(depth_um.size(), CV_8UC1);
  out.support = cv::min(cv::max(den, 0.f), 1.f);
  out.agreement = cv::Mat(depth_um.size(), CV_32FC1, cv::Scalar(0));
  bool unreached = false;
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* f = fit.ptr<float>(y);
    const float* d = reach.ptr<float>(y);
    const float* z = depth_um.ptr<float>(y);
    const float* c = centred.ptr<float>(y);
    float* o = out.depth_um.ptr<float>(y);
    uint8_t* inf = out.inferred.ptr<uint8_t>(y);
    float* agree = out.agreement.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      const float fe = fit_edge.at<float>(y, x);
      const bool outlier = reject && std::abs(c[x] - fe) > cauchy;
      if (z[x] == z[x]) {
        const double r = (c[x] - fe) / cauchy;
        agree[x] = float(1.0 / (1.0 + r * r));
      }
      if (options.keep_measured && z[x] == z[x] && !outlier) {
        o[x] = z[x];
        inf[x] = 0;
      } else if (d[x] > min_den) {
        // A plane extrapolated far from its support can overshoot: no deeper or nearer than
        // anything measured.
        o[x] = float(std::clamp(f[x] + mean_um, lo_um, hi_um));
        inf[x] = z[x] == z[x] && !outlier ? 0 : 255;
      } else {
        o[x] = nan;
        inf[x] = 255;
        unreached = true;
      }
    }
  }
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
