// Render speed of the simulated rig's image formation (issue: 1024x768 <= 50 ms, 1600x1200
// <= 120 ms per frame). Baseline in the same run: one 5x5 Gaussian blur of a float frame of the
// same size, so the figures can be read as ratios on any machine. "CPU" is the whole process's
// CPU time (all threads): on a loaded machine the real time can be far above it.
#include <benchmark/benchmark.h>

#include <opencv2/imgproc.hpp>

#include "devices/sim/image_formation.h"
#include "devices/sim/simulated_rig.h"
#include "devices/sim/specimen.h"

namespace inspection {
namespace {

cv::Size SizeArg(const benchmark::State& state) {
  return {static_cast<int>(state.range(0)), static_cast<int>(state.range(1))};
}

std::unique_ptr<ImageFormation> MakeRenderer(cv::Size size, const std::string& specimen) {
  SimulatedRigOptions o;
  o.camera_size = size;
  auto f = ImageFormationOptionsFor(o);
  auto s = MakeSpecimen(specimen, SpecimenGrid{size, o.pixel_size_um, o.seed});
  auto r = ImageFormation::Create(*f, *s);
  return std::move(r).value();
}

cv::Mat Checkerboard(cv::Size size, int square) {
  cv::Mat p(size, CV_8UC1);
  for (int r = 0; r < size.height; ++r) {
    for (int c = 0; c < size.width; ++c) p.at<uint8_t>(r, c) = ((r / square + c / square) % 2) ? 255 : 0;
  }
  return p;
}

// Stage mid-way through the specimen: the widest spread of defocus over the frame.
void BM_RenderUniform(benchmark::State& state) {
  auto r = MakeRenderer(SizeArg(state), state.range(2) ? "skew10" : "skew5");
  cv::Mat pattern(r->options().projector_size, CV_8UC1, cv::Scalar(128));
  double lo, hi;
  cv::minMaxLoc(r->specimen().height_um, &lo, &hi);
  const double exposure = r->ExposureForMeanGrey(128, 128);
  uint64_t seed = 0;
  for (auto _ : state) {
    auto frame = r->Render(pattern, 0.5 * (lo + hi), exposure, 0.0, ++seed);
    benchmark::DoNotOptimize(frame.ok());
  }
}
BENCHMARK(BM_RenderUniform)
    ->Args({1024, 768, 0})
    ->Args({1600, 1200, 0})
    ->Args({1600, 1200, 1})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

void BM_RenderCheckerboard(benchmark::State& state) {
  auto r = MakeRenderer(SizeArg(state), "lens");
  const cv::Mat pattern = Checkerboard(r->options().projector_size, 3);
  double lo, hi;
  cv::minMaxLoc(r->specimen().height_um, &lo, &hi);
  const double exposure = r->ExposureForMeanGrey(128, 128);
  uint64_t seed = 0;
  for (auto _ : state) {
    auto frame = r->Render(pattern, 0.5 * (lo + hi), exposure, 0.0, ++seed);
    benchmark::DoNotOptimize(frame.ok());
  }
}
BENCHMARK(BM_RenderCheckerboard)
    ->Args({1024, 768})
    ->Args({1600, 1200})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

// Far from focus (the scan's first frame): large PSFs on reduced images.
void BM_RenderFarDefocus(benchmark::State& state) {
  auto r = MakeRenderer(SizeArg(state), "skew5");
  cv::Mat pattern(r->options().projector_size, CV_8UC1, cv::Scalar(128));
  double lo, hi;
  cv::minMaxLoc(r->specimen().height_um, &lo, &hi);
  uint64_t seed = 0;
  for (auto _ : state) {
    auto frame = r->Render(pattern, lo - 20.0, 3000.0, 0.0, ++seed);
    benchmark::DoNotOptimize(frame.ok());
  }
}
BENCHMARK(BM_RenderFarDefocus)
    ->Args({1024, 768})
    ->Args({1600, 1200})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

// A 60-frame simulated scan through the rig's devices (move, capture) over skew10.
void BM_Scan60Frames(benchmark::State& state) {
  SimulatedRigOptions o;
  o.camera_size = SizeArg(state);
  o.specimen = "skew10";
  auto rig = std::move(CreateSimulatedRig(o)).value();
  const auto range = rig->simulation()->SpecimenZRangeUm();
  const double step = (range.second - range.first + 40.0) / 59.0;
  for (auto _ : state) {
    for (int i = 0; i < 60; ++i) {
      benchmark::DoNotOptimize(rig->stage().MoveTo(range.first - 20.0 + i * step).ok());
      benchmark::DoNotOptimize(rig->camera().Capture().ok());
    }
  }
}
BENCHMARK(BM_Scan60Frames)
    ->Args({1024, 768})
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

void BM_BaselineGaussian5x5(benchmark::State& state) {
  cv::Mat src(SizeArg(state), CV_32FC1), dst;
  cv::randu(src, 0.0, 1.0);
  for (auto _ : state) {
    cv::GaussianBlur(src, dst, cv::Size(5, 5), 0.0);
    benchmark::DoNotOptimize(dst.data);
  }
}
BENCHMARK(BM_BaselineGaussian5x5)
    ->Args({1024, 768})
    ->Args({1600, 1200})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

}  // namespace
}  // namespace inspection
