// Speed of one compensation solve per frame (thesis 5.1, eq. 5.5-5.6 and 5.11 via LSCG on the
// low-passed sparse system) for a 1280x720 projector, which must not slow the scan (<= 30 ms).
// Two geometries: the thesis's (1024x768 camera, 3.4 camera px per projector px, the camera sees
// a 301x226 projector window) and a worst case where all 921600 projector pixels reach a
// 1280x720 camera (1 px per projector px, 3x3 patches). Baseline in the same run: one
// prediction A e_p (BM_ScatterPredict), so the figures read as ratios on any machine.
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "core/illumination/compensation.h"

namespace inspection {
namespace {

struct Models {
  CameraResponseFunction crf;
  ProjectorResponseFunction prf;
  ScatterMatrix scatter;
  cv::Mat frame;
};

Models* MakeModels(cv::Size camera, double ratio, int radius, double sigma) {
  auto* m = new Models;
  m->crf.levels = 256;
  for (int z = 0; z < 256; ++z) m->crf.log_exposure.push_back(std::log(std::max(z, 1) / 128.0));
  for (int i = 0; i < 256; ++i) m->prf.relative_irradiance.push_back(0.002 + 0.998 * (i / 255.0) * (i / 255.0));
  ScatterMatrix& s = m->scatter;
  s.camera_size = camera;
  s.projector_size = {1280, 720};
  s.projector_black_irradiance = 0.002;
  s.black_radiance = cv::Mat(camera, CV_32FC1, cv::Scalar(0.002f));
  std::vector<Eigen::Triplet<float, int>> t;
  for (int v = 0; v < 720; ++v) {
    for (int u = 0; u < 1280; ++u) {
      const double cx = camera.width / 2.0 + (u - 640) * ratio, cy = camera.height / 2.0 + (v - 360) * ratio;
      for (int dy = -radius; dy <= radius; ++dy) {
        for (int dx = -radius; dx <= radius; ++dx) {
          const int x = int(std::lround(cx)) + dx, y = int(std::lround(cy)) + dy;
          if (x < 0 || y < 0 || x >= camera.width || y >= camera.height) continue;
          const double d2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
          t.emplace_back(y * camera.width + x, v * 1280 + u, float(std::exp(-d2 / (2 * sigma * sigma))));
        }
      }
    }
  }
  s.a.resize(camera.area(), 1280 * 720);
  s.a.setFromTriplets(t.begin(), t.end());
  // A frame of a two-reflectance scene under grey 128 (one half saturated).
  m->frame = cv::Mat(camera, CV_8UC1, cv::Scalar(40));
  m->frame(cv::Rect(camera.width / 2, 0, camera.width / 2, camera.height)).setTo(255);
  return m;
}

const Models& Thesis() {
  static const Models* m = MakeModels({1024, 768}, 3.4, 4, 1.25);
  return *m;
}
const Models& Dense() {
  static const Models* m = MakeModels({1280, 720}, 1.0, 1, 0.7);
  return *m;
}

void Step(benchmark::State& state, const Models& m) {
  CompensationOptions o;  // defaults: 4 px low-pass grid, 12 LSCG iterations
  auto c = Compensator::Create(m.crf, m.prf, m.scatter, o).value();
  const cv::Mat irr = m.prf.IrradianceImage(cv::Mat(m.scatter.projector_size, CV_8UC1, cv::Scalar(128)));
  const cv::Mat desired(m.scatter.camera_size, CV_32FC1, cv::Scalar(128.0f));
  int it = 0;
  for (auto _ : state) {
    auto st = c->Step(irr, m.frame, 1.0, desired);
    it = st->solver_iterations;
    benchmark::DoNotOptimize(st->pattern.data);
  }
  state.counters["nnz_A"] = double(m.scatter.a.nonZeros());
  state.counters["lscg_iterations"] = it;
}

void Predict(benchmark::State& state, const Models& m) {
  const cv::Mat irr(m.scatter.projector_size, CV_32FC1, cv::Scalar(0.25f));
  for (auto _ : state) benchmark::DoNotOptimize(m.scatter.PredictRadiance(irr)->data);
}

void BM_CompensationStepThesisGeometry(benchmark::State& s) { Step(s, Thesis()); }
void BM_ScatterPredictThesisGeometry(benchmark::State& s) { Predict(s, Thesis()); }
void BM_CompensationStepFullProjector(benchmark::State& s) { Step(s, Dense()); }
void BM_ScatterPredictFullProjector(benchmark::State& s) { Predict(s, Dense()); }
BENCHMARK(BM_CompensationStepThesisGeometry)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ScatterPredictThesisGeometry)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CompensationStepFullProjector)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ScatterPredictFullProjector)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace inspection
