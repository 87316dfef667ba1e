// Synthetic SFF stacks with known ground truth for the engine tests: a random texture seen
// through a defocus blur whose Gaussian sigma grows with |z - h(x, y)| for a known height map h,
// and a textureless (flat grey + noise) stack.
#pragma once

#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

namespace inspection::testing {

struct SyntheticStack {
  std::vector<cv::Mat> frames;
  std::vector<double> z_um;
  cv::Mat height_um;  // CV_32F ground truth
  cv::Mat texture;    // CV_32F sharp texture (grey values)
};

// Random texture, mean 128, contrast +-70, slightly smoothed (optics never pass the pixel
// frequency), deterministic for a seed.
inline cv::Mat RandomTexture(cv::Size size, unsigned seed) {
  cv::Mat t(size, CV_32F);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) t.at<float>(y, x) = u(rng);
  cv::GaussianBlur(t, t, cv::Size(0, 0), 0.7, 0.7, cv::BORDER_REFLECT_101);
  double lo, hi;
  cv::minMaxLoc(t, &lo, &hi);
  t = 128.0 + (t - (lo + hi) / 2) * (140.0 / (hi - lo));
  return t;
}

// Tilted plane h = h0 + gx * x + gy * y (µm) imaged at z_um; blur sigma (px) at defocus d is
// sqrt(sigma0^2 + (blur_per_um * d)^2). Frames are quantised to `type` (CV_8U or CV_16U,
// 16-bit = 8-bit values * 257) after adding Gaussian noise of noise_grey (8-bit units).
inline SyntheticStack TiltedPlaneStack(cv::Size size, const std::vector<double>& z_um, double h0, double gx, double gy,
                                       int type = CV_8U, double noise_grey = 0.5, double sigma0 = 0.6,
                                       double blur_per_um = 0.7, unsigned seed = 11) {
  SyntheticStack s;
  s.z_um = z_um;
  s.texture = RandomTexture(size, seed);
  s.height_um.create(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) s.height_um.at<float>(y, x) = float(h0 + gx * x + gy * y);
  // Blur levels every 0.05 px of sigma, linear interpolation in between.
  double max_defocus = 0;
  double hmin, hmax;
  cv::minMaxLoc(s.height_um, &hmin, &hmax);
  for (double z : z_um) max_defocus = std::max({max_defocus, std::abs(z - hmin), std::abs(z - hmax)});
  const double sigma_max = std::sqrt(sigma0 * sigma0 + std::pow(blur_per_um * max_defocus, 2));
  const double dsig = 0.05;
  std::vector<cv::Mat> levels;
  for (double sg = 0; sg <= sigma_max + dsig; sg += dsig) {
    cv::Mat b;
    if (sg < 0.05)
      b = s.texture.clone();
    else
      cv::GaussianBlur(s.texture, b, cv::Size(0, 0), sg, sg, cv::BORDER_REFLECT_101);
    levels.push_back(b);
  }
  std::mt19937 rng(seed * 7 + 1);
  std::normal_distribution<float> noise(0.f, float(noise_grey));
  for (double z : z_um) {
    cv::Mat f(size, CV_32F);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const double d = z - s.height_um.at<float>(y, x);
        const double sg = std::sqrt(sigma0 * sigma0 + blur_per_um * blur_per_um * d * d);
        const double pos = sg / dsig;
        const int i = std::min(int(pos), int(levels.size()) - 2);
        const double w = pos - i;
        f.at<float>(y, x) = float((1 - w) * levels[i].at<float>(y, x) + w * levels[i + 1].at<float>(y, x)) +
                            (noise_grey > 0 ? noise(rng) : 0.f);
      }
    cv::Mat q;
    if (type == CV_8U)
      f.convertTo(q, CV_8U);
    else
      f.convertTo(q, CV_16U, 257.0);
    s.frames.push_back(q);
  }
  return s;
}

// Flat grey 128 plus Gaussian noise: no texture, so no depth can be trusted.
inline std::vector<cv::Mat> TexturelessStack(cv::Size size, int n, double noise_grey, unsigned seed = 5) {
  std::vector<cv::Mat> frames;
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.f, float(noise_grey));
  for (int k = 0; k < n; ++k) {
    cv::Mat f(size, CV_32F);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) f.at<float>(y, x) = 128.f + noise(rng);
    cv::Mat q;
    f.convertTo(q, CV_8U);
    frames.push_back(q);
  }
  return frames;
}

inline std::vector<double> UniformZ(int n, double z0, double dz) {
  std::vector<double> z(static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) z[size_t(k)] = z0 + k * dz;
  return z;
}

// RMSE and count of finite depth values against the ground truth.
struct DepthError {
  double rmse_um = 0;
  double max_abs_um = 0;
  double valid_fraction = 0;
};

inline DepthError CompareDepth(const cv::Mat& depth, const cv::Mat& truth, int border = 0) {
  DepthError e;
  double sq = 0;
  size_t n = 0, total = 0;
  for (int y = border; y < depth.rows - border; ++y)
    for (int x = border; x < depth.cols - border; ++x) {
      ++total;
      const float d = depth.at<float>(y, x);
      if (!std::isfinite(d)) continue;
      const double err = d - truth.at<float>(y, x);
      sq += err * err;
      e.max_abs_um = std::max(e.max_abs_um, std::abs(err));
      ++n;
    }
  e.rmse_um = n ? std::sqrt(sq / n) : 0;
  e.valid_fraction = total ? double(n) / total : 0;
  return e;
}

// Same size, type and bytes (NaN payloads included): the engines' paths promise this.
inline bool BitIdentical(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int y = 0; y < a.rows; ++y)
    if (std::memcmp(a.ptr(y), b.ptr(y), a.cols * a.elemSize()) != 0) return false;
  return true;
}

}  // namespace inspection::testing
