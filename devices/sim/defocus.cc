// Defocus PSF model (thesis 4.3.3) and the fast spatially varying blur used for both defocus
// passes of the image formation (thesis 5.1.1, Fig. 5.2).
#include "devices/sim/defocus.h"

#include <algorithm>
#include <cmath>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

constexpr double kLadderRatio = 1.4;  // sigma ratio between rungs
constexpr double kLadderMaxSigmaPx = 90.0;
constexpr int kMaxFactor = 32;
constexpr double kGaussianOnlyWeight = 0.02;  // below this pillbox weight the PSF is Gaussian
constexpr double kMaxFullResSigmaPx = 3.0;
constexpr double kMaxResidualSigmaPx = 2.0;  // kernel half-size 5 at most
constexpr double kGaussianTruncation = 2.5;  // kernel half-size in sigmas

// PSF sigma left for the kernel on an f-times reduced image: the f x f box reduction and the
// bilinear enlargement together contribute about f^2/4 to the variance (full-res px^2).
double ResidualSigma(double sigma, int f) {
  return std::sqrt(std::max(sigma * sigma - 0.25 * f * f, 0.09 * f * f)) / f;
}

void GaussianBlurTruncated(const cv::Mat& src, cv::Mat* dst, double sigma) {
  const int half = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
  cv::GaussianBlur(src, *dst, cv::Size(2 * half + 1, 2 * half + 1), sigma, sigma, cv::BORDER_REFLECT);
}

}  // namespace

Status DefocusModel::Validate() const {
  if (!(in_focus_sigma_px >= 0.2 && in_focus_sigma_px <= 5.0)) {
    return Status::InvalidArgument("defocus in_focus_sigma_px must be in [0.2, 5]");
  }
  if (!(blur_radius_px_per_um > 0.0 && blur_radius_px_per_um <= 10.0)) {
    return Status::InvalidArgument("defocus blur_radius_px_per_um must be in (0, 10]");
  }
  if (!(gaussian_until_sigma_px >= 0.0 && pillbox_from_sigma_px > gaussian_until_sigma_px)) {
    return Status::InvalidArgument("defocus pillbox_from_sigma_px must exceed gaussian_until_sigma_px >= 0");
  }
  return Status::Ok();
}

double DefocusModel::SigmaPx(double defocus_um) const {
  const double radius = blur_radius_px_per_um * std::abs(defocus_um);
  return std::sqrt(in_focus_sigma_px * in_focus_sigma_px + 0.25 * radius * radius);
}

double DefocusModel::PillboxWeight(double sigma_px) const {
  return std::clamp((sigma_px - gaussian_until_sigma_px) / (pillbox_from_sigma_px - gaussian_until_sigma_px), 0.0, 1.0);
}

cv::Mat DefocusModel::Kernel(double sigma_px, double shape_sigma_px, double truncation_sigmas) const {
  const double w = PillboxWeight(shape_sigma_px);
  const double radius = 2.0 * sigma_px;
  const int half =
      static_cast<int>(std::ceil(std::max(w < 1.0 ? truncation_sigmas * sigma_px : 0.0, radius + 0.5) - 1e-9));
  const int size = 2 * half + 1;
  cv::Mat gauss(size, size, CV_64FC1, cv::Scalar(0)), disk(size, size, CV_64FC1, cv::Scalar(0));
  constexpr int kSub = 4;  // supersampling of the pillbox edge
  for (int y = 0; y < size; ++y) {
    for (int x = 0; x < size; ++x) {
      const double dx = x - half, dy = y - half;
      gauss.at<double>(y, x) = std::exp(-(dx * dx + dy * dy) / (2.0 * sigma_px * sigma_px));
      int inside = 0;
      for (int sy = 0; sy < kSub; ++sy) {
        for (int sx = 0; sx < kSub; ++sx) {
          const double px = dx + (sx + 0.5) / kSub - 0.5, py = dy + (sy + 0.5) / kSub - 0.5;
          inside += (px * px + py * py <= radius * radius) ? 1 : 0;
        }
      }
      disk.at<double>(y, x) = inside;
    }
  }
  gauss /= cv::sum(gauss)[0];
  const double disk_sum = cv::sum(disk)[0];
  if (disk_sum > 0) disk /= disk_sum;
  cv::Mat k = (1.0 - w) * gauss + w * disk;
  cv::Mat k32;
  k.convertTo(k32, CV_32FC1);
  return k32;
}

