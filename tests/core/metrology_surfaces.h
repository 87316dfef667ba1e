// Analytic surfaces with known parameters for the metrology tests (form removal, ISO 25178
// parameters, filters, step heights, uncertainty): height maps in µm on a pixel grid whose pixel
// (col, row) has its centre at ((col + 0.5) p, (row + 0.5) p) µm (core/metrology/surface_roi.h), plus
// noise with the SFF error model's structure (box-correlated) and NaN holes.
#pragma once

#include <cmath>
#include <functional>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

namespace inspection::testing {

inline constexpr double kPi = 3.14159265358979323846;

// z(x_um, y_um) sampled at the pixel centres, CV_32FC1.
inline cv::Mat SampleSurface(cv::Size size, double pixel_size_um, const std::function<double(double, double)>& z) {
  cv::Mat m(size, CV_32FC1);
  for (int row = 0; row < size.height; ++row) {
    for (int col = 0; col < size.width; ++col) {
      m.at<float>(row, col) = float(z((col + 0.5) * pixel_size_um, (row + 0.5) * pixel_size_um));
    }
  }
  return m;
}

// Box-correlated Gaussian noise of standard deviation sigma_um: white noise summed over a
// window x window box and normalised, the structure core/metrology/depth_noise_model.h assumes.
inline cv::Mat CorrelatedNoise(cv::Size size, double sigma_um, int window_px, unsigned seed) {
  const int r = window_px / 2;
  cv::Mat white(size.height + 2 * r, size.width + 2 * r, CV_32FC1);
  std::mt19937 rng(seed);
  std::normal_distribution<float> n(0.f, 1.f);
  for (int i = 0; i < white.rows; ++i)
    for (int j = 0; j < white.cols; ++j) white.at<float>(i, j) = n(rng);
  cv::Mat boxed;
  cv::boxFilter(white, boxed, CV_32F, cv::Size(window_px, window_px), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  return boxed(cv::Rect(r, r, size.width, size.height)) * (sigma_um / window_px);
}

// Sets `count` round holes of radius radius_px to NaN at random places (deterministic by seed).
inline void PunchHoles(cv::Mat& depth, int count, int radius_px, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> x(0, depth.cols - 1), y(0, depth.rows - 1);
  for (int k = 0; k < count; ++k) cv::circle(depth, cv::Point(x(rng), y(rng)), radius_px, cv::Scalar(NAN), cv::FILLED);
}

inline int CountFinite(const cv::Mat& depth) { return cv::countNonZero(depth == depth); }

}  // namespace inspection::testing
