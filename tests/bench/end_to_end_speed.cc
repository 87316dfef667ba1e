// e2e-bench: `inspectctl reconstruct --stack` end to end with server and client
// in this process on loopback: a generated stack (default 60 x 1600x1200 8-bit PNG, a textured
// tilted wavy surface, defocus growing with |z - surface|) is uploaded, reconstructed with the
// request's defaults (the streaming SFF engine of thesis 3.1, estimated alignment) and its result
// files downloaded. Prints per run the phase times
//   upload    first byte sent -> last chunk sent (frames decode meanwhile on the new path)
//   decode    last chunk sent -> the job exists (the frames still decoding and the whole-stack
//             check; the baseline decodes every frame here, one after another)
//   engine    the job's reconstruction: alignment and the SFF engine (the baseline decodes every
//             frame again in it); "engine_s" is the job's own figure
//   artifacts writing and hashing the result files, publication
//   download  the result files to the client
// and the process's peak RSS above its level before the run, against the decoded stack's size.
// The baseline is the sequential path (ReconstructPipelineOptions::sequential: decode after the
// upload, then one frame after another), run alternately with the parallel path in the same process: the machine is shared
// and noisy, so only the ratios mean anything. Each run's depth, confidence and all-in-focus are
// compared bit for bit with the first run's.
//
//   e2e-bench [--frames 60] [--width 1600] [--height 1200] [--runs 2] [--colour]
//             [--alignment none|estimate] [--dense on|off] [--work DIR] [--decode-threads 0] [--verbose]
//             [--only parallel|sequential]   (one path alone, e.g. under perf; no ratios)
//             [--focus-stack BIN]   (also time `BIN --nocrop --depthmap=...` on the same PNGs, once
//                                    per run between ours, and print ours against it)
//             [--renderer own|lens]  (own: the wavy surface below; lens: chain_lens_renderer, a
//                                    terraced scene through a thin lens that shares no code with it)
//             [--moving]             (lens only: scale 3 %, shift 30/-12 px over the stack)
//             [--warp-floor]         (no reconstruction: time cv::warpAffine of the stack's frames,
//                                    INTER_LINEAR and INTER_LANCZOS4, and reading + INTER_AREA
//                                    resizing of 13 frames to 256 px, the costs alignment cannot undercut)
// Each run prints what the alignment decided (DepthSummary.alignment_detail).
#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <thread>
#include <vector>

#include "client_cli/inspection_client.h"
#include "server/app/inspection_server.h"
#include "tests/bench/chain_lens_renderer.h"
#include "tests/bench/process_memory.h"

namespace fs = std::filesystem;
namespace v1 = inspection::v1;
using inspection::client::ClientOptions;
using inspection::client::InspectionClient;

namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }


using inspection::bench::ProcStatusKb;
using inspection::bench::ResetPeakRss;

struct Args {
  int frames = 60, width = 1600, height = 1200, runs = 2, decode_threads = 0;
  bool colour = false, verbose = false, moving = false, warp_floor = false;
  std::string renderer = "own";  // "own" (the wavy surface) or "lens" (chain_lens_renderer)
  std::string alignment;  // empty = the request's default (estimate, unaligned when it fails)
  std::string dense;      // "on" / "off": ReconstructionOptions.dense_depth; empty = the request's default
  std::string only;       // "parallel" or "sequential": that path alone (profiling)
  std::string focus_stack;  // focus-stack's binary: timed per run as the external baseline
  fs::path work = fs::temp_directory_path() / "e2e-bench";
};