SpatiallyVaryingBlur::SpatiallyVaryingBlur(const DefocusModel& model) : model_(model) {
  for (double s = model.in_focus_sigma_px; s < kLadderMaxSigmaPx * kLadderRatio; s *= kLadderRatio) {
    ladder_.push_back(s);
    // Full resolution while the PSF is Gaussian (separable, cheap); otherwise the smallest
    // reduction whose residual kernel fits 11x11 (direct convolution, no DFT).
    int f = 1;
    if (model.PillboxWeight(s) >= kGaussianOnlyWeight || s > kMaxFullResSigmaPx) {
      f = 2;
      while (f < kMaxFactor && ResidualSigma(s, f) > kMaxResidualSigmaPx) f *= 2;
    }
    factor_.push_back(f);
  }
  layers_.resize(ladder_.size());
  layer_factor_.assign(ladder_.size(), 1);
}

void SpatiallyVaryingBlur::ComputeLayer(int i) {
  const double sigma = ladder_[i];
  int k = 0;
  while ((1 << k) < factor_[i] && k + 1 < static_cast<int>(reduced_.size())) ++k;
  const int f = 1 << k;
  const double sigma_low = f == 1 ? sigma : ResidualSigma(sigma, f);
  layer_factor_[i] = f;
  if (f == 1) {  // Gaussian at full resolution (separable)
    GaussianBlurTruncated(padded_, &layers_[i], sigma);
    return;
  }
  cv::Mat low;
  if (model_.PillboxWeight(sigma) < kGaussianOnlyWeight) {
    GaussianBlurTruncated(reduced_[k], &low, sigma_low);
  } else {
    cv::filter2D(reduced_[k], low, CV_32F, model_.Kernel(sigma_low, sigma, kGaussianTruncation), cv::Point(-1, -1), 0.0,
                 cv::BORDER_REFLECT);
  }
  layers_[i] = low;  // kept reduced; enlarged row by row while mixing
}

BlurPlan SpatiallyVaryingBlur::Plan(const cv::Mat& sigma_px) const {
  CV_Assert(sigma_px.type() == CV_32FC1);
  BlurPlan plan;
  double smin = 0, smax = 0;
  cv::minMaxLoc(sigma_px, &smin, &smax);
  const int n = static_cast<int>(ladder_.size());
  int i0 = 0;
  while (i0 + 1 < n && ladder_[i0 + 1] <= smin) ++i0;
  int i1 = i0;
  while (i1 + 1 < n && ladder_[i1] < smax) ++i1;
  plan.first_rung = i0;
  plan.last_rung = i1;
  const int m = i1 - i0 + 1;
  std::vector<float> var(m), inv_step(m, 0.0f);
  for (int j = 0; j < m; ++j) var[j] = static_cast<float>(ladder_[i0 + j] * ladder_[i0 + j]);
  for (int j = 0; j + 1 < m; ++j) inv_step[j] = 1.0f / (var[j + 1] - var[j]);
  plan.rung.create(sigma_px.size(), CV_8UC1);
  plan.weight.create(sigma_px.size(), CV_32FC1);
  cv::parallel_for_(cv::Range(0, sigma_px.rows), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y) {
      const float* s = sigma_px.ptr<float>(y);
      uint8_t* rung = plan.rung.ptr<uint8_t>(y);
      float* w = plan.weight.ptr<float>(y);
      int j = 0;
      for (int x = 0; x < sigma_px.cols; ++x) {
        const float v = s[x] * s[x];
        // Rungs change slowly along a row: walk from the previous pixel's rung.
        while (j > 0 && var[j] > v) --j;
        while (j + 1 < m && var[j + 1] <= v) ++j;
        rung[x] = static_cast<uint8_t>(j);
        w[x] = (j + 1 >= m || v <= var[j]) ? 0.0f : (v - var[j]) * inv_step[j];
      }
    }
  });
  return plan;
}

