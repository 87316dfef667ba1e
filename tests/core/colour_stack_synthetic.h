// A synthetic colour focal stack with known depth for the colour all-in-focus tests (core and
// server): a random colour texture (channels independent, so its colours are not grey), two
// depth regions (left half in focus at one frame, right half at another), each frame the texture
// blurred by a Gaussian whose sigma grows with the distance from focus (a thin-lens stand-in
// for thesis 3.1's defocus).
#pragma once

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "core/io/stack.h"

namespace inspection::testing {

struct ColourStackSpec {
  cv::Size size{96, 64};
  int frames = 9;
  double z_step_um = 5.0;
  int focus_frame_left = 3;   // columns [0, width/2)
  int focus_frame_right = 6;  // columns [width/2, width)
  double blur_sigma_per_frame_px = 0.9;
  bool sixteen_bit = false;  // 16-bit TIFF frames instead of 8-bit PNG
  unsigned seed = 7;
};

// The sharp texture (CV_8UC3 or CV_16UC3, BGR), i.e. what the in-focus frame shows.
inline cv::Mat ColourTexture(const ColourStackSpec& s) {
  cv::RNG rng(s.seed);
  // Blocks of 2x2 px of independent random B, G, R: a texture the 7x7 window sees well.
  cv::Mat small(s.size.height / 2, s.size.width / 2, CV_8UC3);
  rng.fill(small, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(256));
  cv::Mat tex;
  cv::resize(small, tex, s.size, 0, 0, cv::INTER_NEAREST);
  if (s.sixteen_bit) tex.convertTo(tex, CV_16UC3, 257.0);
  return tex;
}

inline double TrueDepthUm(const ColourStackSpec& s, int x) {
  return s.z_step_um * (x < s.size.width / 2 ? s.focus_frame_left : s.focus_frame_right);
}

inline cv::Mat BlurredFrame(const ColourStackSpec& s, const cv::Mat& tex, int i) {
  cv::Mat out(tex.size(), tex.type());
  const int half = s.size.width / 2;
  for (int side = 0; side < 2; ++side) {
    const int focus = side == 0 ? s.focus_frame_left : s.focus_frame_right;
    const double sigma = s.blur_sigma_per_frame_px * std::abs(i - focus);
    cv::Mat blurred = tex.clone();
    if (sigma > 0) cv::GaussianBlur(tex, blurred, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
    const cv::Rect cols = side == 0 ? cv::Rect(0, 0, half, tex.rows) : cv::Rect(half, 0, tex.cols - half, tex.rows);
    blurred(cols).copyTo(out(cols));
  }
  return out;
}

// Writes the frames and stack.json into dir; returns the manifest. grey_frame >= 0 stores that
// frame as grey (its luminance) to make a mixed stack.
inline StackManifest WriteColourStack(const std::filesystem::path& dir, const ColourStackSpec& s, int grey_frame = -1) {
  std::filesystem::create_directories(dir);
  const cv::Mat tex = ColourTexture(s);
  StackManifest m;
  m.pixel_size_um = 0.5;
  m.bit_depth = s.sixteen_bit ? 16 : 8;
  for (int i = 0; i < s.frames; ++i) {
    cv::Mat frame = BlurredFrame(s, tex, i);
    if (i == grey_frame) cv::cvtColor(frame, frame, cv::COLOR_BGR2GRAY);
    const std::string name = "f" + std::to_string(i) + (s.sixteen_bit ? ".tiff" : ".png");
    cv::imwrite((dir / name).string(), frame);
    m.frames.push_back({name, s.z_step_um * i, 1000, "uniform:128"});
  }
  if (const Status written = WriteStackManifest(dir, m); !written.ok()) throw std::runtime_error(written.ToString());
  return m;
}

}  // namespace inspection::testing
