// inspect-bench: reconstructs a stack folder in-process and compares the SFF engine (thesis 3.1,
// Tenengrad + Gaussian by default) with a straightforward per-frame OpenCV implementation timed
// in the same run. Frames are decoded first (timed separately) and then handed to the engine from
// memory, as a camera delivers them. Without --stack it generates a 1600x1200 x 60 synthetic
// stack (tilted plane with a bump, known ground truth) in a temporary folder.
// The last line of output is one JSON object with the figures.
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>
#include <vector>

#include "core/io/depth_export.h"
#include "core/sff/sff_engine.h"
#include "core/io/stack.h"
#include "tests/bench/process_memory.h"

namespace fs = std::filesystem;
using inspection::DepthResult;
using inspection::SffEngine;
using inspection::SffOptions;

namespace {

double Now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }


// User + system CPU seconds of the whole process (all threads).
double CpuSeconds() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) + 1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

using inspection::bench::ProcStatusKb;
using inspection::bench::ResetPeakRss;

struct Args {
  std::string stack;
  std::string keep;  // generate into this folder and keep it
  int width = 1600, height = 1200, frames = 60;
  double dz_um = 0.5;
  int repeat = 3;
  bool engine_only = false;  // profiling: skip the streaming pass and the baseline
  std::string dump_depth;    // raw bytes of the results, for bit-identity checks across builds
  SffOptions options;
};

bool ParseArgs(int argc, char** argv, Args* a) {
  a->options.threads = 2;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> std::string { return i + 1 < argc ? argv[++i] : ""; };
    if (k == "--stack")
      a->stack = next();
    else if (k == "--keep")
      a->keep = next();
    else if (k == "--width")
      a->width = std::stoi(next());
    else if (k == "--height")
      a->height = std::stoi(next());
    else if (k == "--frames")
      a->frames = std::stoi(next());
    else if (k == "--dz")
      a->dz_um = std::stod(next());
    else if (k == "--repeat")
      a->repeat = std::max(1, std::stoi(next()));
    else if (k == "--engine-only")
      a->engine_only = true;
    else if (k == "--dump-depth")
      a->dump_depth = next();
    else if (k == "--no-simd")
      a->options.use_simd = false;  // portable kernels
    else if (k == "--no-avx512")
      a->options.use_avx512 = false;  // AVX2 kernels only
    else if (k == "--threads")
      a->options.threads = std::stoi(next());
    else if (k == "--window")
      a->options.window_px = std::stoi(next());
    else if (k == "--measure") {
      auto m = inspection::ParseFocusMeasure(next());
      if (!m.ok()) return std::fprintf(stderr, "%s\n", m.status().ToString().c_str()), false;
      a->options.focus_measure = *m;
    } else if (k == "--interp") {
      auto m = inspection::ParseDepthInterpolation(next());
      if (!m.ok()) return std::fprintf(stderr, "%s\n", m.status().ToString().c_str()), false;
      a->options.interpolation = *m;
    } else {
      std::fprintf(stderr,
                   "usage: inspect-bench [--stack DIR | --keep DIR] [--width 1600 --height 1200 --frames 60 --dz 0.5]\n"
                   "                     [--measure tenengrad --window 7 --interp gaussian --threads 2 --repeat 3]\n"
                   "                     [--dump-depth FILE] [--no-simd | --no-avx512]\n");
      return false;
    }
  }
  return true;
}

