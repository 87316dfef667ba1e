// Speed of the calibration maths at the thesis's full size (1280x720 projector, 1024x768
// camera, 3.4 camera px per projector px; thesis 4.3.4 needed about an hour for the scatter
// matrix). Baselines in the same run, so figures read as ratios on any machine:
//   BM_ScatterBuild (per-capture patch cutting straight into CSC) vs BM_ScatterBuildTriplets
//   (the same patches through Eigen's setFromTriplets);
//   BM_ScatterPredict (one predicted camera image, eq. 4.12) vs BM_FrameCopy (one float frame copy).
#include <benchmark/benchmark.h>

#include <Eigen/SparseCore>
#include <opencv2/imgproc.hpp>

#include "core/calibration/geometric_calibration.h"
#include "core/calibration/scatter_matrix.h"

namespace inspection {
namespace {

constexpr int kSpacing = 8;
constexpr int kRadius = 9;

struct Fixture {
  GeometricCalibration geometry;
  cv::Mat black;
  std::vector<cv::Mat> captures;  // one dot-grid radiance image per grid offset (sigma 1.25 px dots)
};

const Fixture& Full() {
  static const Fixture* f = [] {
    auto* x = new Fixture;
    GeometricCalibration& g = x->geometry;
    g.projector_size = {1280, 720};
    g.camera_size = {1024, 768};
    g.projector_to_camera = cv::Mat(g.projector_size, CV_32FC2, cv::Scalar(NAN, NAN));
    // Projector centre on the camera centre, 3.4 camera px per projector px (what the camera sees).
    for (int v = 0; v < 720; ++v)
      for (int u = 0; u < 1280; ++u) {
        const double x0 = 512 + (u - 640) * 3.4, y0 = 384 + (v - 360) * 3.4;
        if (x0 >= 0 && y0 >= 0 && x0 < 1024 && y0 < 768) g.projector_to_camera.at<cv::Vec2f>(v, u) = cv::Vec2f(x0, y0);
      }
    x->black = cv::Mat(g.camera_size, CV_32FC1, cv::Scalar(0.01f));
    for (int oy = 0; oy < kSpacing; ++oy)
      for (int ox = 0; ox < kSpacing; ++ox) {
        cv::Mat c(g.camera_size, CV_32FC1);
        cv::randu(c, 0.0f, 0.002f);  // noise floor below the relative threshold
        for (int v = oy; v < 720; v += kSpacing)
          for (int u = ox; u < 1280; u += kSpacing) {
            const cv::Vec2f p = g.projector_to_camera.at<cv::Vec2f>(v, u);
            if (!std::isfinite(p[0])) continue;
            for (int y = std::max(0, int(p[1]) - 6); y <= std::min(767, int(p[1]) + 6); ++y)
              for (int xx = std::max(0, int(p[0]) - 6); xx <= std::min(1023, int(p[0]) + 6); ++xx) {
                const double d2 = (xx - p[0]) * (xx - p[0]) + (y - p[1]) * (y - p[1]);
                c.at<float>(y, xx) += static_cast<float>(std::exp(-d2 / (2 * 1.25 * 1.25)));
              }
          }
        x->captures.push_back(c);
      }
    return x;
  }();
  return *f;
}

ScatterMatrixOptions Options() {
  ScatterMatrixOptions o;
  o.grid_spacing_px = kSpacing;
  o.patch_radius_px = kRadius;
  o.relative_threshold = 0.005;
  return o;
}

void BM_ScatterBuild(benchmark::State& state) {
  const Fixture& f = Full();
  for (auto _ : state) {
    auto b = ScatterMatrixBuilder::Create(f.geometry, f.black, Options());
    for (int oy = 0; oy < kSpacing; ++oy)
      for (int ox = 0; ox < kSpacing; ++ox) b->Add({ox, oy, f.captures[oy * kSpacing + ox]}).IgnoreError();
    auto s = b->Finish();
    benchmark::DoNotOptimize(s->a.nonZeros());
    state.counters["nnz"] = static_cast<double>(s->a.nonZeros());
  }
}
BENCHMARK(BM_ScatterBuild)->Unit(benchmark::kMillisecond);

void BM_ScatterBuildTriplets(benchmark::State& state) {
  const Fixture& f = Full();
  const cv::Size cam = f.geometry.camera_size, proj = f.geometry.projector_size;
  for (auto _ : state) {
    std::vector<Eigen::Triplet<float>> t;
    for (int oy = 0; oy < kSpacing; ++oy)
      for (int ox = 0; ox < kSpacing; ++ox) {
        const cv::Mat& capture = f.captures[oy * kSpacing + ox];
        for (int v = oy; v < proj.height; v += kSpacing)
          for (int u = ox; u < proj.width; u += kSpacing) {
            const cv::Vec2f p = f.geometry.projector_to_camera.at<cv::Vec2f>(v, u);
            if (!std::isfinite(p[0])) continue;
            const int cx = int(std::lround(p[0])), cy = int(std::lround(p[1]));
            float peak = 0;
            for (int y = std::max(0, cy - kRadius); y <= std::min(cam.height - 1, cy + kRadius); ++y)
              for (int x = std::max(0, cx - kRadius); x <= std::min(cam.width - 1, cx + kRadius); ++x)
                peak = std::max(peak, capture.at<float>(y, x));
            for (int y = std::max(0, cy - kRadius); y <= std::min(cam.height - 1, cy + kRadius); ++y)
              for (int x = std::max(0, cx - kRadius); x <= std::min(cam.width - 1, cx + kRadius); ++x)
                if (capture.at<float>(y, x) > 0.005f * peak)
                  t.emplace_back(y * cam.width + x, v * proj.width + u, capture.at<float>(y, x));
          }
      }
    Eigen::SparseMatrix<float> a(cam.area(), proj.area());
    a.setFromTriplets(t.begin(), t.end());
    benchmark::DoNotOptimize(a.nonZeros());
  }
}
BENCHMARK(BM_ScatterBuildTriplets)->Unit(benchmark::kMillisecond);

void BM_ScatterPredict(benchmark::State& state) {
  const Fixture& f = Full();
  auto b = ScatterMatrixBuilder::Create(f.geometry, f.black, Options());
  for (int oy = 0; oy < kSpacing; ++oy)
    for (int ox = 0; ox < kSpacing; ++ox) b->Add({ox, oy, f.captures[oy * kSpacing + ox]}).IgnoreError();
  const ScatterMatrix s = std::move(b->Finish()).value();
  cv::Mat ep(s.projector_size, CV_32FC1);
  cv::randu(ep, 0.0f, 1.0f);
  for (auto _ : state) {
    auto e = s.PredictRadiance(ep);
    benchmark::DoNotOptimize(e->data);
  }
}
BENCHMARK(BM_ScatterPredict)->Unit(benchmark::kMillisecond);

void BM_FrameCopy(benchmark::State& state) {
  const Fixture& f = Full();
  for (auto _ : state) {
    cv::Mat c = f.captures[0].clone();
    benchmark::DoNotOptimize(c.data);
  }
}
BENCHMARK(BM_FrameCopy)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace inspection
