// Residual of a local least-squares plane fit of the depth map, by sliding box sums
// (core/depth_consistency.h).
// For the window W around p with n pixels: var_d = <d^2> - <d>^2, c_x = <x d> - <x><d>,
// c_y = <y d> - <y><d>; the window is a Cartesian product of its rows and columns (also where it
// is mirrored at the border), so cov(x, y) = 0 and the plane's residual variance is
// var_d - c_x^2 / var_x - c_y^2 / var_y.
#include "core/depth_consistency.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>

namespace inspection {
namespace {

constexpr int kBorder = cv::BORDER_REFLECT_101;

// Mean and variance of the coordinates a window of radius r centred at each position of a line
// of length len covers, mirrored like the box filter.
void CoordinateStats(int len, int r, std::vector<double>* mean, std::vector<double>* var) {
  mean->assign(size_t(len), 0.0);
  var->assign(size_t(len), 0.0);
  for (int p = 0; p < len; ++p) {
    double s = 0, s2 = 0;
    for (int k = -r; k <= r; ++k) {
      const double c = cv::borderInterpolate(p + k, len, kBorder);
      s += c;
      s2 += c * c;
    }
    const double n = 2.0 * r + 1.0;
    (*mean)[size_t(p)] = s / n;
    (*var)[size_t(p)] = std::max(s2 / n - (s / n) * (s / n), 0.0);
  }
}

}  // namespace

Status DepthConsistencyOptions::Validate() const {
  if (radius_px < 0 || radius_px > 31) {
    return Status::InvalidArgument("consistency radius_px " + std::to_string(radius_px) + " must be 0 (auto)..31");
  }
  if (!(max_residual_z_steps > 0.0) || !std::isfinite(max_residual_z_steps)) {
    return Status::InvalidArgument("consistency max_residual_z_steps must be > 0");
  }
  return Status::Ok();
}

StatusOr<cv::Mat> LocalDepthResidual(const cv::Mat& raw_depth_um, int radius_px) {
  if (raw_depth_um.empty() || raw_depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("raw_depth_um must be CV_32FC1");
  }
  if (radius_px < 1 || radius_px > 31) return Status::InvalidArgument("radius_px must be 1..31");
  // Mirroring needs the window to fit inside the image once.
  const int r = std::min(radius_px, std::min(raw_depth_um.rows, raw_depth_um.cols) - 1);
  cv::Mat out(raw_depth_um.size(), CV_32FC1, cv::Scalar(0.f));
  if (r < 1) return out;

  // Sliding window sums of d, d^2, x d, y d and the NaN count in double, with O(width) state:
  // column sums over the window's rows are updated by one row in and one row out, then summed
  // along the row with a prefix sum. Depth is centred on its mean and coordinates on the image
  // centre, so the differences of sums below keep their precision.
  const int w = raw_depth_um.cols, h = raw_depth_um.rows;
  const cv::Mat finite = raw_depth_um == raw_depth_um;
  const double centre = cv::countNonZero(finite) > 0 ? cv::mean(raw_depth_um, finite)[0] : 0.0;
  const double cx0 = 0.5 * (w - 1), cy0 = 0.5 * (h - 1);
  constexpr int kQ = 5;  // d, d^2, x d, y d, NaN
  std::vector<double> mean_x, var_x, mean_y, var_y;
  CoordinateStats(w, r, &mean_x, &var_x);
  CoordinateStats(h, r, &mean_y, &var_y);
  const double n = double(2 * r + 1) * (2 * r + 1);
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<int> xmap(size_t(w + 2 * r));  // extended position -> mirrored column
  for (int i = 0; i < w + 2 * r; ++i) xmap[size_t(i)] = cv::borderInterpolate(i - r, w, kBorder);

  // Bands of rows in parallel, each with its own column sums (started at its first row).
  cv::parallel_for_(
      cv::Range(0, h),
      [&](const cv::Range& band) {
        std::vector<double> col(size_t(kQ) * w, 0.0), prefix(size_t(kQ) * (w + 2 * r + 1), 0.0);
        auto add_row = [&](int row, double sign) {
          const float* s = raw_depth_um.ptr<float>(row);
          const double yc = row - cy0;
          for (int x = 0; x < w; ++x) {
            double* c = &col[size_t(kQ) * x];
            if (std::isfinite(s[x])) {
              const double d = s[x] - centre;
              c[0] += sign * d;
              c[1] += sign * d * d;
              c[2] += sign * (x - cx0) * d;
              c[3] += sign * yc * d;
            } else {
              c[4] += sign;
            }
          }
        };
        for (int k = band.start - r; k <= band.start + r; ++k) add_row(cv::borderInterpolate(k, h, kBorder), 1.0);
        for (int y = band.start; y < band.end; ++y) {
          if (y > band.start) {
            add_row(cv::borderInterpolate(y + r, h, kBorder), 1.0);
            add_row(cv::borderInterpolate(y - r - 1, h, kBorder), -1.0);
          }
          for (int i = 0; i < w + 2 * r; ++i) {  // prefix[i + 1] = sum of col over extended positions 0..i
            const double* c = &col[size_t(kQ) * xmap[size_t(i)]];
            const double* p = &prefix[size_t(kQ) * i];
            double* p1 = &prefix[size_t(kQ) * (i + 1)];
            for (int q = 0; q < kQ; ++q) p1[q] = p[q] + c[q];
          }
          float* o = out.ptr<float>(y);
          const double my = mean_y[size_t(y)] - cy0, vy = var_y[size_t(y)];
          for (int x = 0; x < w; ++x) {
            const double* hi = &prefix[size_t(kQ) * (x + 2 * r + 1)];
            const double* lo = &prefix[size_t(kQ) * x];
            if (hi[4] - lo[4] > 0.5) {
              o[x] = inf;
              continue;
            }
            const double m = (hi[0] - lo[0]) / n;
            const double var_d = (hi[1] - lo[1]) / n - m * m;
            const double cx = (hi[2] - lo[2]) / n - (mean_x[size_t(x)] - cx0) * m;
            const double cy = (hi[3] - lo[3]) / n - my * m;
            const double res = var_d - cx * cx / var_x[size_t(x)] - cy * cy / vy;
            o[x] = float(std::sqrt(std::max(res, 0.0)));
          }
        }
      },
      4.0);  // 4 bands: each restarts its sums (2r + 1 rows), negligible
  return out;
}

StatusOr<cv::Mat> RejectInconsistentDepth(const cv::Mat& depth_um, const cv::Mat& raw_depth_um, double z_step_um,
                                          int focus_window_px, const DepthConsistencyOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.type() != CV_32FC1 || depth_um.size() != raw_depth_um.size()) {
    return Status::InvalidArgument("depth_um must be CV_32FC1 of raw_depth_um's size");
  }
  if (!(z_step_um > 0.0) || !std::isfinite(z_step_um)) return Status::InvalidArgument("z_step_um must be > 0");
  const int radius = options.radius_px > 0 ? options.radius_px : DefaultConsistencyRadius(focus_window_px);
  INSPECT_ASSIGN_OR_RETURN(cv::Mat residual, LocalDepthResidual(raw_depth_um, std::clamp(radius, 1, 31)));
  cv::Mat out = depth_um.clone();
  out.setTo(std::numeric_limits<float>::quiet_NaN(), residual > options.max_residual_z_steps * z_step_um);
  return out;
}

double MedianZStep(const std::vector<double>& z_um) {
  if (z_um.size() < 2) return 0.0;
  std::vector<double> steps;
  for (size_t i = 1; i < z_um.size(); ++i) steps.push_back(std::abs(z_um[i] - z_um[i - 1]));
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  return steps[steps.size() / 2];
}

}  // namespace inspection
