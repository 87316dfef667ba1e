// Residual of a local least-squares plane fit of the depth map, by sliding box sums
// (core/sff/depth_consistency.h).
// For the window W around p with n pixels: var_d = <d^2> - <d>^2, c_x = <x d> - <x><d>,
// c_y = <y d> - <y><d>; the window is a Cartesian product of its rows and columns (also where it
// is mirrored at the border), so cov(x, y) = 0 and the plane's residual variance is
// var_d - c_x^2 / var_x - c_y^2 / var_y.
#include "core/sff/depth_consistency.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/sff/internal/depth_plane_kernel.h"

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
  if (!(max_window_mixing_z_steps >= 0.0) || !std::isfinite(max_window_mixing_z_steps)) {
    return Status::InvalidArgument("consistency max_window_mixing_z_steps must be >= 0 (0: off)");
  }
  return Status::Ok();
}

StatusOr<cv::Mat> LocalDepthResidual(const cv::Mat& raw_depth_um, int radius_px) {
  LocalDepthPlane plane;
  INSPECT_RETURN_IF_ERROR(FitLocalDepthPlanes(raw_depth_um, radius_px, &plane));
  return plane.residual_um;
}

Status FitLocalDepthPlanes(const cv::Mat& raw_depth_um, int radius_px, LocalDepthPlane* plane) {
  if (raw_depth_um.empty() || raw_depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("raw_depth_um must be CV_32FC1");
  }
  if (radius_px < 1 || radius_px > 31) return Status::InvalidArgument("radius_px must be 1..31");
  // Mirroring needs the window to fit inside the image once.
  const int r = std::min(radius_px, std::min(raw_depth_um.rows, raw_depth_um.cols) - 1);
  plane->residual_um.create(raw_depth_um.size(), CV_32FC1);
  plane->slope_x.create(raw_depth_um.size(), CV_32FC1);
  plane->slope_y.create(raw_depth_um.size(), CV_32FC1);
  cv::Mat& out = plane->residual_um;
  if (r < 1) {
    out.setTo(0.f);
    plane->slope_x.setTo(0.f);
    plane->slope_y.setTo(0.f);
    return Status::Ok();
  }
  // Every pixel is written below, in parallel (so are the new pages' first touches).

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
  std::vector<int> xmap(size_t(w + 2 * r));  // extended position -> mirrored column
  for (int i = 0; i < w + 2 * r; ++i) xmap[size_t(i)] = cv::borderInterpolate(i - r, w, kBorder);

  // The row kernels: per instruction set, picked at run time (core/sff/internal/depth_plane_kernel.h).
  const depth_plane_kernel::PlaneKernels& kernel = depth_plane_kernel::PickPlaneKernels();
  // mean_x relative to the image centre, as the sums' x is.
  std::vector<double> mean_xc(size_t(w), 0.0);
  for (int x = 0; x < w; ++x) mean_xc[size_t(x)] = mean_x[size_t(x)] - cx0;
  // Bands of rows in parallel, each with its own column sums (started at its first row).
  cv::parallel_for_(
      cv::Range(0, h),
      [&](const cv::Range& band) {
        const size_t ext = size_t(w + 2 * r + 1);
        std::vector<double> col(size_t(kQ) * w, 0.0), prefix(size_t(kQ) * ext, 0.0);
        depth_plane_kernel::PlaneSums c, p;
        for (int q = 0; q < kQ; ++q) c.q[q] = &col[size_t(q) * w], p.q[q] = &prefix[size_t(q) * ext];
        auto add_row = [&](int row, double sign) {
          kernel.add_depth_row(raw_depth_um.ptr<float>(row), w, centre, cx0, row - cy0, sign, c.q[0], c.q[1], c.q[2], c.q[3],
                      c.q[4]);
        };
        for (int k = band.start - r; k <= band.start + r; ++k) add_row(cv::borderInterpolate(k, h, kBorder), 1.0);
        for (int y = band.start; y < band.end; ++y) {
          if (y > band.start) {
            add_row(cv::borderInterpolate(y + r, h, kBorder), 1.0);
            add_row(cv::borderInterpolate(y - r - 1, h, kBorder), -1.0);
          }
          // prefix[i + 1] = sum of col over extended positions 0..i; the five running sums in
          // one loop, so their dependency chains overlap.
          {
            double *p0 = p.q[0], *p1 = p.q[1], *p2 = p.q[2], *p3 = p.q[3], *p4 = p.q[4];
            const double *c0 = c.q[0], *c1 = c.q[1], *c2 = c.q[2], *c3 = c.q[3], *c4 = c.q[4];
            for (int i = 0; i < w + 2 * r; ++i) {
              const int xi = xmap[size_t(i)];
              p0[i + 1] = p0[i] + c0[xi];
              p1[i + 1] = p1[i] + c1[xi];
              p2[i + 1] = p2[i] + c2[xi];
              p3[i + 1] = p3[i] + c3[xi];
              p4[i + 1] = p4[i] + c4[xi];
            }
          }
          kernel.plane_row(p, w, r, n, mean_xc.data(), var_x.data(), mean_y[size_t(y)] - cy0, var_y[size_t(y)],
                   out.ptr<float>(y), plane->slope_x.ptr<float>(y), plane->slope_y.ptr<float>(y));
        }
      },
      4.0);  // 4 bands: each restarts its sums (2r + 1 rows), negligible
  return Status::Ok();
}