void SpatiallyVaryingBlur::Apply(const cv::Mat& src, const BlurPlan& plan, cv::Mat* dst) {
  CV_Assert(src.type() == CV_32FC1 && src.size() == plan.rung.size());
  const int i0 = plan.first_rung, i1 = plan.last_rung;
  // Reduced copies of the source, each exactly half of the previous (box 2x2).
  int max_factor = 1;
  for (int i = i0; i <= i1; ++i) max_factor = std::max(max_factor, factor_[i]);
  while (max_factor > 1 && std::min(src.cols, src.rows) / max_factor < 8) max_factor /= 2;
  const int pw = (src.cols + max_factor - 1) / max_factor * max_factor;
  const int ph = (src.rows + max_factor - 1) / max_factor * max_factor;
  if (pw == src.cols && ph == src.rows) {
    padded_ = src;  // no copy; released below so a later call never writes into src
  } else {
    cv::copyMakeBorder(src, padded_, 0, ph - src.rows, 0, pw - src.cols, cv::BORDER_REFLECT);
  }
  reduced_.assign(1, padded_);
  for (int f = 2; f <= max_factor; f *= 2) {
    cv::Mat half;
    cv::resize(reduced_.back(), half, cv::Size(pw / f, ph / f), 0, 0, cv::INTER_AREA);
    reduced_.push_back(half);
  }

  // One task per rung, all independent (full-resolution rungs blur the source directly), handed
  // out one at a time so two threads share the expensive full-resolution rungs.
  const int tasks = i1 - i0 + 1;
  cv::parallel_for_(
      cv::Range(0, tasks),
      [&](const cv::Range& r) {
        for (int t = r.start; t < r.end; ++t) ComputeLayer(i0 + t);
      },
      tasks);

  // Bilinear enlargement of reduced rungs (same sampling as cv::resize INTER_LINEAR), done per
  // row into small buffers so no full-size copy of a reduced rung is ever stored. For an exact
  // power-of-two factor f, output pixel f*a + q mixes reduced columns a-1, a (q < f/2) or a,
  // a+1 (q >= f/2) with weights that depend on q only.
  const int m = i1 - i0 + 1;
  std::vector<std::vector<float>> phase_weight(m);
  for (int j = 0; j < m; ++j) {
    const int f = layer_factor_[i0 + j];
    phase_weight[j].resize(f);
    for (int q = 0; q < f; ++q) {
      const float t = (q + 0.5f) / f - 0.5f;  // position relative to column a
      phase_weight[j][q] = t < 0.0f ? 1.0f + t : t;
    }
  }
  // Per pixel: mix the plan's two rungs. Runs of equal rung are long, so the inner loop is a
  // plain vectorisable lerp.
  dst->create(src.size(), CV_32FC1);
  cv::parallel_for_(cv::Range(0, src.rows), [&](const cv::Range& r) {
    std::vector<const float*> rows(m + 1);
    std::vector<std::vector<float>> enlarged(m);
    std::vector<float> column_mix;
    std::vector<int> first(m), last(m);
    for (int y = r.start; y < r.end; ++y) {
      const uint8_t* rung = plan.rung.ptr<uint8_t>(y);
      // Columns where each rung is needed (as the lower or the upper of a pair).
      std::fill(first.begin(), first.end(), src.cols);
      std::fill(last.begin(), last.end(), -1);
      for (int x = 0; x < src.cols; ++x) {
        const int j = rung[x];
        first[j] = std::min(first[j], x);
        last[j] = x;
        if (j + 1 < m) {
          first[j + 1] = std::min(first[j + 1], x);
          last[j + 1] = std::max(last[j + 1], x);
        }
      }
      for (int j = 0; j < m; ++j) {
        if (last[j] < 0) continue;
        const cv::Mat& layer = layers_[i0 + j];
        const int f = layer_factor_[i0 + j];
        if (f == 1) {
          rows[j] = layer.ptr<float>(y);
          continue;
        }
        const float sy = (y + 0.5f) / f - 0.5f;
        int y0 = static_cast<int>(std::floor(sy));
        float wy = sy - y0;
        if (y0 < 0) y0 = 0, wy = 0.0f;
        if (y0 >= layer.rows - 1) y0 = layer.rows - 1, wy = 0.0f;
        const float* r0 = layer.ptr<float>(y0);
        const float* r1 = layer.ptr<float>(std::min(y0 + 1, layer.rows - 1));
        // Vertical mix on the reduced columns the span needs (one replicated column each side),
        // then the horizontal enlargement.
        const int a0 = first[j] / f, a1 = last[j] / f, top = layer.cols - 1;
        column_mix.resize(layer.cols + 2);
        float* c = column_mix.data() + 1;
        for (int a = std::max(a0 - 1, 0); a <= std::min(a1 + 1, top); ++a) c[a] = r0[a] + wy * (r1[a] - r0[a]);
        c[-1] = c[0];
        c[top + 1] = c[top];
        std::vector<float>& out = enlarged[j];
        out.resize(static_cast<size_t>(layer.cols) * f);
        const float* pw = phase_weight[j].data();
        const int half = f / 2;
        for (int a = a0; a <= a1; ++a) {
          const float left = c[a - 1], centre = c[a], right = c[a + 1];
          float* o = out.data() + static_cast<size_t>(a) * f;
          for (int q = 0; q < half; ++q) o[q] = left + pw[q] * (centre - left);
          for (int q = half; q < f; ++q) o[q] = centre + pw[q] * (right - centre);
        }
        rows[j] = out.data();
      }
      rows[m] = rows[m - 1];
      const float* __restrict w = plan.weight.ptr<float>(y);
      float* __restrict d = dst->ptr<float>(y);
      int x = 0;
      while (x < src.cols) {
        const int j = rung[x];
        int end = x + 1;
        while (end < src.cols && rung[end] == j) ++end;
        const float* __restrict a = rows[j];
        const float* __restrict b = rows[j + 1];
        for (int k = x; k < end; ++k) d[k] = a[k] + w[k] * (b[k] - a[k]);
        x = end;
      }
    }
  });
  if (padded_.data == src.data) {
    padded_.release();
    reduced_.clear();
  }
}

