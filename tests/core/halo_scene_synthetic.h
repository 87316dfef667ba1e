// A halo test scene (tests and tests/bench/halo_evaluate.cc): a bright textured foreground object
// in front of a darker textured background, both flat, rendered per focus position with a thin
// lens and occlusion. Shares no code with devices/sim (its own texture, PSF and compositing), so
// a result on it is not an artefact of the project's renderer.
//
// Model: frame k is focused at depth k (frame units; z_um = k). A layer at depth d is blurred by
// an anti-aliased disc of radius blur_px_per_frame * |d - k| and a Gaussian of in_focus_sigma_px.
// Compositing in linear radiance, back to front with the "over" operator on the blurred
// premultiplied foreground and its blurred alpha: I = K*(a c_f) + (1 - K*a) (K_b * c_b), so the
// defocused foreground spreads over the background and its edge becomes semi-transparent, and
// an in-focus foreground edge stays sharp over the blurred background. Camera: shot noise
// (full_well_electrons at radiance 1), read noise, gamma 1/2.2, 8-bit grey.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace inspection::testing_halo {

enum class HaloShape { kEllipse, kRoundedBox, kPole };

struct HaloSceneOptions {
  cv::Size size{192, 192};
  int frames = 30;
  uint32_t seed = 1;
  HaloShape shape = HaloShape::kEllipse;
  double blur_px_per_frame = 0.8;
  double in_focus_sigma_px = 0.5;
  double foreground_frame = 6.0;   // depth of the (flat) foreground, frames
  double background_frame = 22.0;  // depth of the (flat) background, frames
  double foreground_radiance = 0.45, background_radiance = 0.04;  // linear, 1 = full well
  double foreground_contrast = 0.4, background_contrast = 0.35;    // texture std / mean
  double full_well_electrons = 6000.0, read_noise_electrons = 5.0;
};

struct HaloScene {
  std::vector<cv::Mat> frames;  // CV_8UC1
  std::vector<double> z_um;     // frame k at k
  cv::Mat depth_frames;         // CV_32FC1 truth: the visible layer's depth (alpha >= 0.5: foreground)
  cv::Mat all_in_focus;         // CV_8UC1 truth: each layer at its own focus, noise-free
  cv::Mat foreground;           // CV_8UC1: 255 where alpha >= 0.5
  // CV_8UC1: 255 on background pixels within band_px of the foreground (the halo band).
  cv::Mat background_band;
  double band_px = 0.0;  // the foreground's blur radius at the background's focus
};

// Zero-mean, unit-std texture with structure from 1 to ~8 px (sum of blurred white noise).
inline cv::Mat HaloTexture(cv::Size size, cv::RNG& rng) {
  cv::Mat sum(size, CV_32FC1, cv::Scalar(0));
  for (double sigma : {0.8, 1.6, 3.2, 6.4}) {
    cv::Mat noise(size, CV_32FC1);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
    cv::GaussianBlur(noise, noise, {0, 0}, sigma);
    cv::Scalar mean, std;
    cv::meanStdDev(noise, mean, std);
    sum += (noise - mean[0]) / std[0];
  }
  cv::Scalar mean, std;
  cv::meanStdDev(sum, mean, std);
  return (sum - mean[0]) / std[0];
}

// The PSF of a defocus of `radius_px` (disc) with the in-focus Gaussian, normalised.
inline cv::Mat HaloPsf(double radius_px, double sigma_px) {
  const int half = int(std::ceil(radius_px + 3 * sigma_px)) + 1;
  cv::Mat k(2 * half + 1, 2 * half + 1, CV_32FC1, cv::Scalar(0));
  if (radius_px < 0.25) {
    k.at<float>(half, half) = 1.f;
  } else {
    constexpr int kSub = 4;  // anti-aliased disc: coverage by 4x4 sub-samples per pixel
    for (int y = -half; y <= half; ++y)
      for (int x = -half; x <= half; ++x) {
        int in = 0;
        for (int sy = 0; sy < kSub; ++sy)
          for (int sx = 0; sx < kSub; ++sx) {
            const double u = x + (sx + 0.5) / kSub - 0.5, v = y + (sy + 0.5) / kSub - 0.5;
            in += u * u + v * v <= radius_px * radius_px ? 1 : 0;
          }
        k.at<float>(y + half, x + half) = float(in);
      }
  }
  cv::GaussianBlur(k, k, {0, 0}, sigma_px);
  return k / cv::sum(k)[0];
}

inline cv::Mat HaloBlur(const cv::Mat& src, double radius_px, double sigma_px) {
  cv::Mat out;
  cv::filter2D(src, out, CV_32F, HaloPsf(radius_px, sigma_px), {-1, -1}, 0, cv::BORDER_REFLECT_101);
  return out;
}

