#include "core/metrology/depth_metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace inspection {

DepthErrorStats CompareDepth(const cv::Mat& depth_um, const cv::Mat& reference_um, double outlier_threshold_um,
                             int border_px) {
  return CompareDepth(depth_um, reference_um, cv::Mat(), outlier_threshold_um, border_px);
}

DepthErrorStats CompareDepth(const cv::Mat& depth_um, const cv::Mat& reference_um, const cv::Mat& mask,
                             double outlier_threshold_um, int border_px) {
  DepthErrorStats s;
  CV_Assert(depth_um.type() == CV_32FC1 && reference_um.type() == CV_32FC1 && depth_um.size() == reference_um.size());
  CV_Assert(mask.empty() || (mask.type() == CV_8UC1 && mask.size() == depth_um.size()));
  double sum = 0, sum2 = 0, sum_abs = 0;
  size_t outliers = 0, measured = 0, finite = 0;
  for (int y = border_px; y < depth_um.rows - border_px; ++y) {
    const float* d = depth_um.ptr<float>(y);
    const float* r = reference_um.ptr<float>(y);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(y);
    for (int x = border_px; x < depth_um.cols - border_px; ++x) {
      if (m && !m[x]) continue;
      ++measured;
      if (!std::isfinite(d[x])) continue;
      ++finite;
      if (!std::isfinite(r[x])) continue;
      const double e = double(d[x]) - double(r[x]);
      sum += e;
      sum2 += e * e;
      sum_abs += std::abs(e);
      outliers += std::abs(e) > outlier_threshold_um;
      ++s.compared_pixels;
    }
  }
  s.valid_percent = measured ? 100.0 * double(finite) / double(measured) : 0.0;
  if (s.compared_pixels == 0) return s;
  const double n = double(s.compared_pixels);
  s.mean_error_um = sum / n;
  s.rmse_um = std::sqrt(sum2 / n);
  s.stddev_error_um = std::sqrt(std::max(0.0, sum2 / n - s.mean_error_um * s.mean_error_um));
  s.mean_abs_error_um = sum_abs / n;
  s.outlier_percent = 100.0 * double(outliers) / n;
  return s;
}

double LocalOutlierPercent(const cv::Mat& depth_um, double jump_threshold_um, int border_px) {
  CV_Assert(depth_um.type() == CV_32FC1);
  size_t measured = 0, outliers = 0;
  float nb[8];
  for (int y = border_px; y < depth_um.rows - border_px; ++y) {
    const float* d = depth_um.ptr<float>(y);
    for (int x = border_px; x < depth_um.cols - border_px; ++x) {
      if (!std::isfinite(d[x])) continue;
      ++measured;
      int n = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        const int yy = y + dy;
        if (yy < border_px || yy >= depth_um.rows - border_px) continue;
        const float* row = depth_um.ptr<float>(yy);
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx;
          if ((dx == 0 && dy == 0) || xx < border_px || xx >= depth_um.cols - border_px) continue;
          if (std::isfinite(row[xx])) nb[n++] = row[xx];
        }
      }
      if (n < 3) continue;
      std::nth_element(nb, nb + n / 2, nb + n);
      double median = nb[n / 2];
      if (n % 2 == 0) median = 0.5 * (median + double(*std::max_element(nb, nb + n / 2)));
      outliers += std::abs(double(d[x]) - median) > jump_threshold_um;
    }
  }
  return measured ? 100.0 * double(outliers) / double(measured) : 0.0;
}

std::pair<double, double> FiniteRange(const cv::Mat& depth_um) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      if (std::isfinite(d[x])) {
        lo = std::min(lo, double(d[x]));
        hi = std::max(hi, double(d[x]));
      }
    }
  }
  if (lo > hi) return {std::nan(""), std::nan("")};
  return {lo, hi};
}

}  // namespace inspection
