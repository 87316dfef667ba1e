// ISO 16610-61 areal Gaussian filter by normalised convolution (missing pixels and region edges).
#include "core/areal_filter.h"

#include <cmath>
#include <string>

#include <opencv2/imgproc.hpp>

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

StatusOr<cv::Mat> GaussianMeanSurface(const cv::Mat& surface_um, const cv::Mat& mask, double pixel_size_um,
                                      double cutoff_um) {
  if (surface_um.empty() || surface_um.type() != CV_32FC1) {
    return Status::InvalidArgument("surface must be a non-empty CV_32FC1 image");
  }
  if (mask.type() != CV_8UC1 || mask.size() != surface_um.size()) {
    return Status::InvalidArgument("mask must be CV_8UC1 of the surface's size");
  }
  if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um)) {
    return Status::InvalidArgument("pixel_size_um must be > 0");
  }
  if (!(cutoff_um > 0.0) || !std::isfinite(cutoff_um)) {
    return Status::InvalidArgument("filter cut-off must be > 0 um, got " + std::to_string(cutoff_um));
  }
  cv::Mat out(surface_um.size(), CV_32FC1, cv::Scalar(std::nanf("")));
  // Usable pixels; z relative to their mean so the double sums keep their precision.
  cv::Mat usable = mask & (surface_um == surface_um);
  const cv::Rect box = cv::boundingRect(usable);
  if (box.empty()) return out;
  const double z_ref = cv::mean(surface_um, usable)[0];
  const cv::Mat kernel = GaussianKernel(cutoff_um, pixel_size_um);
  const int radius = kernel.rows / 2;
  // Only the usable pixels' bounding box matters: outside it the weights see zeros.
  const cv::Rect pad_box = (box + cv::Size(2 * radius, 2 * radius) - cv::Point(radius, radius)) &
                           cv::Rect(0, 0, surface_um.cols, surface_um.rows);
  cv::Mat zm(pad_box.size(), CV_64F, cv::Scalar(0.0)), m(pad_box.size(), CV_64F, cv::Scalar(0.0));
  for (int row = 0; row < pad_box.height; ++row) {
    const float* s = surface_um.ptr<float>(row + pad_box.y) + pad_box.x;
    const uint8_t* u = usable.ptr<uint8_t>(row + pad_box.y) + pad_box.x;
    double* pz = zm.ptr<double>(row);
    double* pm = m.ptr<double>(row);
    for (int col = 0; col < pad_box.width; ++col) {
      if (!u[col]) continue;
      pz[col] = double(s[col]) - z_ref;
      pm[col] = 1.0;
    }
  }
  // Separable: rows then columns. filter2D switches to a DFT for long kernels, so large cut-offs
  // cost O(N log N) rather than O(N K). Constant (zero) border: no data beyond the image.
  auto blur = [&](const cv::Mat& in) {
    cv::Mat tmp, res;
    cv::filter2D(in, tmp, CV_64F, kernel.t(), cv::Point(-1, -1), 0.0, cv::BORDER_CONSTANT);
    cv::filter2D(tmp, res, CV_64F, kernel, cv::Point(-1, -1), 0.0, cv::BORDER_CONSTANT);
    return res;
  };
  const cv::Mat num = blur(zm), den = blur(m);
  for (int row = 0; row < pad_box.height; ++row) {
    const uint8_t* u = usable.ptr<uint8_t>(row + pad_box.y) + pad_box.x;
    const double* pn = num.ptr<double>(row);
    const double* pd = den.ptr<double>(row);
    float* o = out.ptr<float>(row + pad_box.y) + pad_box.x;
    for (int col = 0; col < pad_box.width; ++col) {
      if (u[col] && pd[col] > 0.0) o[col] = float(pn[col] / pd[col] + z_ref);
    }
  }
  return out;
}

}  // namespace inspection