// Synthetic specimen: random texture, height = tilted plane + Gaussian bump (µm), each frame
// blurred with sigma = sqrt(0.6^2 + (0.7 px/µm * |z - h|)^2) / dz-scaled, plus noise.
inspection::Status GenerateStack(const fs::path& dir, const Args& a) {
  fs::create_directories(dir);
  const cv::Size size(a.width, a.height);
  cv::Mat texture(size, CV_32F);
  cv::randu(texture, -1.0, 1.0);
  cv::GaussianBlur(texture, texture, cv::Size(0, 0), 0.7);
  cv::normalize(texture, texture, 60, 200, cv::NORM_MINMAX);
  const double z_range = a.dz_um * (a.frames - 1);
  cv::Mat h(size, CV_32F);
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      const double u = double(x) / a.width, v = double(y) / a.height;
      const double bump = std::exp(-((u - 0.6) * (u - 0.6) + (v - 0.4) * (v - 0.4)) / 0.02);
      h.at<float>(y, x) = float(z_range * (0.2 + 0.35 * u + 0.15 * v + 0.2 * bump));
    }
  const double blur_per_um = 0.7 / a.dz_um;  // 0.7 px more blur per z step of defocus
  const double sigma0 = 0.6, dsig = 0.1;
  double sigma_max = std::sqrt(sigma0 * sigma0 + std::pow(blur_per_um * z_range, 2));
  sigma_max = std::min(sigma_max, 12.0);  // beyond this a frame is grey anyway
  std::vector<cv::Mat> levels;
  for (double s = 0; s <= sigma_max + dsig; s += dsig) {
    cv::Mat b;
    if (s < 0.05)
      b = texture.clone();
    else
      cv::GaussianBlur(texture, b, cv::Size(0, 0), s);
    levels.push_back(b);
  }
  inspection::StackManifest m;
  m.pixel_size_um = 0.74;
  m.bit_depth = 8;
  m.specimen = "inspect-bench synthetic plane+bump";
  cv::RNG rng(7);
  for (int k = 0; k < a.frames; ++k) {
    const double z = k * a.dz_um;
    cv::Mat f(size, CV_8U), noise(size, CV_32F);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
    for (int y = 0; y < a.height; ++y) {
      const float* hr = h.ptr<float>(y);
      const float* nr = noise.ptr<float>(y);
      uint8_t* fr = f.ptr<uint8_t>(y);
      for (int x = 0; x < a.width; ++x) {
        const double d = blur_per_um * (z - hr[x]);
        const double s = std::min(std::sqrt(sigma0 * sigma0 + d * d), sigma_max);
        const double pos = s / dsig;
        const int i = std::min(int(pos), int(levels.size()) - 2);
        const double w = pos - i;
        const double v =
            (1 - w) * levels[size_t(i)].at<float>(y, x) + w * levels[size_t(i) + 1].at<float>(y, x) + nr[x];
        fr[x] = cv::saturate_cast<uint8_t>(v);
      }
    }
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%04d.png", k);
    if (!cv::imwrite((dir / name).string(), f, {cv::IMWRITE_PNG_COMPRESSION, 1})) {
      return inspection::Status::Internal(std::string("cannot write ") + name);
    }
    m.frames.push_back({name, z, 8000.0, "uniform:128"});
  }
  inspection::DepthExportMeta meta;
  meta.pixel_size_um = m.pixel_size_um;
  meta.description = "ground truth";
  INSPECT_RETURN_IF_ERROR(inspection::WriteDepthTiff(dir / inspection::kGroundTruthDepthName, h, meta));
  return inspection::WriteStackManifest(dir, m);
}

