// ISO 16610-61 areal Gaussian filter by normalised convolution (missing pixels and region edges).
#include "core/metrology/areal_filter.h"

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <string>

namespace inspection {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Sampled 1D weighting function out to +-cutoff, normalised to sum 1 (CV_64F column).
cv::Mat GaussianKernel(double cutoff_um, double pixel_size_um) {
  const double a_lc = GaussianFilterAlpha() * cutoff_um;
  const int radius = std::max(1, int(std::ceil(cutoff_um / pixel_size_um)));
  cv::Mat k(2 * radius + 1, 1, CV_64F);
  double sum = 0.0;
  for (int i = -radius; i <= radius; ++i) {
    const double x = i * pixel_size_um;
    const double w = std::exp(-kPi * (x / a_lc) * (x / a_lc));
    k.at<double>(i + radius) = w;
    sum += w;
  }
  k /= sum;
  return k;
}

}  // namespace

double GaussianFilterAlpha() { return std::sqrt(std::log(2.0) / kPi); }

double GaussianFilterSigmaUm(double cutoff_um) { return GaussianFilterAlpha() * cutoff_um / std::sqrt(2.0 * kPi); }

double GaussianMeanTransmission(double cutoff_um, double wavelength_um) {
  const double r = GaussianFilterAlpha() * cutoff_um / wavelength_um;
  return std::exp(-kPi * r * r);
}

namespace {

// Separable blur (rows then columns) with a constant zero border. Short kernels run direct in
// float (exact to ~1e-7 relative, and 10x faster than double); long ones in double, where
// filter2D switches to a DFT (O(N log N), ~0.1 s for 1024 x 768 whatever the cut-off), whose
// rounding float would raise to ~1e-6 of the map's range.
constexpr int kDirectFloatMaxTaps = 127;

cv::Mat SeparableBlur(const cv::Mat& in, const cv::Mat& kernel) {
  const int depth = kernel.rows <= kDirectFloatMaxTaps ? CV_32F : CV_64F;
  cv::Mat k, src, tmp, res;
  kernel.convertTo(k, depth);
  in.convertTo(src, depth);
  cv::filter2D(src, tmp, depth, k.t(), cv::Point(-1, -1), 0.0, cv::BORDER_CONSTANT);
  cv::filter2D(tmp, res, depth, k, cv::Point(-1, -1), 0.0, cv::BORDER_CONSTANT);
  return res;
}

}  // namespace

StatusOr<GaussianAreaFilter> GaussianAreaFilter::Create(const cv::Mat& usable, double pixel_size_um, double cutoff_um) {
  if (usable.empty() || usable.type() != CV_8UC1) return Status::InvalidArgument("filter mask must be a CV_8UC1 image");
  if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um)) {
    return Status::InvalidArgument("pixel_size_um must be > 0");
  }
  if (!(cutoff_um > 0.0) || !std::isfinite(cutoff_um)) {
    return Status::InvalidArgument("filter cut-off must be > 0 um, got " + std::to_string(cutoff_um));
  }
  GaussianAreaFilter f;
  f.usable_ = usable.clone();
  f.kernel_ = GaussianKernel(cutoff_um, pixel_size_um);
  const cv::Rect box = cv::boundingRect(usable);
  if (box.empty()) return f;
  const int radius = f.kernel_.rows / 2;
  // Only the usable pixels' bounding box matters: outside it the weights see zeros.
  f.pad_box_ =
      (box + cv::Size(2 * radius, 2 * radius) - cv::Point(radius, radius)) & cv::Rect(0, 0, usable.cols, usable.rows);
  cv::Mat m;
  usable(f.pad_box_).convertTo(m, CV_64F, 1.0 / 255.0);
  cv::threshold(m, m, 0.0, 1.0, cv::THRESH_BINARY);  // any non-zero mask value counts as 1
  f.weight_sum_ = SeparableBlur(m, f.kernel_);
  f.weight_sum_.convertTo(f.weight_sum_, CV_64F);
  return f;
}

cv::Mat GaussianAreaFilter::MeanSurface(const cv::Mat& surface_um) const {
  cv::Mat out(usable_.size(), CV_32FC1, cv::Scalar(std::nanf("")));
  if (pad_box_.empty()) return out;
  // z relative to the usable pixels' mean, so the sums keep their precision.
  const double z_ref = cv::mean(surface_um, usable_)[0];
  cv::Mat zm(pad_box_.size(), CV_64F, cv::Scalar(0.0));
  for (int row = 0; row < pad_box_.height; ++row) {
    const float* s = surface_um.ptr<float>(row + pad_box_.y) + pad_box_.x;
    const uint8_t* u = usable_.ptr<uint8_t>(row + pad_box_.y) + pad_box_.x;
    double* pz = zm.ptr<double>(row);
    for (int col = 0; col < pad_box_.width; ++col) {
      if (u[col] && std::isfinite(s[col])) pz[col] = double(s[col]) - z_ref;
    }
  }
  cv::Mat num = SeparableBlur(zm, kernel_);
  num.convertTo(num, CV_64F);
  for (int row = 0; row < pad_box_.height; ++row) {
    const uint8_t* u = usable_.ptr<uint8_t>(row + pad_box_.y) + pad_box_.x;
    const double* pn = num.ptr<double>(row);
    const double* pd = weight_sum_.ptr<double>(row);
    float* o = out.ptr<float>(row + pad_box_.y) + pad_box_.x;
    for (int col = 0; col < pad_box_.width; ++col) {
      if (u[col] && pd[col] > 0.0) o[col] = float(pn[col] / pd[col] + z_ref);
    }
  }
  return out;
}

StatusOr<cv::Mat> GaussianMeanSurface(const cv::Mat& surface_um, const cv::Mat& mask, double pixel_size_um,
                                      double cutoff_um) {
  if (surface_um.empty() || surface_um.type() != CV_32FC1) {
    return Status::InvalidArgument("surface must be a non-empty CV_32FC1 image");
  }
  if (mask.type() != CV_8UC1 || mask.size() != surface_um.size()) {
    return Status::InvalidArgument("mask must be CV_8UC1 of the surface's size");
  }
  INSPECT_ASSIGN_OR_RETURN(GaussianAreaFilter f,
                           GaussianAreaFilter::Create(mask & (surface_um == surface_um), pixel_size_um, cutoff_um));
  return f.MeanSurface(surface_um);
}

}  // namespace inspection