bool ParseArgs(int argc, char** argv, Args* a) {
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    const char* v = nullptr;
    if (k == "--colour") {
      a->colour = true;
    } else if (k == "--verbose") {
      a->verbose = true;
    } else if (k == "--moving") {
      a->moving = true;
    } else if (k == "--warp-floor") {
      a->warp_floor = true;
    } else if (k == "--renderer" && (v = next())) {
      a->renderer = v;
      if (a->renderer != "own" && a->renderer != "lens") return false;
    } else if ((k == "--frames" || k == "--width" || k == "--height" || k == "--runs" || k == "--decode-threads") &&
               (v = next())) {
      const int n = std::atoi(v);
      if (n < 0 || (k != "--decode-threads" && n < 1)) return false;
      (k == "--frames" ? a->frames : k == "--width" ? a->width : k == "--height" ? a->height : k == "--runs" ? a->runs : a->decode_threads) = n;
    } else if (k == "--alignment" && (v = next())) {
      a->alignment = v;
      if (a->alignment != "none" && a->alignment != "estimate") return false;
    } else if (k == "--dense" && (v = next())) {
      a->dense = v;
      if (a->dense != "on" && a->dense != "off") return false;
    } else if (k == "--only" && (v = next())) {
      a->only = v;
      if (a->only != "parallel" && a->only != "sequential") return false;
    } else if (k == "--work" && (v = next())) {
      a->work = v;
    } else if (k == "--focus-stack" && (v = next())) {
      a->focus_stack = v;
    } else {
      return false;
    }
  }
  if (a->moving && a->renderer != "lens") return false;
  if (a->renderer == "lens" && a->colour) return false;  // the lens renderer is grey only
  return a->frames >= 3 && a->width >= 32 && a->height >= 32;
}

// focus-stack's whole-process wall time on the stack's PNGs (its depth map and merged image go to
// the work folder); < 0 when it fails.
double TimeFocusStack(const Args& a, const fs::path& stack) {
  std::string cmd = "'" + a.focus_stack + "' --nocrop --depthmap='" + (a.work / "focus_stack_depth.png").string() +
                    "' --output='" + (a.work / "focus_stack_merged.jpg").string() + "'";
  for (int k = 0; k < a.frames; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", k);
    cmd += " '" + (stack / name).string() + "'";
  }
  cmd += " > '" + (a.work / "focus_stack.log").string() + "' 2>&1";
  const auto t0 = Clock::now();
  const int rc = std::system(cmd.c_str());
  const double s = Seconds(t0, Clock::now());
  return rc == 0 ? s : -1.0;
}

// The lens renderer's stack as PNGs (1 um per frame), reused like GenerateStack's.
fs::path GenerateLensStack(const Args& a) {
  char tag[96];
  std::snprintf(tag, sizeof tag, "lens_%dx%dx%d%s", a.width, a.height, a.frames, a.moving ? "_moving" : "_still");
  const fs::path dir = a.work / tag;
  if (fs::exists(dir / "stack.json")) return dir;
  fs::remove_all(dir);
  fs::create_directories(dir);
  chain_bench::LensStackOptions o;
  o.size = cv::Size(a.width, a.height);
  o.frames = a.frames;
  o.seed = 1;
  if (a.moving) {
    o.scale_total = 0.03;
    o.shift_x_total_px = 30.0;
    o.shift_y_total_px = -12.0;
  }
  const chain_bench::LensStack stack = chain_bench::RenderLensStack(o);
  std::ofstream json(dir / "stack.json.tmp");
  json << R"({"format": "inspection-stack", "version": 1, "pixel_size_um": 1.0, "bit_depth": 8, "frames": [)";
  for (int k = 0; k < a.frames; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", k);
    cv::imwrite((dir / name).string(), stack.frames[size_t(k)]);
    json << (k ? "," : "") << R"({"file": ")" << name << R"(", "z_um": )" << double(k) << "}";
  }
  json << "]}\n";
  json.close();
  fs::rename(dir / "stack.json.tmp", dir / "stack.json");
  return dir;
}

