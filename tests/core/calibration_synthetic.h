// Synthetic projector-camera pair for the calibration tests: a known projector->camera mapping
// (homography + radial distortion), Gaussian light footprint per projector pixel, linear or
// gamma camera. Ground truth for geometry, PSF and scatter-matrix tests.
#pragma once

#include <cmath>
#include <opencv2/core.hpp>
#include <random>
#include <vector>

namespace inspection::testing_synthetic {

struct SyntheticRig {
  cv::Size projector{40, 30};
  cv::Size camera{128, 100};
  double scale = 2.6;        // camera px per projector px
  double angle_rad = 0.004;  // small rotation (thesis: 0.1 deg skew)
  cv::Point2d offset{12.0, 9.0};
  double k_radial = 2e-6;  // barrel distortion around the camera centre, per px^2
  double sigma_px = 1.1;   // Gaussian footprint of one projector pixel in the camera
  double peak = 120.0;     // camera grey (linear camera) of one lit projector pixel
  double black = 3.0;      // camera grey with all projector pixels black

  // True camera position of projector pixel centre (u, v).
  cv::Point2d Map(double u, double v) const {
    const double c = std::cos(angle_rad), s = std::sin(angle_rad);
    cv::Point2d h(offset.x + scale * (c * u - s * v), offset.y + scale * (s * u + c * v));
    const cv::Point2d ctr(camera.width / 2.0, camera.height / 2.0);
    const cv::Point2d d = h - ctr;
    const double f = 1.0 + k_radial * (d.x * d.x + d.y * d.y);
    return ctr + d * f;
  }
  // Inverse of Map by fixed-point iteration (for Gray-code rendering).
  cv::Point2d Unmap(double x, double y) const {
    cv::Point2d p((x - offset.x) / scale, (y - offset.y) / scale);
    for (int it = 0; it < 30; ++it) {
      const cv::Point2d m = Map(p.x, p.y);
      p.x += (x - m.x) / scale;
      p.y += (y - m.y) / scale;
    }
    return p;
  }

  // Linear camera radiance (grey units at unit exposure) of a projector image of relative
  // irradiances (CV_32FC1): black + sum_j e_j * peak * G(x - Map(j)).
  cv::Mat Render(const cv::Mat& irradiance) const {
    cv::Mat out(camera, CV_32FC1, cv::Scalar(black));
    const int r = static_cast<int>(std::ceil(4 * sigma_px));
    for (int v = 0; v < projector.height; ++v)
      for (int u = 0; u < projector.width; ++u) {
        const float e = irradiance.at<float>(v, u);
        if (e == 0) continue;
        const cv::Point2d c = Map(u, v);
        const int cx = static_cast<int>(std::lround(c.x)), cy = static_cast<int>(std::lround(c.y));
        for (int y = std::max(0, cy - r); y <= std::min(camera.height - 1, cy + r); ++y)
          for (int x = std::max(0, cx - r); x <= std::min(camera.width - 1, cx + r); ++x) {
            const double d2 = (x - c.x) * (x - c.x) + (y - c.y) * (y - c.y);
            out.at<float>(y, x) += static_cast<float>(e * peak * std::exp(-d2 / (2 * sigma_px * sigma_px)));
          }
      }
    return out;
  }
  // Projector pattern (CV_8UC1, linear projector: irradiance = grey / 255) -> 8-bit image.
  cv::Mat Capture(const cv::Mat& pattern, double noise, std::mt19937& rng) const {
    cv::Mat e;
    pattern.convertTo(e, CV_32F, 1.0 / 255.0);
    cv::Mat rad = Render(e);
    std::normal_distribution<float> n(0.0f, static_cast<float>(noise));
    cv::Mat out(camera, CV_8UC1);
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x)
        out.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(rad.at<float>(y, x) + (noise > 0 ? n(rng) : 0.0f));
    return out;
  }
  // Gray-code style capture: each camera pixel sees the projector pixel it maps to (sharp).
  cv::Mat CaptureSharp(const cv::Mat& pattern) const {
    cv::Mat out(camera, CV_8UC1, cv::Scalar(0));
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        const cv::Point2d p = Unmap(x, y);
        const int u = static_cast<int>(std::lround(p.x)), v = static_cast<int>(std::lround(p.y));
        if (u < 0 || v < 0 || u >= projector.width || v >= projector.height) continue;
        out.at<uint8_t>(y, x) = pattern.at<uint8_t>(v, u) ? 200 : 10;
      }
    return out;
  }
};

}  // namespace inspection::testing_synthetic