// Foreground alpha (anti-aliased over ~1 px) of the shape, placed and sized from rng.
inline cv::Mat HaloAlpha(const HaloSceneOptions& o, cv::RNG& rng) {
  const double w = o.size.width, h = o.size.height;
  const double cx = rng.uniform(0.35, 0.65) * w, cy = rng.uniform(0.35, 0.65) * h;
  const double ax = rng.uniform(0.18, 0.3) * w, ay = rng.uniform(0.18, 0.3) * h;
  const double angle = rng.uniform(0.0, CV_PI);
  const double ca = std::cos(angle), sa = std::sin(angle);
  const double corner = rng.uniform(0.2, 0.5) * std::min(ax, ay);
  const double pole_half = rng.uniform(0.08, 0.14) * w;
  cv::Mat alpha(o.size, CV_32FC1);
  for (int y = 0; y < o.size.height; ++y)
    for (int x = 0; x < o.size.width; ++x) {
      const double dx = x - cx, dy = y - cy;
      const double u = ca * dx + sa * dy, v = -sa * dx + ca * dy;
      double g = 0.0;  // > 0 inside, ~ distance to the outline in px
      switch (o.shape) {
        case HaloShape::kEllipse: {
          const double r = std::hypot(u / ax, v / ay);
          g = (1.0 - r) * std::min(ax, ay);
          break;
        }
        case HaloShape::kRoundedBox: {
          const double qx = std::abs(u) - (ax - corner), qy = std::abs(v) - (ay - corner);
          const double outside = std::hypot(std::max(qx, 0.0), std::max(qy, 0.0));
          g = corner - (outside + std::min(std::max(qx, qy), 0.0));
          break;
        }
        case HaloShape::kPole:
          g = pole_half - std::abs(u);
          break;
      }
      alpha.at<float>(y, x) = float(std::clamp(0.5 + g, 0.0, 1.0));
    }
  return alpha;
}

inline HaloScene RenderHaloScene(const HaloSceneOptions& o) {
  cv::RNG rng(o.seed * 2654435761u + 17u);
  const cv::Mat alpha = HaloAlpha(o, rng);
  cv::Mat fg = o.foreground_radiance * (1.0 + o.foreground_contrast * HaloTexture(o.size, rng));
  cv::Mat bg = o.background_radiance * (1.0 + o.background_contrast * HaloTexture(o.size, rng));
  cv::max(fg, 0.0, fg);
  cv::max(bg, 0.0, bg);
  const cv::Mat fg_premultiplied = fg.mul(alpha);

  auto encode = [](const cv::Mat& radiance) {
    cv::Mat clipped, v, out;
    cv::min(cv::max(radiance, 0.0), 1.0, clipped);
    cv::pow(clipped, 1.0 / 2.2, v);
    v.convertTo(out, CV_8UC1, 255.0);
    return out;
  };
  HaloScene s;
  for (int k = 0; k < o.frames; ++k) {
    const double rf = o.blur_px_per_frame * std::abs(o.foreground_frame - k);
    const double rb = o.blur_px_per_frame * std::abs(o.background_frame - k);
    const cv::Mat a = HaloBlur(alpha, rf, o.in_focus_sigma_px);
    cv::Mat radiance = HaloBlur(fg_premultiplied, rf, o.in_focus_sigma_px) +
                       (1.0 - a).mul(HaloBlur(bg, rb, o.in_focus_sigma_px));
    cv::Mat electrons = cv::max(radiance, 0.0) * o.full_well_electrons, sd, noise(o.size, CV_32FC1);
    cv::sqrt(electrons + o.read_noise_electrons * o.read_noise_electrons, sd);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
    radiance = (electrons + noise.mul(sd)) / o.full_well_electrons;
    s.frames.push_back(encode(radiance));
    s.z_um.push_back(double(k));
  }
  const cv::Mat a0 = HaloBlur(alpha, 0.0, o.in_focus_sigma_px);
  s.all_in_focus = encode(HaloBlur(fg_premultiplied, 0.0, o.in_focus_sigma_px) +
                          (1.0 - a0).mul(HaloBlur(bg, 0.0, o.in_focus_sigma_px)));
  s.foreground = alpha >= 0.5;
  s.depth_frames = cv::Mat(o.size, CV_32FC1, cv::Scalar(o.background_frame));
  s.depth_frames.setTo(o.foreground_frame, s.foreground);
  s.band_px = o.blur_px_per_frame * std::abs(o.background_frame - o.foreground_frame);
  cv::Mat distance;
  cv::distanceTransform(~s.foreground, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  s.background_band = (distance > 0) & (distance <= s.band_px);
  return s;
}

// Errors in the halo band: background pixels from 4 px (beyond the 7 px focus window's reach of
// the edge) to the object's blur radius at the background's focus. depth: CV_32FC1 in frames (NaN
// = no depth: counted out of the RMSE, into valid_percent); all_in_focus: CV_8UC1.
struct HaloBandError {
  double depth_rmse_frames = 0, aif_rms = 0;  // depth over the pixels with depth
  double valid_percent = 0;
};
inline HaloBandError HaloBandErrorOf(const HaloScene& s, const cv::Mat& depth, const cv::Mat& all_in_focus) {
  cv::Mat not_foreground = ~s.foreground, distance;
  cv::distanceTransform(not_foreground, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  double dsq = 0, asq = 0;
  int n = 0, valid = 0;
  for (int y = 0; y < distance.rows; ++y)
    for (int x = 0; x < distance.cols; ++x) {
      const float d = distance.at<float>(y, x);
      if (d <= 4 || d > s.band_px) continue;
      const double e = depth.at<float>(y, x) - s.depth_frames.at<float>(y, x);
      if (std::isfinite(e)) {
        dsq += e * e;
        ++valid;
      }
      const double a = double(all_in_focus.at<uint8_t>(y, x)) - s.all_in_focus.at<uint8_t>(y, x);
      asq += a * a;
      ++n;
    }
  return {std::sqrt(dsq / std::max(valid, 1)), std::sqrt(asq / std::max(n, 1)), 100.0 * valid / std::max(n, 1)};
}

}  // namespace inspection::testing_halo