StatusOr<cv::Mat> FocusEnergyCentroidOffset(const cv::Mat& all_in_focus, int focus_window_px) {
  if (all_in_focus.empty() || (all_in_focus.channels() != 1 && all_in_focus.channels() != 3)) {
    return Status::InvalidArgument("all_in_focus must be a grey or BGR image");
  }
  if (focus_window_px < 3 || focus_window_px % 2 == 0) {
    return Status::InvalidArgument("focus_window_px must be odd and >= 3");
  }
  // Sobel of an 8- or 16-bit image into CV_32F is exact (integer sums far below 2^24), so those
  // are filtered as stored; other depths go through CV_32F as the gradient's own type.
  cv::Mat grey = all_in_focus;
  if (grey.channels() == 3) cv::cvtColor(all_in_focus, grey, cv::COLOR_BGR2GRAY);
  if (grey.depth() != CV_8U && grey.depth() != CV_16U && grey.depth() != CV_32F) grey.convertTo(grey, CV_32F);
  const int rows = grey.rows, cols = grey.cols;
  const int r = focus_window_px / 2;
  cv::Mat ones(1, 2 * r + 1, CV_32F, cv::Scalar(1.f)), ramp(1, 2 * r + 1, CV_32F);
  for (int k = -r; k <= r; ++k) ramp.at<float>(0, k + r) = float(k);
  // Two passes over bands of rows, in parallel: the gradient energy, then its box sums and the
  // centroid. A band is a view into the whole image, so the filters read the rows beyond it
  // (and mirror only at the image's own border): every pixel is what whole-image filtering gives.
  // Small bands keep the temporaries small (no fresh pages for each full-size intermediate).
  constexpr int kBandRows = 32;
  const int bands = (rows + kBandRows - 1) / kBandRows;
  auto band_rows = [&](int b) { return cv::Range(b * kBandRows, std::min(rows, (b + 1) * kBandRows)); };
  cv::Mat energy(rows, cols, CV_32F);
  cv::parallel_for_(cv::Range(0, bands), [&](const cv::Range& range) {
    cv::Mat gx, gy;
    for (int b = range.start; b < range.end; ++b) {
      const cv::Range band = band_rows(b);
      const cv::Mat src = grey.rowRange(band);
      cv::Sobel(src, gx, CV_32F, 1, 0, 3, 1.0, 0.0, kBorder);
      cv::Sobel(src, gy, CV_32F, 0, 1, 3, 1.0, 0.0, kBorder);
      for (int y = 0; y < src.rows; ++y) {
        const float* a = gx.ptr<float>(y);
        const float* c = gy.ptr<float>(y);
        float* e = energy.ptr<float>(band.start + y);
        for (int x = 0; x < cols; ++x) {
          const float a2 = a[x] * a[x], c2 = c[x] * c[x];
          e[x] = a2 + c2;
        }
      }
    }
  });
  cv::Mat out(rows, cols, CV_32FC2);
  cv::parallel_for_(cv::Range(0, bands), [&](const cv::Range& range) {
    cv::Mat sum, mx, my;
    for (int b = range.start; b < range.end; ++b) {
      const cv::Range band = band_rows(b);
      const cv::Mat e = energy.rowRange(band);
      cv::sepFilter2D(e, sum, CV_32F, ones, ones, cv::Point(-1, -1), 0.0, kBorder);
      cv::sepFilter2D(e, mx, CV_32F, ramp, ones, cv::Point(-1, -1), 0.0, kBorder);
      cv::sepFilter2D(e, my, CV_32F, ones, ramp, cv::Point(-1, -1), 0.0, kBorder);
      for (int y = 0; y < e.rows; ++y) {
        const float* s = sum.ptr<float>(y);
        const float* px = mx.ptr<float>(y);
        const float* py = my.ptr<float>(y);
        cv::Vec2f* o = out.ptr<cv::Vec2f>(band.start + y);
        for (int x = 0; x < cols; ++x) {
          // 0 where the window holds no gradient (a sum of squares: <= 0 means 0).
          o[x] = s[x] <= 0.f ? cv::Vec2f(0.f, 0.f) : cv::Vec2f(px[x] / s[x], py[x] / s[x]);
        }
      }
    }
  });
  return out;
}

