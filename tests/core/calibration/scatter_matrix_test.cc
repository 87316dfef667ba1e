// Scatter matrix (thesis 4.3.4, eq. 4.11-4.12): built from dot grids of a synthetic rig whose
// light transport is known, it must predict the camera image of a random pattern.
#include "core/calibration/scatter_matrix.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "tests/core/calibration_synthetic.h"

namespace inspection {
namespace {
using testing_synthetic::SyntheticRig;

// Linear camera at exposure 1 us: radiance == grey.
CameraResponseFunction LinearCamera() {
  CameraResponseFunction c;
  c.levels = 256;
  for (int z = 0; z < 256; ++z) c.log_exposure.push_back(std::log(std::max(z, 1) * 1.0) - (z == 0 ? 1.0 : 0.0));
  return c;
}

ProjectorResponseFunction LinearProjector() {
  ProjectorResponseFunction p;
  for (int i = 0; i < 256; ++i) p.relative_irradiance.push_back(i / 255.0);
  return p;
}

GeometricCalibration TrueGeometry(const SyntheticRig& rig) {
  GeometricCalibration g;
  g.projector_size = rig.projector;
  g.camera_size = rig.camera;
  g.projector_to_camera = cv::Mat(rig.projector, CV_32FC2);
  for (int v = 0; v < rig.projector.height; ++v)
    for (int u = 0; u < rig.projector.width; ++u) {
      const cv::Point2d c = rig.Map(u, v);
      g.projector_to_camera.at<cv::Vec2f>(v, u) = cv::Vec2f(float(c.x), float(c.y));
    }
  EXPECT_TRUE(FinishGeometricCalibration(g).ok());
  return g;
}

struct Built {
  ScatterMatrix s;
  cv::Mat mask;
};

Built BuildFromRig(const SyntheticRig& rig, int spacing, int radius, std::mt19937& rng) {
  const CameraResponseFunction crf = LinearCamera();
  const GeometricCalibration g = TrueGeometry(rig);
  const cv::Mat black = crf.Radiance(rig.Capture(cv::Mat::zeros(rig.projector, CV_8UC1), 0.5, rng), 1.0);
  std::vector<ScatterCapture> caps;
  for (int oy = 0; oy < spacing; ++oy)
    for (int ox = 0; ox < spacing; ++ox) {
      cv::Mat pattern = cv::Mat::zeros(rig.projector, CV_8UC1);
      for (int v = oy; v < rig.projector.height; v += spacing)
        for (int u = ox; u < rig.projector.width; u += spacing) pattern.at<uint8_t>(v, u) = 255;
      caps.push_back({ox, oy, crf.Radiance(rig.Capture(pattern, 0.5, rng), 1.0) - black});
    }
  ScatterMatrixOptions o;
  o.grid_spacing_px = spacing;
  o.patch_radius_px = radius;
  auto s = BuildScatterMatrix(caps, g, black, o);
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  cv::Mat mask(rig.camera, CV_8UC1);
  for (int y = 0; y < rig.camera.height; ++y)
    for (int x = 0; x < rig.camera.width; ++x) mask.at<uint8_t>(y, x) = g.ProjectorFromCamera({x, y}) ? 255 : 0;
  return {std::move(s).value(), mask};
}

TEST(ScatterMatrixTest, PredictsRandomPatternWithinOnePercent) {
  SyntheticRig rig;
  std::mt19937 rng(11);
  Built b = BuildFromRig(rig, 4, 4, rng);
  ASSERT_TRUE(b.s.Validate().ok());
  // Every projector pixel got a column; ~ (pi * (sigma * sqrt(2 ln 100))^2) entries above 1 %.
  const double per_col = static_cast<double>(b.s.a.nonZeros()) / rig.projector.area();
  EXPECT_GT(per_col, 25);
  EXPECT_LT(per_col, 81);
  EXPECT_NEAR(b.s.Density(), per_col / rig.camera.area(), 1e-12);

  cv::Mat pattern(rig.projector, CV_8UC1);
  cv::randu(pattern, 0, 256);
  const cv::Mat captured = rig.Capture(pattern, 0.5, rng);
  auto pred = PredictAndCompare(b.s, LinearProjector(), LinearCamera(), pattern, 1.0, captured, b.mask);
  ASSERT_TRUE(pred.ok()) << pred.status().ToString();
  EXPECT_GT(pred->pixel_count, 5000);
  EXPECT_LT(pred->mean_abs_error_percent, 1.0);
}

TEST(ScatterMatrixTest, TooSmallPatchLosesLightAndTheErrorShows) {
  SyntheticRig rig;
  std::mt19937 rng(12);
  Built small = BuildFromRig(rig, 4, 1, rng);
  cv::Mat pattern(rig.projector, CV_8UC1, cv::Scalar(200));
  const cv::Mat captured = rig.Capture(pattern, 0.5, rng);
  auto pred = PredictAndCompare(small.s, LinearProjector(), LinearCamera(), pattern, 1.0, captured, small.mask);
  ASSERT_TRUE(pred.ok());
  // A 3x3 patch keeps only part of a sigma-1.1 footprint: the prediction is clearly too dark.
  EXPECT_GT(pred->mean_abs_error_percent, 5.0);
}

TEST(ScatterMatrixTest, SparseFileRoundTripAndCorruption) {
  ScatterMatrix::Sparse a(6, 4);
  a.insert(1, 0) = 1.5f;
  a.insert(4, 0) = -2.0f;
  a.insert(2, 3) = 7.25f;
  a.makeCompressed();
  const auto file = std::filesystem::temp_directory_path() / ("scatter_test_" + std::to_string(::getpid()) + ".bin");
  ASSERT_TRUE(WriteSparseMatrix(file, a).ok());
  auto back = ReadSparseMatrix(file);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->nonZeros(), 3);
  EXPECT_FLOAT_EQ(back->coeff(4, 0), -2.0f);
  EXPECT_FLOAT_EQ(back->coeff(2, 3), 7.25f);
  {
    // A column pointer beyond nnz must be caught before any row index is read through it.
    std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
    const int32_t bad = 100;
    f.seekp(24 + 4);
    f.write(reinterpret_cast<const char*>(&bad), 4);
  }
  EXPECT_EQ(ReadSparseMatrix(file).status().code(), StatusCode::kDataLoss);
  ASSERT_TRUE(WriteSparseMatrix(file, a).ok());
  std::filesystem::resize_file(file, std::filesystem::file_size(file) - 4);
  EXPECT_EQ(ReadSparseMatrix(file).status().code(), StatusCode::kDataLoss);
  std::filesystem::remove(file);
}

}  // namespace
}  // namespace inspection
