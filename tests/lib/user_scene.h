// User scenes (devices/sim/specimen.h, "file:" specimens) for tests and benches: a height
// function sampled on the camera grid plus a mean-1 log-normal texture like the built-in
// specimens' (fine grain plus mottling), written as scene.json, a float height TIFF and a
// 16-bit texture PNG.
#pragma once

#include <filesystem>
#include <fstream>
#include <functional>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

namespace inspection::test_scenes {

inline void WriteSceneTexture(const std::filesystem::path& path, cv::Size size, unsigned seed) {
  cv::Mat fine(size, CV_32F), coarse(size, CV_32F);
  cv::RNG rng(seed);
  rng.fill(fine, cv::RNG::NORMAL, 0.0, 1.0);
  rng.fill(coarse, cv::RNG::NORMAL, 0.0, 1.0);
  cv::GaussianBlur(fine, fine, cv::Size(0, 0), 1.0);
  cv::GaussianBlur(coarse, coarse, cv::Size(0, 0), 8.0);
  cv::Scalar m, s;
  cv::meanStdDev(fine, m, s);
  fine = (fine - m[0]) / s[0];
  cv::meanStdDev(coarse, m, s);
  coarse = (coarse - m[0]) / s[0];
  cv::Mat t = 0.35 * fine + 0.15 * coarse;
  cv::exp(t, t);
  t *= 20000.0 / cv::mean(t)[0];
  cv::Mat t16;
  t.convertTo(t16, CV_16U);
  cv::imwrite(path.string(), t16);
}

// height_um(x_um, y_um) at pixel centres; returns the specimen name "file:<dir>/<name>.json".
inline std::string WriteUserScene(const std::filesystem::path& dir, const std::string& name, cv::Size size,
                                  double pixel_size_um, const std::function<double(double, double)>& height_um,
                                  unsigned texture_seed) {
  std::filesystem::create_directories(dir);
  cv::Mat h(size, CV_32F);
  for (int r = 0; r < size.height; ++r) {
    for (int c = 0; c < size.width; ++c) {
      h.at<float>(r, c) = float(height_um((c + 0.5) * pixel_size_um, (r + 0.5) * pixel_size_um));
    }
  }
  cv::imwrite((dir / (name + "_height.tiff")).string(), h);
  WriteSceneTexture(dir / (name + "_texture.png"), size, texture_seed);
  std::ofstream((dir / (name + ".json")).string())
      << "{\"height\": \"" << name << "_height.tiff\", \"texture\": \"" << name << "_texture.png\"}\n";
  return "file:" + (dir / (name + ".json")).string();
}

}  // namespace inspection::test_scenes