// The stack: frame k = the texture blurred by sigma(|z_k - h(x, y)|), interpolated between
// precomputed blur levels. Reused when stack.json says it was made with the same parameters.
fs::path GenerateStack(const Args& a) {
  char tag[96];
  std::snprintf(tag, sizeof tag, "stack_%dx%dx%d%s", a.width, a.height, a.frames, a.colour ? "_rgb" : "");
  const fs::path dir = a.work / tag;
  if (fs::exists(dir / "stack.json")) return dir;
  fs::remove_all(dir);
  fs::create_directories(dir);
  const cv::Size size(a.width, a.height);
  const int channels = a.colour ? 3 : 1;
  cv::RNG rng(16);
  cv::Mat coarse(size.height / 8 + 1, size.width / 8 + 1, CV_8UC(channels)), fine(size, CV_8UC(channels)), texture;
  rng.fill(coarse, cv::RNG::UNIFORM, cv::Scalar::all(30), cv::Scalar::all(225));
  rng.fill(fine, cv::RNG::UNIFORM, cv::Scalar::all(-40), cv::Scalar::all(40));
  cv::resize(coarse, texture, size, 0, 0, cv::INTER_CUBIC);
  cv::add(texture, fine, texture, cv::noArray(), CV_8UC(channels));
  const double dz_um = 1.0, max_defocus_um = 12.0, level_um = 0.5;
  std::vector<cv::Mat> levels;  // blur at defocus 0, 0.5, ... 12 um
  for (double d = 0; d <= max_defocus_um + 1e-9; d += level_um) {
    cv::Mat b;
    cv::GaussianBlur(texture, b, cv::Size(0, 0), 0.4 + 0.6 * d);
    levels.push_back(b);
  }
  cv::Mat height_um(size, CV_32F);
  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      height_um.at<float>(y, x) = float(a.frames * dz_um * (0.15 + 0.7 * x / size.width) +
                                        3.0 * std::sin(2 * M_PI * y / size.height * 2));
    }
  }
  std::ofstream json(dir / "stack.json.tmp");
  json << R"({"format": "inspection-stack", "version": 1, "pixel_size_um": 1.0, "bit_depth": 8, "frames": [)";
  cv::Mat frame(size, CV_8UC(channels));
  for (int k = 0; k < a.frames; ++k) {
    const double z = k * dz_um;
    for (int y = 0; y < size.height; ++y) {
      const float* h = height_um.ptr<float>(y);
      uchar* out = frame.ptr<uchar>(y);
      for (int x = 0; x < size.width; ++x) {
        const double l = std::min(std::abs(z - h[x]), max_defocus_um) / level_um;
        const int i = std::min(int(l), int(levels.size()) - 2);
        const double f = l - i;
        const uchar* p0 = levels[size_t(i)].ptr<uchar>(y) + x * channels;
        const uchar* p1 = levels[size_t(i) + 1].ptr<uchar>(y) + x * channels;
        for (int c = 0; c < channels; ++c) out[x * channels + c] = cv::saturate_cast<uchar>(p0[c] + f * (p1[c] - p0[c]));
      }
    }
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", k);
    cv::imwrite((dir / name).string(), frame);
    json << (k ? "," : "") << R"({"file": ")" << name << R"(", "z_um": )" << z << "}";
  }
  json << "]}\n";
  json.close();
  fs::rename(dir / "stack.json.tmp", dir / "stack.json");
  return dir;
}

struct Phases {
  std::string alignment;  // what the alignment decided (DepthSummary.alignment_detail)
  double upload = 0, decode = 0, engine = 0, artifacts = 0, download = 0, total = 0;
  double engine_s = 0;  // the job's own engine figure (DepthSummary.engine_seconds)
  double peak_rss_mb = 0;      // above the process's RSS before the run (the server's share)
  double peak_rss_abs_mb = 0;  // the whole process (server, client, libraries)
};

struct Outputs {
  cv::Mat depth, confidence, all_in_focus;
};

bool SameBytes(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int y = 0; y < a.rows; ++y)
    if (std::memcmp(a.ptr(y), b.ptr(y), a.cols * a.elemSize()) != 0) return false;
  return true;
}