// The straightforward per-frame OpenCV implementation of Tenengrad + running argmax + three-
// point Gaussian: whole-frame calls, one after the other, as one would first write it.
cv::Mat BaselineTenengradGaussian(const std::vector<cv::Mat>& frames, const std::vector<double>& z, int window) {
  const cv::Size size = frames[0].size();
  cv::Mat best(size, CV_32F, cv::Scalar(-1)), prev(size, CV_32F, cv::Scalar(0)), next(size, CV_32F, cv::Scalar(0));
  cv::Mat last(size, CV_32F, cv::Scalar(0)), idx(size, CV_32S, cv::Scalar(0)), aif(size, frames[0].type());
  cv::Mat gx, gy, fm, gt, was_best, take_next;
  for (size_t k = 0; k < frames.size(); ++k) {
    cv::Sobel(frames[k], gx, CV_32F, 1, 0, 3, 1, 0, cv::BORDER_REFLECT_101);
    cv::Sobel(frames[k], gy, CV_32F, 0, 1, 3, 1, 0, cv::BORDER_REFLECT_101);
    fm = gx.mul(gx) + gy.mul(gy);
    cv::boxFilter(fm, fm, -1, cv::Size(window, window), cv::Point(-1, -1), false, cv::BORDER_REFLECT_101);
    cv::compare(fm, best, gt, cv::CMP_GT);
    cv::compare(idx, int(k) - 1, was_best, cv::CMP_EQ);
    cv::bitwise_and(was_best, ~gt, take_next);
    fm.copyTo(next, take_next);
    last.copyTo(prev, gt);
    next.setTo(0, gt);
    fm.copyTo(best, gt);
    idx.setTo(int(k), gt);
    frames[k].copyTo(aif, gt);
    std::swap(last, fm);
  }
  cv::Mat depth(size, CV_32F);
  const int n = int(z.size());
  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      const int m = idx.at<int>(y, x);
      double d = z[size_t(m)];
      const float f1 = prev.at<float>(y, x), f2 = best.at<float>(y, x), f3 = next.at<float>(y, x);
      if (m > 0 && m < n - 1 && f1 > 0 && f2 > 0 && f3 > 0) {
        const double a = std::log(f2 / f1), b = std::log(f2 / f3);
        const double u1 = z[size_t(m) - 1] - z[size_t(m)], u3 = z[size_t(m) + 1] - z[size_t(m)];
        const double den = a * u3 - b * u1;
        if (den != 0) d += (a * u3 * u3 - b * u1 * u1) / (2 * den);
      }
      depth.at<float>(y, x) = float(d);
    }
  }
  return depth;
}

