// Residual of a local least-squares plane fit of the depth map, by box sums (core/depth_consistency.h).
// For the window W around p with n pixels: var_d = <d^2> - <d>^2, c_x = <x d> - <x><d>,
// c_y = <y d> - <y><d>; the window is a Cartesian product of its rows and columns (also where it
// is mirrored at the border), so cov(x, y) = 0 and the plane's residual variance is
// var_d - c_x^2 / var_x - c_y^2 / var_y.
#include "core/depth_consistency.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

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

  // Float box sums (accumulated in double by OpenCV) of d, d^2, x d and y d in one 4-channel
  // pass; depth centred on its mean and coordinates on the image centre, so the differences of
  // sums below keep their precision.
  const cv::Mat finite = raw_depth_um == raw_depth_um;
  const bool any_nan = cv::countNonZero(finite) != int(raw_depth_um.total());
  const double centre = cv::countNonZero(finite) > 0 ? cv::mean(raw_depth_um, finite)[0] : 0.0;
  const float cx0 = 0.5f * float(raw_depth_um.cols - 1), cy0 = 0.5f * float(raw_depth_um.rows - 1);
  cv::Mat sums(raw_depth_um.size(), CV_32FC4);
  for (int y = 0; y < raw_depth_um.rows; ++y) {
    const float* s = raw_depth_um.ptr<float>(y);
    cv::Vec4f* o = sums.ptr<cv::Vec4f>(y);
    const float yc = float(y) - cy0;
    for (int x = 0; x < raw_depth_um.cols; ++x) {
      const float d = std::isfinite(s[x]) ? float(s[x] - centre) : 0.f;
      o[x] = cv::Vec4f(d, d * d, (float(x) - cx0) * d, yc * d);
    }
  }
  try {
    const cv::Size window(2 * r + 1, 2 * r + 1);
    cv::boxFilter(sums, sums, CV_32F, window, cv::Point(-1, -1), true, kBorder);
    cv::Mat nan_share;
    if (any_nan) {
      cv::Mat nan;
      const cv::Mat not_finite = ~finite;
      not_finite.convertTo(nan, CV_32F, 1.0 / 255.0);
      cv::boxFilter(nan, nan_share, CV_32F, window, cv::Point(-1, -1), true, kBorder);
    }
    std::vector<double> mean_x, var_x, mean_y, var_y;
    CoordinateStats(raw_depth_um.cols, r, &mean_x, &var_x);
    CoordinateStats(raw_depth_um.rows, r, &mean_y, &var_y);
    const float inf = std::numeric_limits<float>::infinity();
    for (int y = 0; y < raw_depth_um.rows; ++y) {
      const cv::Vec4f* m4 = sums.ptr<cv::Vec4f>(y);
      const float* ns = any_nan ? nan_share.ptr<float>(y) : nullptr;
      float* o = out.ptr<float>(y);
      const double my = mean_y[size_t(y)] - cy0, vy = var_y[size_t(y)];
      for (int x = 0; x < raw_depth_um.cols; ++x) {
        if (ns && ns[x] > 1e-6f) {
          o[x] = inf;
          continue;
        }
        const double m = m4[x][0];
        const double var_d = m4[x][1] - m * m;
        const double cx = m4[x][2] - (mean_x[size_t(x)] - cx0) * m;
        const double cy = m4[x][3] - my * m;
        const double res = var_d - cx * cx / var_x[size_t(x)] - cy * cy / vy;
        o[x] = float(std::sqrt(std::max(res, 0.0)));
      }
    }
  } catch (const cv::Exception& e) {
    return Status::Internal(std::string("depth residual failed: ") + e.what());
  }
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
