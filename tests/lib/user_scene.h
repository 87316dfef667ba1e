// User scenes (devices/sim/specimen.h, "file:" specimens) for tests and benches: a height
// function sampled on the camera grid plus a mean-1 log-normal texture like the built-in
// specimens' (fine grain plus mottling), written as scene.json, a float height TIFF and a
// 16-bit texture PNG.
#pragma once

#include <cmath>
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

// A user scene: height (um) and, optionally, linear reflectance as functions of the position
// (x_um, y_um) of a pixel centre; the texture's contrast scales its deviation from 1.
struct UserSceneSpec {
  std::function<double(double, double)> height_um;
  std::function<double(double, double)> reflectance;  // empty: the loader's default (0.5)
  double texture_contrast = 1.0;
  unsigned texture_seed = 1;
};

// Writes <name>.json, <name>_height.tiff, <name>_texture.png (and <name>_reflectance.tiff);
// returns the specimen name "file:<dir>/<name>.json".
inline std::string WriteUserScene(const std::filesystem::path& dir, const std::string& name, cv::Size size,
                                  double pixel_size_um, const UserSceneSpec& spec) {
  std::filesystem::create_directories(dir);
  auto sample = [&](const std::function<double(double, double)>& f) {
    cv::Mat m(size, CV_32F);
    for (int r = 0; r < size.height; ++r) {
      for (int c = 0; c < size.width; ++c) m.at<float>(r, c) = float(f((c + 0.5) * pixel_size_um, (r + 0.5) * pixel_size_um));
    }
    return m;
  };
  cv::imwrite((dir / (name + "_height.tiff")).string(), sample(spec.height_um));
  WriteSceneTexture(dir / (name + "_texture.png"), size, spec.texture_seed);
  std::ofstream json((dir / (name + ".json")).string());
  json << "{\"height\": \"" << name << "_height.tiff\", \"texture\": \"" << name << "_texture.png\"";
  if (spec.texture_contrast != 1.0) json << ", \"texture_contrast\": " << spec.texture_contrast;
  if (spec.reflectance) {
    cv::imwrite((dir / (name + "_reflectance.tiff")).string(), sample(spec.reflectance));
    json << ", \"reflectance\": \"" << name << "_reflectance.tiff\", \"reflectance_scale\": 1";
  }
  json << "}\n";
  return "file:" + (dir / (name + ".json")).string();
}

// A 20 um weld bead across the middle of the field (a half ellipse, 0.6 of the field's height
// wide) on a flat base at 200 um, with glints along its crest ~500:1 against its dark flanks
// (reflectance 0.01; the base 0.21). inspect-evaluate's user scene and ScanModesTest's.
inline UserSceneSpec WeldBeadScene(cv::Size size, double pixel_size_um) {
  const double w = size.width * pixel_size_um, h = size.height * pixel_size_um, bead_w = 0.3 * h;
  UserSceneSpec bead;
  bead.height_um = [=](double, double y) {
    const double u = (y - 0.5 * h) / bead_w;
    return 200.0 + (std::abs(u) < 1.0 ? 20.0 * std::sqrt(1.0 - u * u) : 0.0);
  };
  bead.reflectance = [=](double x, double y) {
    const double u = (y - 0.5 * h) / bead_w;
    const double ripple = 0.5 + 0.5 * std::cos(2.0 * M_PI * x / (0.1 * w));
    return std::abs(u) < 1.0 ? 0.01 + 5.0 * std::exp(-u * u / 0.02) * ripple : 0.01 + 0.2;
  };
  bead.texture_contrast = 0.6;
  bead.texture_seed = 33;
  return bead;
}

// height_um(x_um, y_um) at pixel centres, the default reflectance and full texture contrast.
inline std::string WriteUserScene(const std::filesystem::path& dir, const std::string& name, cv::Size size,
                                  double pixel_size_um, const std::function<double(double, double)>& height_um,
                                  unsigned texture_seed) {
  UserSceneSpec spec;
  spec.height_um = height_um;
  spec.texture_seed = texture_seed;
  return WriteUserScene(dir, name, size, pixel_size_um, spec);
}

}  // namespace inspection::test_scenes
