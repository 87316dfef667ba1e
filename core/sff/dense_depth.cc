// Normalised FGS of depth*w and w with the all-in-focus image as guide (core/sff/dense_depth.h).
#include "core/sff/dense_depth.h"

#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/edge_filter.hpp>

#include "core/sff/depth_fill.h"

namespace inspection {

Status DenseDepthOptions::Validate() const {
  if (!(lambda > 0.0 && std::isfinite(lambda))) return Status::InvalidArgument("dense.lambda must be > 0");
  if (!(sigma_color > 0.0 && std::isfinite(sigma_color))) {
    return Status::InvalidArgument("dense.sigma_color must be > 0");
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

}  // namespace

StatusOr<cv::Mat> DensifyDepth(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& guide,
                               const DenseDepthOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.empty() || depth_um.type() != CV_32FC1) return Status::InvalidArgument("depth_um must be CV_32FC1");
  if (!confidence.empty() && (confidence.type() != CV_32FC1 || confidence.size() != depth_um.size())) {
    return Status::InvalidArgument("confidence must be CV_32FC1 of the depth map's size");
  }
  if (guide.empty() || guide.size() != depth_um.size() || (guide.channels() != 1 && guide.channels() != 3)) {
    return Status::InvalidArgument("guide must be the all-in-focus image (1 or 3 channels) of the depth map's size");
  }
  const cv::Mat measured = depth_um == depth_um;
  if (cv::countNonZero(measured) == 0) return depth_um.clone();

  // Weights: the measured pixels' confidence (floored so that a measured pixel always counts),
  // 0 where nothing was measured; depth relative to its mean so the float filter keeps precision.
  cv::Mat w(depth_um.size(), CV_32FC1, cv::Scalar(0));
  if (confidence.empty()) {
    w.setTo(1.f, measured);
  } else {
    cv::Mat floored = cv::max(confidence, 1e-3f);
    floored.copyTo(w, measured);
  }
  const double mean_um = cv::mean(depth_um, measured)[0];
  cv::Mat dw(depth_um.size(), CV_32FC1, cv::Scalar(0));
  cv::Mat centred = depth_um - mean_um;
  centred.copyTo(dw, measured);
  dw = dw.mul(w);

  cv::Ptr<cv::ximgproc::FastGlobalSmootherFilter> fgs =
      cv::ximgproc::createFastGlobalSmootherFilter(Guide8(guide), options.lambda, options.sigma_color);
  cv::Mat num, den;
  fgs->filter(dw, num);
  fgs->filter(w, den);

  double max_den = 0.0;
  cv::minMaxLoc(den, nullptr, &max_den);
  const float min_den = float(1e-6 * max_den);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::Mat dense(depth_um.size(), CV_32FC1);
  bool unreached = false;
  for (int y = 0; y < dense.rows; ++y) {
    const float* n = num.ptr<float>(y);
    const float* d = den.ptr<float>(y);
    const float* z = depth_um.ptr<float>(y);
    float* out = dense.ptr<float>(y);
    for (int x = 0; x < dense.cols; ++x) {
      if (options.keep_measured && z[x] == z[x]) {
        out[x] = z[x];
      } else if (d[x] > min_den) {
        out[x] = float(n[x] / d[x] + mean_um);
      } else {
        out[x] = nan;
        unreached = true;
      }
    }
  }
  if (unreached) {
    INSPECT_ASSIGN_OR_RETURN(dense, FillDepth(dense, cv::Mat(), guide, DepthFillOptions{}));
  }
  return dense;
}

}  // namespace inspection