void SpatiallyVaryingBlur::ApplyScatter(const cv::Mat& src, const BlurPlan& plan, cv::Mat* dst) {
  CV_Assert(src.type() == CV_32FC1 && src.size() == plan.rung.size());
  const int m = plan.last_rung - plan.first_rung + 1;
  cv::Mat total(src.size(), CV_32FC1, cv::Scalar(0)), part(src.size(), CV_32FC1), blurred;
  BlurPlan one;  // a single rung everywhere
  one.rung = cv::Mat(src.size(), CV_8UC1, cv::Scalar(0));
  one.weight = cv::Mat(src.size(), CV_32FC1, cv::Scalar(0));
  for (int j = 0; j < m; ++j) {
    bool any = false;
    for (int y = 0; y < src.rows; ++y) {
      const float* s = src.ptr<float>(y);
      const uint8_t* r = plan.rung.ptr<uint8_t>(y);
      const float* w = plan.weight.ptr<float>(y);
      float* p = part.ptr<float>(y);
      for (int x = 0; x < src.cols; ++x) {
        const float share = r[x] == j ? 1.0f - w[x] : (r[x] + 1 == j ? w[x] : 0.0f);
        p[x] = share * s[x];
        any = any || share > 0.0f;
      }
    }
    if (!any) continue;
    one.first_rung = one.last_rung = plan.first_rung + j;
    Apply(part, one, &blurred);
    total += blurred;
  }
  *dst = total;
}

}  // namespace inspection