// One reconstruction against a fresh server; false (with a message) when anything failed.
bool RunOnce(const Args& a, const fs::path& stack, bool sequential, int run, Phases* p, Outputs* out) {
  const std::string name = std::string(sequential ? "sequential" : "parallel") + "_" + std::to_string(run);
  const fs::path data = a.work / ("data_" + name), results = a.work / ("results_" + name);
  fs::remove_all(data);
  fs::remove_all(results);
  ResetPeakRss();
  const long rss_before_kb = ProcStatusKb("VmRSS");
  inspection::ServerOptions so;
  so.listen_address = "127.0.0.1:0";
  so.data_dir = data;
  so.no_rig = true;
  so.reconstruct.sequential = sequential;
  so.reconstruct.decode_threads = a.decode_threads;
  auto server = inspection::InspectionServer::Start(so);
  if (!server.ok()) {
    std::cerr << "e2e-bench: server: " << server.status().ToString() << "\n";
    return false;
  }
  ClientOptions co;
  co.target = (*server)->address();
  InspectionClient client(co);
  if (!client.WaitConnected().ok()) return false;
  v1::ReconstructStart start;
  if (a.alignment == "none") start.mutable_options()->set_alignment(v1::FRAME_ALIGNMENT_NONE);
  if (a.alignment == "estimate") start.mutable_options()->set_alignment(v1::FRAME_ALIGNMENT_ESTIMATE);
  if (!a.dense.empty()) start.mutable_options()->set_dense_depth(a.dense == "on");

  Clock::time_point t_upload{}, t_job{}, t_storing{}, t_done{};
  const auto t0 = Clock::now();
  v1::Job job;
  grpc::Status st = client.ReconstructUpload(
      stack, start,
      [&](const v1::JobEvent& e) {
        const auto now = Clock::now();
        if (t_job == Clock::time_point{}) t_job = now;
        if (e.phase() == v1::JOB_PHASE_STORING && t_storing == Clock::time_point{}) t_storing = now;
        if (e.has_job()) t_done = now;
      },
      &job,
      [&](int64_t done, int64_t total) {
        if (done >= total) t_upload = Clock::now();
      });
  if (!st.ok()) {
    std::cerr << "e2e-bench: reconstruct: " << st.error_message() << "\n";
    return false;
  }
  const auto t_dl0 = Clock::now();
  std::vector<fs::path> written;
  st = client.DownloadResults(job, results, false, &written);
  const auto t_end = Clock::now();
  if (!st.ok()) {
    std::cerr << "e2e-bench: download: " << st.error_message() << "\n";
    return false;
  }
  p->peak_rss_abs_mb = double(ProcStatusKb("VmHWM")) / 1024.0;
  p->peak_rss_mb = p->peak_rss_abs_mb - double(rss_before_kb) / 1024.0;
  p->upload = Seconds(t0, t_upload);
  p->decode = Seconds(t_upload, t_job);
  p->engine = Seconds(t_job, t_storing);
  p->artifacts = Seconds(t_storing, t_done);
  p->download = Seconds(t_dl0, t_end);
  p->total = Seconds(t0, t_end);
  p->engine_s = job.result().depth().engine_seconds();
  {
    const v1::AlignmentDetail& d = job.result().depth().alignment_detail();
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s%s stat %.2f/%.2f max corner %.2f px", d.method().empty() ? "none" : d.method().c_str(),
                  d.still() ? " still" : !d.fallback_reason().empty() ? " fallback" : !d.method().empty() ? " warped" : "",
                  d.still_statistic(), d.still_threshold(), d.max_corner_displacement_px());
    p->alignment = buf;
    double max_scale = 0, max_shift = 0;  // the warp applied, largest over the frames
    for (const v1::FrameTransform& f : d.frames()) {
      max_scale = std::max(max_scale, std::abs(f.scale() - 1.0) * 100.0);
      max_shift = std::max(max_shift, std::hypot(f.shift_x_px(), f.shift_y_px()));
    }
    std::snprintf(buf, sizeof buf, "; %d frames, max scale change %.3f %%, max shift %.2f px", d.frames_size(),
                  max_scale, max_shift);
    p->alignment += buf;
    if (!d.fallback_reason().empty()) p->alignment += "; fallback: " + d.fallback_reason();
    if (!d.decision().empty()) p->alignment += "; why: " + d.decision();
  }
  (*server)->Shutdown();
  out->depth = cv::imread((results / "depth.tiff").string(), cv::IMREAD_UNCHANGED);
  out->confidence = cv::imread((results / "confidence.tiff").string(), cv::IMREAD_UNCHANGED);
  out->all_in_focus = cv::imread((results / "all_in_focus.png").string(), cv::IMREAD_UNCHANGED);
  fs::remove_all(data);
  fs::remove_all(results);
  return !out->depth.empty() && !out->confidence.empty() && !out->all_in_focus.empty();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

