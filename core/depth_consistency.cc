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

cv::Mat BoxMean(const cv::Mat& m, int r) {
  cv::Mat out;
  cv::boxFilter(m, out, CV_64F, cv::Size(2 * r + 1, 2 * r + 1), cv::Point(-1, -1), true, kBorder);
  return out;
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

  // Centred on the mean depth, so the squared sums do not swamp the residual.
  cv::Mat finite = raw_depth_um == raw_depth_um;
  const double centre = cv::countNonZero(finite) > 0 ? cv::mean(raw_depth_um, finite)[0] : 0.0;
  const cv::Mat not_finite = ~finite;
  cv::Mat d, nan;
  raw_depth_um.convertTo(d, CV_64F, 1.0, -centre);
  d.setTo(0.0, not_finite);
  not_finite.convertTo(nan, CV_64F, 1.0 / 255.0);
  cv::Mat xd(d.size(), CV_64F), yd(d.size(), CV_64F);
  for (int y = 0; y < d.rows; ++y) {
    const double* s = d.ptr<double>(y);
    double* px = xd.ptr<double>(y);
    double* py = yd.ptr<double>(y);
    for (int x = 0; x < d.cols; ++x) {
      px[x] = x * s[x];
      py[x] = y * s[x];
    }
  }
  try {
    const cv::Mat md = BoxMean(d, r), mdd = BoxMean(d.mul(d), r), mxd = BoxMean(xd, r), myd = BoxMean(yd, r);
    const cv::Mat mnan = BoxMean(nan, r);
    std::vector<double> mean_x, var_x, mean_y, var_y;
    CoordinateStats(d.cols, r, &mean_x, &var_x);
    CoordinateStats(d.rows, r, &mean_y, &var_y);
    const float inf = std::numeric_limits<float>::infinity();
    for (int y = 0; y < d.rows; ++y) {
      float* o = out.ptr<float>(y);
      for (int x = 0; x < d.cols; ++x) {
        if (mnan.at<double>(y, x) > 1e-9) {
          o[x] = inf;
          continue;
        }
        const double m = md.at<double>(y, x);
        const double var_d = mdd.at<double>(y, x) - m * m;
        const double cx = mxd.at<double>(y, x) - mean_x[size_t(x)] * m;
        const double cy = myd.at<double>(y, x) - mean_y[size_t(y)] * m;
        const double res = var_d - cx * cx / var_x[size_t(x)] - cy * cy / var_y[size_t(y)];
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