StatusOr<cv::Mat> RejectInconsistentDepth(const cv::Mat& depth_um, const cv::Mat& raw_depth_um, double z_step_um,
                                          int focus_window_px, const DepthConsistencyOptions& options,
                                          const cv::Mat& all_in_focus) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.type() != CV_32FC1 || depth_um.size() != raw_depth_um.size()) {
    return Status::InvalidArgument("depth_um must be CV_32FC1 of raw_depth_um's size");
  }
  if (!(z_step_um > 0.0) || !std::isfinite(z_step_um)) return Status::InvalidArgument("z_step_um must be > 0");
  if (!all_in_focus.empty() && all_in_focus.size() != raw_depth_um.size()) {
    return Status::InvalidArgument("all_in_focus must have raw_depth_um's size");
  }
  const int radius = options.radius_px > 0 ? options.radius_px : DefaultConsistencyRadius(focus_window_px);
  LocalDepthPlane plane;
  INSPECT_RETURN_IF_ERROR(FitLocalDepthPlanes(raw_depth_um, std::clamp(radius, 1, 31), &plane));
  cv::Mat offset;  // the window-mixing check's centroid offsets, when it runs
  if (!all_in_focus.empty() && options.max_window_mixing_z_steps > 0.0 && focus_window_px >= 3) {
    INSPECT_ASSIGN_OR_RETURN(offset, FocusEnergyCentroidOffset(all_in_focus, focus_window_px | 1));
  }
  // Both checks in one pass over bands of rows. The residual limit is compared in float, as
  // cv::compare of a CV_32F image with a scalar does (the scalar rounded to float).
  const float residual_limit = float(options.max_residual_z_steps * z_step_um);
  const double mixing_limit = options.max_window_mixing_z_steps * z_step_um;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::Mat out(depth_um.size(), CV_32FC1);
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const float* d = depth_um.ptr<float>(y);
      const float* res = plane.residual_um.ptr<float>(y);
      float* o = out.ptr<float>(y);
      for (int x = 0; x < out.cols; ++x) o[x] = res[x] > residual_limit ? nan : d[x];
      if (offset.empty()) continue;
      const float* sx = plane.slope_x.ptr<float>(y);
      const float* sy = plane.slope_y.ptr<float>(y);
      const cv::Vec2f* c = offset.ptr<cv::Vec2f>(y);
      for (int x = 0; x < out.cols; ++x) {
        if (std::abs(sx[x] * c[x][0] + sy[x] * c[x][1]) > mixing_limit) o[x] = nan;
      }
    }
  });
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