// The floor under any alignment of this stack: warping every frame once (the aligner's warp,
// both interpolations) and the registration's input (13 frames read and shrunk to 256 px).
int WarpFloor(const Args& a, const fs::path& stack) {
  std::vector<cv::Mat> frames;
  for (int k = 0; k < a.frames; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", k);
    frames.push_back(cv::imread((stack / name).string(), cv::IMREAD_UNCHANGED));
    if (frames.back().empty()) return 1;
  }
  const cv::Matx23d m(1.01, 0.002, 3.3, -0.002, 1.01, -1.7);
  for (int run = 0; run < a.runs; ++run) {
    for (int interp : {cv::INTER_LINEAR, cv::INTER_LANCZOS4}) {
      cv::Mat out;
      const auto t0 = Clock::now();
      for (const cv::Mat& f : frames) cv::warpAffine(f, out, m, f.size(), interp, cv::BORDER_REPLICATE);
      std::printf("warp floor run %d: %d frames warpAffine %-8s %.3f s\n", run, a.frames,
                  interp == cv::INTER_LINEAR ? "LINEAR" : "LANCZOS4", Seconds(t0, Clock::now()));
    }
    const auto t0 = Clock::now();
    const int n = std::min(13, a.frames);
    for (int i = 0; i < n; ++i) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%04d.png", i * (a.frames - 1) / std::max(1, n - 1));
      const cv::Mat f = cv::imread((stack / name).string(), cv::IMREAD_UNCHANGED);
      cv::Mat small;
      const double s = 256.0 / std::max(f.cols, f.rows);
      cv::resize(f, small, cv::Size(), s, s, cv::INTER_AREA);
    }
    std::printf("warp floor run %d: read + INTER_AREA to 256 px of %d frames %.3f s\n", run, n,
                Seconds(t0, Clock::now()));
    std::fflush(stdout);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  if (!ParseArgs(argc, argv, &a)) {
    std::cerr << "usage: e2e-bench [--frames 60] [--width 1600] [--height 1200] [--runs 2] [--colour]\n"
                 "                 [--alignment none|estimate] [--dense on|off] [--work DIR] [--decode-threads 0]\n"
                 "                 [--verbose] [--only parallel|sequential] [--focus-stack BIN]\n"
                 "                 [--renderer own|lens] [--moving] [--warp-floor]\n";
    return 2;
  }
  // The servers' per-job lines would bury the table; --verbose shows them with the jobs' timings.
  spdlog::set_level(a.verbose ? spdlog::level::debug : spdlog::level::warn);
  fs::create_directories(a.work);
  const auto tg = Clock::now();
  const fs::path stack = a.renderer == "lens" ? GenerateLensStack(a) : GenerateStack(a);
  std::printf("stack (%s%s): %d x %dx%d 8-bit %s PNG in %s (ready in %.1f s)\n", a.renderer.c_str(), a.moving ? ", moving" : "",
              a.frames, a.width, a.height, a.colour ? "colour" : "grey", stack.c_str(), Seconds(tg, Clock::now()));
  const double decoded_mb = double(a.frames) * a.width * a.height * (a.colour ? 3 : 1) / (1024.0 * 1024.0);
  std::printf("decoded stack: %.1f MiB; alignment: %s; dense depth: %s; hardware threads: %u\n", decoded_mb,
              a.alignment.empty() ? "request default (estimate)" : a.alignment.c_str(),
              a.dense.empty() ? "request default" : a.dense.c_str(),
              std::thread::hardware_concurrency());

  if (a.warp_floor) return WarpFloor(a, stack);
  std::map<bool, std::vector<Phases>> by_path;  // sequential? -> runs
  Outputs first;
  bool identical = true;
  std::printf("\n%-12s %3s %8s %8s %8s %9s %8s %8s %8s %9s\n", "path", "run", "upload", "decode", "engine",
              "artifacts", "download", "total", "engine_s", "peakRSS");
  std::vector<double> focus_stack_s;
  for (int run = 0; run < a.runs; ++run) {
    if (!a.focus_stack.empty()) {
      const double t = TimeFocusStack(a, stack);
      if (t < 0) {
        std::cerr << "e2e-bench: " << a.focus_stack << " failed; see " << (a.work / "focus_stack.log").string() << "\n";
        return 1;
      }
      focus_stack_s.push_back(t);
      std::printf("%-12s %3d %62.3f\n", "focus-stack", run, t);
    }
    for (bool sequential : {true, false}) {
      if (!a.only.empty() && sequential != (a.only == "sequential")) continue;
      Phases p;
      Outputs o;
      if (!RunOnce(a, stack, sequential, run, &p, &o)) return 1;
      if (first.depth.empty()) {
        first = o;
      } else {
        identical = identical && SameBytes(first.depth, o.depth) && SameBytes(first.confidence, o.confidence) &&
                    SameBytes(first.all_in_focus, o.all_in_focus);
      }
      by_path[sequential].push_back(p);
      std::printf("%-12s %3d %8.3f %8.3f %8.3f %9.3f %8.3f %8.3f %8.3f %6.0f MiB\n",
                  sequential ? "sequential" : "parallel", run, p.upload, p.decode, p.engine, p.artifacts, p.download,
                  p.total, p.engine_s, p.peak_rss_mb);
      std::printf("%-12s %3d alignment: %s\n", "", run, p.alignment.c_str());
      std::fflush(stdout);
    }
  }
  auto median = [&](bool sequential, double Phases::*field) {
    std::vector<double> v;
    for (const Phases& p : by_path[sequential]) v.push_back(p.*field);
    return Median(v);
  };
  std::printf("\nmedian of %d runs each, seconds (ratio = sequential / parallel)\n", a.runs);
  std::printf("%-10s %10s %10s %7s\n", "phase", "sequential", "parallel", "ratio");
  const std::pair<const char*, double Phases::*> rows[] = {
      {"upload", &Phases::upload},       {"decode", &Phases::decode},     {"engine", &Phases::engine},
      {"artifacts", &Phases::artifacts}, {"download", &Phases::download}, {"total", &Phases::total},
      {"engine_s", &Phases::engine_s}};
  for (const auto& [label, field] : rows) {
    const double s = median(true, field), q = median(false, field);
    std::printf("%-10s %10.3f %10.3f %6.2fx\n", label, s, q, q > 0 ? s / q : 0.0);
  }
  std::printf("peak RSS above the pre-run level: sequential %.0f MiB, parallel %.0f MiB (%.2fx the decoded stack)\n",
              median(true, &Phases::peak_rss_mb), median(false, &Phases::peak_rss_mb),
              median(false, &Phases::peak_rss_mb) / decoded_mb);
  std::printf("peak RSS of the whole process: sequential %.0f MiB, parallel %.0f MiB (%.2fx the decoded stack)\n",
              median(true, &Phases::peak_rss_abs_mb), median(false, &Phases::peak_rss_abs_mb),
              median(false, &Phases::peak_rss_abs_mb) / decoded_mb);
  if (!focus_stack_s.empty()) {
    const double fs_median = Median(focus_stack_s), ours = median(false, &Phases::total);
    std::printf("focus-stack (--nocrop --depthmap, whole process), median of %d: %.3f s; ours (parallel, total): "
                "%.3f s; ratio %.1fx\n",
                int(focus_stack_s.size()), fs_median, ours, ours > 0 ? fs_median / ours : 0.0);
  }
  std::printf("depth, confidence, all-in-focus bit-identical across all runs: %s\n", identical ? "yes" : "NO");
  return identical ? 0 : 1;
}