// --dump-depth: depth_um, confidence and all_in_focus of each result, raw row-major bytes one
// after the other (batch result first, then the first streaming pass unless --engine-only), so
// that two builds can be compared with cmp or sha256sum.
bool DumpResults(const std::string& path, const std::vector<const DepthResult*>& results) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  for (const DepthResult* r : results) {
    for (const cv::Mat* m : {&r->depth_um, &r->confidence, &r->all_in_focus}) {
      const cv::Mat c = m->isContinuous() ? *m : m->clone();
      out.write(reinterpret_cast<const char*>(c.data), std::streamsize(c.total() * c.elemSize()));
    }
  }
  return bool(out.flush());
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (!ParseArgs(argc, argv, &a)) return 2;
  fs::path dir = a.stack;
  bool remove_dir = false;
  double generate_s = 0;
  if (dir.empty()) {
    dir = a.keep.empty() ? fs::temp_directory_path() / ("inspect_bench_stack_" + std::to_string(::getpid()))
                         : fs::path(a.keep);
    remove_dir = a.keep.empty();
    const double t0 = Now();
    auto st = GenerateStack(dir, a);
    generate_s = Now() - t0;
    if (!st.ok()) {
      std::fprintf(stderr, "generate: %s\n", st.ToString().c_str());
      return 1;
    }
    std::fprintf(stderr, "generated %dx%d x %d frames in %s (%.1f s)\n", a.width, a.height, a.frames, dir.c_str(),
                 generate_s);
  }

  // Load/decode, timed on its own.
  const double t_load = Now();
  auto manifest = inspection::ReadStackManifest(dir);
  if (!manifest.ok()) {
    std::fprintf(stderr, "%s\n", manifest.status().ToString().c_str());
    return 1;
  }
  std::vector<cv::Mat> frames;
  std::vector<double> z;
  for (size_t k = 0; k < manifest->frames.size(); ++k) {
    auto f = inspection::LoadStackFrame(dir, *manifest, k);
    if (!f.ok()) {
      std::fprintf(stderr, "%s\n", f.status().ToString().c_str());
      return 1;
    }
    frames.push_back(*f);
    z.push_back(manifest->frames[k].z_um);
  }
  const double load_s = Now() - t_load;
  size_t frame_bytes = 0;
  for (const auto& f : frames) frame_bytes += f.total() * f.elemSize();

  // Engine, batch path (tiles across all frames), best of `repeat`; peak RSS of this phase.
  const long rss_before_kb = ProcStatusKb("VmRSS");
  const bool peak_reset = ResetPeakRss();
  double engine_s = 1e9, engine_cpu_s = 1e9;
  DepthResult result;
  for (int r = 0; r < a.repeat; ++r) {
    const double t0 = Now(), c0 = CpuSeconds();
    auto res = SffEngine::ReconstructInMemory(a.options, frames, z);
    const double t = Now() - t0;
    engine_cpu_s = std::min(engine_cpu_s, CpuSeconds() - c0);
    if (!res.ok()) {
      std::fprintf(stderr, "%s\n", res.status().ToString().c_str());
      return 1;
    }
    engine_s = std::min(engine_s, t);
    result = std::move(res).value();
  }
  const long engine_peak_kb = ProcStatusKb("VmHWM");
  std::vector<const DepthResult*> dumped = {&result};
  DepthResult first_streamed;
  auto dump = [&]() {
    if (a.dump_depth.empty() || DumpResults(a.dump_depth, dumped)) return true;
    std::fprintf(stderr, "cannot write %s\n", a.dump_depth.c_str());
    return false;
  };
  if (a.engine_only) {
    if (!dump()) return 1;
    std::printf("{\"engine_seconds\": %.4f, \"engine_cpu_seconds\": %.4f}\n", engine_s, engine_cpu_s);
    return 0;
  }

  // Engine, streaming path: PushFrame per frame as a camera delivers them, then Finish; best of
  // `repeat` passes (one engine alive at a time, so the peak RSS is that of one pass).
  double push_total_s = 1e9, push_max_s = 0, finish_s = 1e9;
  size_t state_bytes = 0;
  for (int r = 0; r < a.repeat; ++r) {
    auto engine = SffEngine::Create(a.options, frames[0].size(), frames[0].type());
    if (!engine.ok()) return 1;
    state_bytes = (*engine)->state_bytes();
    double total = 0, worst = 0;
    for (size_t k = 0; k < frames.size(); ++k) {
      const double t0 = Now();
      if (!(*engine)->PushFrame(frames[k], z[k]).ok()) return 1;
      const double t = Now() - t0;
      total += t;
      worst = std::max(worst, t);
    }
    const double t0 = Now();
    auto streamed = (*engine)->Finish();
    finish_s = std::min(finish_s, Now() - t0);
    if (!streamed.ok()) return 1;
    if (total < push_total_s) {
      push_total_s = total;
      push_max_s = worst;
    }
    if (r > 0) continue;
    if (!a.dump_depth.empty()) {  // kept only when dumped: it would count in the streaming peak RSS
      first_streamed = *streamed;
      dumped.push_back(&first_streamed);
    }
    cv::Mat diff = streamed->depth_um != result.depth_um;
    cv::Mat both_nan = (streamed->depth_um != streamed->depth_um) & (result.depth_um != result.depth_um);
    const int differing = cv::countNonZero(diff & ~both_nan);
    if (differing) std::fprintf(stderr, "WARNING: streaming and batch differ at %d pixels\n", differing);
  }
  const long streaming_peak_kb = ProcStatusKb("VmHWM");
  if (!dump()) return 1;

  // Baseline: straightforward per-frame OpenCV, best of `repeat` (OpenCV's own threading).
  double baseline_s = 1e9, baseline_cpu_s = 1e9;
  cv::Mat baseline_depth;
  for (int r = 0; r < a.repeat; ++r) {
    const double t0 = Now(), c0 = CpuSeconds();
    baseline_depth = BaselineTenengradGaussian(frames, z, a.options.window_px);
    baseline_s = std::min(baseline_s, Now() - t0);
    baseline_cpu_s = std::min(baseline_cpu_s, CpuSeconds() - c0);
  }

  // Accuracy against the ground truth when there is one, and agreement with the baseline.
  nlohmann::json j;
  auto truth = inspection::ReadDepthTiff(dir / inspection::kGroundTruthDepthName);
  const double dz = z.size() > 1 ? std::abs(z[1] - z[0]) : 1.0;
  if (truth.ok() && truth->size() == result.depth_um.size()) {
    double sq = 0;
    size_t n = 0;
    for (int y = 0; y < truth->rows; ++y)
      for (int x = 0; x < truth->cols; ++x) {
        const float d = result.depth_um.at<float>(y, x);
        if (!std::isfinite(d)) continue;
        sq += std::pow(d - truth->at<float>(y, x), 2);
        ++n;
      }
    j["rmse_um"] = n ? std::sqrt(sq / n) : 0.0;
    j["rmse_steps"] = n ? std::sqrt(sq / n) / dz : 0.0;
  }
  {
    size_t agree = 0, n = 0;
    for (int y = 0; y < baseline_depth.rows; ++y)
      for (int x = 0; x < baseline_depth.cols; ++x) {
        const float d = result.depth_um.at<float>(y, x);
        if (!std::isfinite(d)) continue;
        ++n;
        agree += std::abs(d - baseline_depth.at<float>(y, x)) < 0.01 * dz;
      }
    j["baseline_agreement"] = n ? double(agree) / n : 0.0;
  }
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  j["stack"] = dir.string();
  j["width"] = frames[0].cols;
  j["height"] = frames[0].rows;
  j["frames"] = int(frames.size());
  j["measure"] = inspection::FocusMeasureName(a.options.focus_measure);
  j["window_px"] = a.options.window_px;
  j["interpolation"] = inspection::DepthInterpolationName(a.options.interpolation);
  j["threads"] = a.options.threads;
  j["generate_seconds"] = generate_s;
  j["load_seconds"] = load_s;
  j["engine_seconds"] = engine_s;
  j["streaming_push_seconds_total"] = push_total_s;
  j["streaming_push_ms_per_frame"] = 1e3 * push_total_s / double(frames.size());
  j["streaming_push_ms_max"] = 1e3 * push_max_s;
  j["streaming_finish_seconds"] = finish_s;
  j["streaming_seconds"] = push_total_s + finish_s;  // all pushes plus Finish: the streaming engine's time
  j["streaming_speedup_vs_baseline"] = baseline_s / (push_total_s + finish_s);
  j["streaming_state_bytes_per_pixel"] = double(state_bytes) / double(frames[0].total());
  j["engine_cpu_seconds"] = engine_cpu_s;
  j["baseline_seconds"] = baseline_s;
  j["baseline_cpu_seconds"] = baseline_cpu_s;
  j["cpu_speedup_vs_baseline"] = baseline_cpu_s / engine_cpu_s;
  double load_avg[1] = {0};
  if (getloadavg(load_avg, 1) == 1) j["load_average_1min"] = load_avg[0];
  j["speedup_vs_baseline"] = baseline_s / engine_s;
  j["valid_fraction"] = result.valid_fraction;
  j["frames_mb"] = double(frame_bytes) / 1e6;
  j["engine_extra_mb"] = peak_reset ? double(engine_peak_kb - rss_before_kb) / 1024.0 : -1.0;
  j["streaming_extra_mb"] = peak_reset ? double(streaming_peak_kb - rss_before_kb) / 1024.0 : -1.0;
  j["peak_rss_mb"] = double(ru.ru_maxrss) / 1024.0;
  if (remove_dir) fs::remove_all(dir);
  std::printf("%s\n", j.dump().c_str());
  return 0;
}
