// Defocus PSF model (thesis 4.3.3) and the fast spatially varying blur used for both defocus
// passes of the image formation (thesis 5.1.1, Fig. 5.2).
#include "devices/sim/defocus.h"

#include <algorithm>
#include <cmath>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

constexpr double kLadderRatio = 1.4;   // sigma ratio between rungs
constexpr double kLadderMaxSigmaPx = 90.0;
constexpr int kMaxFactor = 16;

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
  return std::clamp((sigma_px - gaussian_until_sigma_px) / (pillbox_from_sigma_px - gaussian_until_sigma_px),
                    0.0, 1.0);
}

cv::Mat DefocusModel::Kernel(double sigma_px, double shape_sigma_px) const {
  const double w = PillboxWeight(shape_sigma_px);
  const double radius = 2.0 * sigma_px;
  const int half = static_cast<int>(std::ceil(std::max(w < 1.0 ? 3.0 * sigma_px : 0.0, radius + 1.0)));
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
    int f = 1;
    if (s >= 2.8) {
      while (f * 2 <= s / 1.4 && f * 2 <= kMaxFactor) f *= 2;
    }
    factor_.push_back(f);
  }
  layers_.resize(ladder_.size());
}

void SpatiallyVaryingBlur::ComputeLayer(int i) {
  const double sigma = ladder_[i];
  int f = factor_[i];
  int k = 0;
  while ((1 << k) < f) ++k;
  if (k >= static_cast<int>(reduced_.size())) {
    k = static_cast<int>(reduced_.size()) - 1;
    f = 1 << k;
  }
  const bool gaussian = model_.PillboxWeight(sigma) < 0.02;
  // Reduction (box of f x f) and bilinear enlargement add about f^2/4 to the variance.
  const double sigma_low = f == 1 ? sigma : std::sqrt(std::max(sigma * sigma - 0.25 * f * f, 0.09 * f * f)) / f;
  cv::Mat low;
  if (gaussian) {
    cv::GaussianBlur(reduced_[k], low, cv::Size(0, 0), sigma_low, sigma_low, cv::BORDER_REFLECT);
  } else {
    cv::filter2D(reduced_[k], low, CV_32F, model_.Kernel(sigma_low, sigma), cv::Point(-1, -1), 0.0,
                 cv::BORDER_REFLECT);
  }
  if (f == 1) {
    layers_[i] = low;
  } else {
    cv::resize(low, layers_[i], padded_.size(), 0, 0, cv::INTER_LINEAR);
  }
}

void SpatiallyVaryingBlur::Apply(const cv::Mat& src, const cv::Mat& sigma_px, cv::Mat* dst) {
  CV_Assert(src.type() == CV_32FC1 && sigma_px.type() == CV_32FC1 && src.size() == sigma_px.size());
  double smin = 0, smax = 0;
  cv::minMaxLoc(sigma_px, &smin, &smax);
  const int n = static_cast<int>(ladder_.size());
  int i0 = 0;
  while (i0 + 1 < n && ladder_[i0 + 1] <= smin) ++i0;
  int i1 = i0;
  while (i1 + 1 < n && ladder_[i1] < smax) ++i1;

  // Reduced copies of the source, each exactly half of the previous (box 2x2).
  int max_factor = 1;
  for (int i = i0; i <= i1; ++i) max_factor = std::max(max_factor, factor_[i]);
  while (max_factor > 1 && std::min(src.cols, src.rows) / max_factor < 8) max_factor /= 2;
  const int pw = (src.cols + max_factor - 1) / max_factor * max_factor;
  const int ph = (src.rows + max_factor - 1) / max_factor * max_factor;
  cv::copyMakeBorder(src, padded_, 0, ph - src.rows, 0, pw - src.cols, cv::BORDER_REFLECT);
  reduced_.assign(1, padded_);
  for (int f = 2; f <= max_factor; f *= 2) {
    cv::Mat half;
    cv::resize(reduced_.back(), half, cv::Size(pw / f, ph / f), 0, 0, cv::INTER_AREA);
    reduced_.push_back(half);
  }

  cv::parallel_for_(cv::Range(i0, i1 + 1), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) ComputeLayer(i);
  });

  // Per pixel: mix the two rungs bracketing its sigma so that the mixture has its variance.
  std::vector<float> var(n);
  for (int i = 0; i < n; ++i) var[i] = static_cast<float>(ladder_[i] * ladder_[i]);
  dst->create(src.size(), CV_32FC1);
  cv::parallel_for_(cv::Range(0, src.rows), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y) {
      const float* s = sigma_px.ptr<float>(y);
      float* d = dst->ptr<float>(y);
      int i = i0;
      for (int x = 0; x < src.cols; ++x) {
        const float v = s[x] * s[x];
        // Rungs change slowly along a row: walk from the previous pixel's rung.
        while (i > i0 && var[i] > v) --i;
        while (i + 1 < i1 + 1 && var[i + 1] <= v) ++i;
        if (i == i1 || v <= var[i]) {
          d[x] = layers_[i].ptr<float>(y)[x];
        } else {
          const float t = (v - var[i]) / (var[i + 1] - var[i]);
          const float a = layers_[i].ptr<float>(y)[x], b = layers_[i + 1].ptr<float>(y)[x];
          d[x] = a + t * (b - a);
        }
      }
    }
  });
}

}  // namespace inspection
