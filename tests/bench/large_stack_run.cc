// large-stack-bench: the stack sizes focus-stacking users have (300 frames of 24 MP) through
// `inspectctl reconstruct --images` against a local inspectd, both real processes. Frames are
// generated on the fly into a folder on disk (a tilted textured plane: each frame's columns
// taken from one of a few precomputed defocus levels, so generation costs a copy per frame),
// then the client uploads the folder. Measured per run: the server's and the client's peak RSS
// (VmHWM of the server before it stops, ru_maxrss of the client), the server's CPU time, wall time of the client from
// start to downloaded result, time per frame, and the largest disk use of the server's data
// directory and the client's temporary folder during the run (sampled), against the stack's size.
// Prints one Markdown table (docs: tests/bench/large_stack_output.md).
// With --interrupt-at F (0 < F < 1) each run is instead an interrupted upload: the client is
// killed (SIGKILL) once the server holds F of the stack's bytes in uploads/, then the bench prints
// what the server has (its job list, what is left in uploads/ and when it goes, what is left after
// a restart) and whether the same upload run again succeeds.
//
//   large-stack-bench --inspectd build/bin/inspectd --inspectctl build/bin/inspectctl
//       --work /work/tmp/large --format tiff16 --frames 30,100 [--width 6000 --height 4000]
//       [--interrupt-at 0.5]
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace {
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

// Bytes of the regular files below dir (0 when it does not exist).
int64_t TreeBytes(const fs::path& dir) {
  std::error_code ec;
  int64_t total = 0;
  if (!fs::exists(dir, ec)) return 0;
  for (auto it = fs::recursive_directory_iterator(dir, fs::directory_options::skip_permission_denied, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    std::error_code e2;
    if (it->is_regular_file(e2) && !it->is_symlink(e2)) {
      // Hard links to the user's images cost no space: count a file only once per inode.
      struct stat st {};
      if (::lstat(it->path().c_str(), &st) == 0 && st.st_nlink == 1) total += int64_t(st.st_blocks) * 512;
    }
  }
  return total;
}

// User + system CPU seconds of a live process (/proc/<pid>/stat fields 14 and 15): on a machine
// shared with other builds wall time per frame says little, CPU time per frame says whether the
// work is linear in the frame count.
double CpuSeconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto close = text.rfind(')');  // the command name may hold spaces
  if (close == std::string::npos) return -1.0;
  std::istringstream fields(text.substr(close + 2));
  std::string f;
  double ticks = 0;
  for (int i = 3; i <= 15 && fields >> f; ++i) {
    if (i >= 14) ticks += std::stod(f);
  }
  return ticks / double(sysconf(_SC_CLK_TCK));
}

long StatusKb(pid_t pid, const char* key) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key, 0) == 0) return std::atol(line.c_str() + std::strlen(key) + 1);
  }
  return -1;
}

pid_t Spawn(const std::vector<std::string>& args, const fs::path& out, const fs::path& err) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::vector<std::string> storage = args;
  std::vector<char*> argv;
  for (auto& s : storage) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, storage[0].c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) {
    std::cerr << "cannot start " << storage[0] << ": " << std::strerror(rc) << "\n";
    return -1;
  }
  return pid;
}

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// A tilted plane whose depth spans the N frames: frame k is sharp where the focus index
// (N - 1) * x / width is k; elsewhere defocus level min(levels - 1, |k - focus|), one level per
// frame whatever N is. So every column's focus curve has the same shape at 30, 100 and 300 frames
// (a deeper specimen, not a finer z step): when the levels were instead spread over N / 24 frames
// each, a 300-frame stack repeated the same image of a column for 12 frames around its focus,
// the focus curve was flat-topped and 96-99 % of the pixels failed the consistency check. What
// does change with N: the share of a frame near focus (about 15 / N of its columns), so a JPEG
// frame of a deep stack is smoother and decodes faster.
class StackGenerator {
 public:
  StackGenerator(cv::Size size, int frames, bool colour) : size_(size), frames_(frames), colour_(colour) {
    cv::Mat noise(size, CV_32F);
    cv::RNG rng(24);
    rng.fill(noise, cv::RNG::UNIFORM, -1.0, 1.0);
    for (int l = 0; l < kLevels; ++l) {
      cv::Mat blurred;
      cv::GaussianBlur(noise, blurred, cv::Size(0, 0), 0.5 + 1.2 * l);
      double lo = 0, hi = 0;
      cv::minMaxLoc(blurred, &lo, &hi);
      // 16-bit: mid grey +- 12000 for the sharpest level; 8-bit: +- 60.
      cv::Mat level;
      blurred.convertTo(level, colour ? CV_8U : CV_16U, (colour ? 60.0 : 12000.0) / std::max(-lo, hi),
                        colour ? 128.0 : 32768.0);
      levels_.push_back(level);
    }
  }

  cv::Mat Frame(int k) const {
    cv::Mat out(size_, levels_[0].type());
    for (int l = 0; l < kLevels; ++l) {
      // Columns whose defocus level is l (a run per level on each side of the focus column).
      int x0 = -1;
      for (int x = 0; x <= size_.width; ++x) {
        bool in = false;
        if (x < size_.width) {
          const double focus = (frames_ - 1) * double(x) / (size_.width - 1);
          in = std::min(kLevels - 1, int(std::abs(k - focus))) == l;
        }
        if (in && x0 < 0) x0 = x;
        if (!in && x0 >= 0) {
          levels_[l].colRange(x0, x).copyTo(out.colRange(x0, x));
          x0 = -1;
        }
      }
    }
    if (!colour_) return out;
    cv::Mat bgr;
    cv::cvtColor(out, bgr, cv::COLOR_GRAY2BGR);
    bgr.forEach<cv::Vec3b>([](cv::Vec3b& p, const int*) { p[0] = cv::saturate_cast<uchar>(p[0] * 0.6); });
    return bgr;
  }

 private:
  static constexpr int kLevels = 8;
  cv::Size size_;
  int frames_;
  bool colour_;
  std::vector<cv::Mat> levels_;
};

// Writes the stack into `images` (frame_NNNN.tif / .jpg); "" or what failed.
std::string GenerateStack(const fs::path& images, const std::string& format, int frames, cv::Size size,
                          double* seconds) {
  const bool jpeg = format == "jpeg";
  const auto g0 = Clock::now();
  StackGenerator gen(size, frames, jpeg);
  for (int k = 0; k < frames; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, jpeg ? "frame_%04d.jpg" : "frame_%04d.tif", k);
    const std::vector<int> params =
        jpeg ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, 92} : std::vector<int>{cv::IMWRITE_TIFF_COMPRESSION, 1};
    if (!cv::imwrite((images / name).string(), gen.Frame(k), params)) return std::string("cannot write ") + name;
  }
  *seconds = Seconds(g0, Clock::now());
  return "";
}

// Starts inspectd on `data` (logs in work/inspectd.out, .err, appended to: a restart keeps the
// first run's lines) and waits for its address; -1 and *note on failure.
pid_t StartServer(const std::string& inspectd, const fs::path& data, const fs::path& work, std::string* address,
                  std::string* note) {
  const fs::path log = work / "inspectd.out";
  const std::string before = ReadAll(log);
  const long lines_before = long(std::count(before.begin(), before.end(), '\n'));
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, (work / "inspectd.err").c_str(),
                                   O_WRONLY | O_CREAT | O_APPEND, 0644);
  std::vector<std::string> storage = {inspectd, "--listen", "127.0.0.1:0", "--data-dir", data.string(), "--no-rig"};
  std::vector<char*> argv;
  for (auto& s : storage) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t server = -1;
  const int rc = posix_spawn(&server, storage[0].c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) {
    *note = "inspectd did not start: " + std::string(std::strerror(rc));
    return -1;
  }
  address->clear();
  for (const auto deadline = Clock::now() + std::chrono::seconds(60); address->empty() && Clock::now() < deadline;) {
    std::istringstream lines(ReadAll(log));
    long n = 0;
    for (std::string line; std::getline(lines, line); ++n) {
      if (n >= lines_before && line.rfind("inspectd listening on ", 0) == 0) *address = line.substr(22);
    }
    if (address->empty()) std::this_thread::sleep_for(std::chrono::milliseconds(50));  // polling, with a deadline
  }
  if (address->empty()) {
    *note = "inspectd did not announce its address: " + ReadAll(work / "inspectd.err");
    kill(server, SIGKILL);
    waitpid(server, nullptr, 0);
    return -1;
  }
  return server;
}

struct Run {
  std::string format;
  int frames = 0;
  bool ok = false;
  std::string note;
  double generate_s = 0, client_s = 0, engine_s = 0;
  int64_t stack_bytes = 0, peak_data_bytes = 0, peak_tmp_bytes = 0;
  long server_peak_kb = 0, client_peak_kb = 0;
  double server_cpu_s = 0;  // inspectd's user + system CPU over the whole run
  // What the job did with the stack: the alignment it chose (a warped stack costs a resampling of
  // every frame, so the per-frame time is only comparable between runs that chose alike) and the
  // share of pixels with a depth.
  std::string alignment;
  double valid_percent = 0;
};

// The folders of one run, emptied (images and the client's tmp created), and the logs removed;
// *not_run says why the run is not attempted when the disk lacks room for the folder and its
// upload with a margin (empty otherwise).
struct RunFolders {
  fs::path images, data, tmp, out;
};
RunFolders PrepareRun(const fs::path& work, const std::string& format, int frames, cv::Size size,
                      std::string* not_run) {
  RunFolders f;
  f.images = work / ("images-" + format + "-" + std::to_string(frames));
  f.data = work / "server-data";
  f.tmp = work / "client-tmp";
  f.out = work / "result";
  for (const auto& d : {f.images, f.data, f.tmp, f.out}) fs::remove_all(d);
  for (const auto& d : {f.images, f.tmp}) fs::create_directories(d);
  for (const char* log : {"inspectd.out", "inspectd.err"}) fs::remove(work / log);
  const double frame_bytes = format == "jpeg" ? 0.6 * size.area() : 2.0 * size.area() + 4096;
  struct statvfs vfs {};
  statvfs(work.c_str(), &vfs);
  const double free_bytes = double(vfs.f_bavail) * vfs.f_frsize;
  if (2.0 * frames * frame_bytes + 8e9 > free_bytes) {
    *not_run = "not run: needs " + std::to_string(int(2.0 * frames * frame_bytes / 1e9)) + " GB + 8 GB margin, " +
               std::to_string(int(free_bytes / 1e9)) + " GB free";
  }
  return f;
}

// "none", "still (max corner c px)", "<method> warped (max corner c px)", or the default's
// fallback reason: from the job result's DepthSummary.alignment_detail.
std::string AlignmentOf(const nlohmann::json& depth) {
  if (!depth.contains("alignment_detail")) return "none";
  const auto& a = depth["alignment_detail"];
  // The chain fills the largest corner motion; the linear-in-z model its scale change and shift.
  char corner[96] = "";
  auto number = [](const nlohmann::json& j, const char* key) { return j.contains(key) ? j[key].get<double>() : 0.0; };
  const bool chain = a.contains("method") && a["method"].get<std::string>() == "chain";
  if (chain) {
    std::snprintf(corner, sizeof corner, " (max corner %.2f px)", number(a, "max_corner_displacement_px"));
  } else if (depth.contains("alignment_max_scale_change_percent") || depth.contains("alignment_max_shift_px")) {
    std::snprintf(corner, sizeof corner, " (scale %.3f %%, shift %.2f px)",
                  number(depth, "alignment_max_scale_change_percent"), number(depth, "alignment_max_shift_px"));
  }
  if (a.contains("fallback_reason") && !a["fallback_reason"].get<std::string>().empty()) {
    return "none: " + a["fallback_reason"].get<std::string>().substr(0, 80);
  }
  const std::string method = a.contains("method") ? a["method"].get<std::string>() : std::string();
  if (method.empty()) return "none";
  if (a.contains("still") && a["still"].get<bool>()) return method + " still" + corner;
  return method + " warped" + corner;
}

Run RunOne(const std::string& inspectd, const std::string& inspectctl, const fs::path& work, const std::string& format,
           int frames, cv::Size size, const std::vector<std::string>& extra) {
  Run r;
  r.format = format;
  r.frames = frames;
  const RunFolders f = PrepareRun(work, format, frames, size, &r.note);
  if (!r.note.empty()) return r;
  const fs::path &images = f.images, &data = f.data, &tmp = f.tmp, &out = f.out;
  r.note = GenerateStack(images, format, frames, size, &r.generate_s);
  if (!r.note.empty()) return r;
  r.stack_bytes = TreeBytes(images);

  std::string address;
  const pid_t server = StartServer(inspectd, data, work, &address, &r.note);
  if (server < 0) return r;
  std::atomic<bool> done{false};
  // Disk use while the run goes on, and the server's VmRSS over time (a TSV beside the logs: where
  // in the job the peak falls, upload, alignment, engine pass or post-processing).
  std::ofstream rss_log(work / ("server_rss_" + format + "_" + std::to_string(frames) + ".tsv"));
  rss_log << "seconds\tvmrss_kb\n";
  const auto s0 = Clock::now();
  std::thread sampler([&] {
    while (!done.load()) {
      r.peak_data_bytes = std::max(r.peak_data_bytes, TreeBytes(data));
      r.peak_tmp_bytes = std::max(r.peak_tmp_bytes, TreeBytes(tmp));
      rss_log << Seconds(s0, Clock::now()) << "\t" << StatusKb(server, "VmRSS") << "\n";
      std::this_thread::sleep_for(std::chrono::milliseconds(500));  // a sampling period, not a wait
    }
  });
  std::vector<std::string> args = {inspectctl, "--server", address, "--json", "reconstruct", "--images",
                                   images.string(), "--z-step", "1", "--out", out.string()};
  args.insert(args.end(), extra.begin(), extra.end());
  // The client's temporary stack folder (hard links) goes to tmp, which is measured.
  setenv("TMPDIR", tmp.c_str(), 1);
  const auto c0 = Clock::now();
  // Through /usr/bin/time: a child spawned from this process would count this process' pages
  // (the generator's) in its ru_maxrss; time's own child starts small.
  args.insert(args.begin(), {"/usr/bin/time", "-f", "client_maxrss_kb %M"});
  const pid_t client = Spawn(args, work / "inspectctl.out", work / "inspectctl.err");
  int status = 0;
  if (client > 0) waitpid(client, &status, 0);
  r.client_s = Seconds(c0, Clock::now());
  {
    const std::string err = ReadAll(work / "inspectctl.err");
    const auto at = err.rfind("client_maxrss_kb ");
    if (at != std::string::npos) r.client_peak_kb = std::atol(err.c_str() + at + 17);
  }
  done = true;
  sampler.join();
  r.server_peak_kb = StatusKb(server, "VmHWM");
  r.server_cpu_s = CpuSeconds(server);
  kill(server, SIGTERM);
  waitpid(server, nullptr, 0);

  r.ok = client > 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0;
  const std::string text = ReadAll(work / "inspectctl.out");
  const auto last = text.rfind('{');
  if (last != std::string::npos) {
    nlohmann::json j = nlohmann::json::parse(text.substr(text.rfind('\n', text.size() - 2) + 1), nullptr, false);
    if (!j.is_discarded() && j.contains("job")) {
      const auto& depth = j["job"]["result"]["depth"];
      if (depth.contains("engine_seconds")) r.engine_s = depth["engine_seconds"].get<double>();
      if (depth.contains("valid_percent")) r.valid_percent = depth["valid_percent"].get<double>();
      r.alignment = AlignmentOf(depth);
    }
  }
  if (!r.ok) r.note = "inspectctl failed: " + ReadAll(work / "inspectctl.err").substr(0, 300);
  fs::remove_all(images);
  fs::remove_all(data);
  fs::remove_all(out);
  return r;
}

// What data/uploads holds: "empty" or each entry with its files and bytes.
std::string UploadsState(const fs::path& data) {
  std::error_code ec;
  std::ostringstream out;
  int entries = 0;
  for (const auto& e : fs::directory_iterator(data / "uploads", ec)) {
    int files = 0;
    for (auto it = fs::recursive_directory_iterator(e.path(), ec); !ec && it != fs::recursive_directory_iterator();
         it.increment(ec)) {
      files += it->is_regular_file() ? 1 : 0;
    }
    char line[256];
    std::snprintf(line, sizeof line, "%s%s (%d files, %.3f GB)", entries ? ", " : "", e.path().filename().c_str(), files,
                  TreeBytes(e.path()) / 1e9);
    out << line;
    ++entries;
  }
  if (ec && entries == 0) return "no uploads/ folder (" + ec.message() + ")";
  return entries == 0 ? "empty" : std::to_string(entries) + " entr" + (entries == 1 ? "y: " : "ies: ") + out.str();
}

// `inspectctl jobs` against the server: "N jobs" and each job's id, state and error.
std::string JobsSummary(const std::string& inspectctl, const std::string& address, const fs::path& work) {
  const pid_t p = Spawn({inspectctl, "--server", address, "--json", "jobs"}, work / "jobs.out", work / "jobs.err");
  int status = 0;
  if (p > 0) waitpid(p, &status, 0);
  if (p <= 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) return "inspectctl jobs failed: " + ReadAll(work / "jobs.err");
  const nlohmann::json j = nlohmann::json::parse(ReadAll(work / "jobs.out"), nullptr, false);
  if (j.is_discarded()) return "inspectctl jobs: no JSON: " + ReadAll(work / "jobs.out");
  const nlohmann::json jobs = j.value("jobs", nlohmann::json::array());
  std::string out = std::to_string(jobs.size()) + " job" + (jobs.size() == 1 ? "" : "s");
  for (const auto& job : jobs) {
    out += "; " + job.value("job_id", std::string("?")) + " " + job.value("state", std::string("?"));
    const std::string error = job.value("error_message", std::string());
    if (!error.empty()) out += " (" + error + ")";
  }
  return out;
}

// The server log's lines from byte `from` on that name the Reconstruct call or uploads/.
std::string LogLines(const fs::path& log, size_t from) {
  const std::string text = ReadAll(log);
  std::istringstream lines(text.size() > from ? text.substr(from) : "");
  std::string out;
  for (std::string line; std::getline(lines, line);) {
    if (line.find("Reconstruct") != std::string::npos || line.find("upload") != std::string::npos ||
        line.find("job ") != std::string::npos) {
      out += "    " + line + "\n";
    }
  }
  return out.empty() ? "    (none)\n" : out;
}

// --interrupt-at: an upload killed part-way (SIGKILL of inspectctl once the server holds
// `fraction` of the stack's bytes), what the server keeps of it, and the same upload run again.
void RunInterrupted(const std::string& inspectd, const std::string& inspectctl, const fs::path& work,
                    const std::string& format, int frames, cv::Size size, const std::vector<std::string>& extra,
                    double fraction) {
  std::printf("\n### interrupted upload: %s, %d frames of %dx%d, client killed at %.0f %% of the stack\n\n",
              format.c_str(), frames, size.width, size.height, 100 * fraction);
  std::string not_run;
  const RunFolders f = PrepareRun(work, format, frames, size, &not_run);
  if (!not_run.empty()) {
    std::printf("%s\n", not_run.c_str());
    return;
  }
  const fs::path &images = f.images, &data = f.data, &tmp = f.tmp, &out = f.out;
  double generate_s = 0;
  if (std::string e = GenerateStack(images, format, frames, size, &generate_s); !e.empty()) {
    std::printf("not run: %s\n", e.c_str());
    return;
  }
  const int64_t stack_bytes = TreeBytes(images);
  std::printf("- stack: %.3f GB in %d files, generated in %.0f s\n", stack_bytes / 1e9, frames, generate_s);
  std::string address, note;
  pid_t server = StartServer(inspectd, data, work, &address, &note);
  if (server < 0) {
    std::printf("not run: %s\n", note.c_str());
    return;
  }
  std::vector<std::string> args = {inspectctl, "--server", address, "--json", "reconstruct", "--images",
                                   images.string(), "--z-step", "1", "--out", out.string()};
  args.insert(args.end(), extra.begin(), extra.end());
  setenv("TMPDIR", tmp.c_str(), 1);
  const size_t log_at_start = ReadAll(work / "inspectd.out").size();

  // 1. The upload, killed once the server holds `fraction` of the bytes (sampled every 20 ms).
  const auto c0 = Clock::now();
  const pid_t client = Spawn(args, work / "inspectctl.out", work / "inspectctl.err");
  int status = 0;
  bool exited = false;
  int64_t held = 0;
  while (client > 0 && !exited) {
    held = TreeBytes(data / "uploads");
    if (held >= fraction * stack_bytes) break;
    exited = waitpid(client, &status, WNOHANG) == client;
    if (!exited) std::this_thread::sleep_for(std::chrono::milliseconds(20));  // a sampling period
  }
  if (exited) {
    std::printf("- the client ended before %.0f %% was uploaded (exit %d): not an interrupted upload\n",
                100 * fraction, WIFEXITED(status) ? WEXITSTATUS(status) : -1);
  } else {
    kill(client, SIGKILL);
    waitpid(client, &status, 0);
  }
  const auto killed = Clock::now();
  std::printf("- inspectctl killed (SIGKILL) %.1f s after its start, the server then holding %.3f GB (%.1f %%) in "
              "uploads/\n",
              Seconds(c0, killed), held / 1e9, 100.0 * held / stack_bytes);
  std::printf("- uploads/ right after the kill: %s\n", UploadsState(data).c_str());
  // 2. How long the partial folder stays (sampled every 50 ms, at most 120 s).
  std::string state = UploadsState(data);
  while (state != "empty" && Seconds(killed, Clock::now()) < 120) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));  // a sampling period, with a deadline
    state = UploadsState(data);
  }
  std::printf("- uploads/ %.2f s after the kill: %s\n", Seconds(killed, Clock::now()), state.c_str());
  std::printf("- jobs on the server: %s\n", JobsSummary(inspectctl, address, work).c_str());
  std::printf("- data dir: %.3f GB (stack %.3f GB)\n", TreeBytes(data) / 1e9, stack_bytes / 1e9);
  std::printf("- server log for the interrupted call:\n%s", LogLines(work / "inspectd.out", log_at_start).c_str());

  // 3. A restart of the server on the same data dir.
  kill(server, SIGTERM);
  waitpid(server, nullptr, 0);
  std::printf("- uploads/ after the server stopped (SIGTERM): %s\n", UploadsState(data).c_str());
  server = StartServer(inspectd, data, work, &address, &note);
  if (server < 0) {
    std::printf("- restart failed: %s\n", note.c_str());
    return;
  }
  std::printf("- uploads/ after a restart: %s; jobs: %s\n", UploadsState(data).c_str(),
              JobsSummary(inspectctl, address, work).c_str());

  // 4. The same upload again, in full (the protocol has no resume: it starts from byte 0).
  args[2] = address;
  const size_t log_at_rerun = ReadAll(work / "inspectd.out").size();
  const auto r0 = Clock::now();
  const pid_t again = Spawn(args, work / "inspectctl.out", work / "inspectctl.err");
  int again_status = 0;
  if (again > 0) waitpid(again, &again_status, 0);
  const bool ok = again > 0 && WIFEXITED(again_status) && WEXITSTATUS(again_status) == 0;
  std::string job_state = "?";
  {
    const std::string text = ReadAll(work / "inspectctl.out");
    const nlohmann::json j = nlohmann::json::parse(text.substr(text.rfind('\n', text.size() - 2) + 1), nullptr, false);
    if (!j.is_discarded() && j.contains("job")) job_state = j["job"].value("state", std::string("?"));
  }
  std::printf("- the same upload run again: exit %d, job %s, %.1f s%s\n",
              WIFEXITED(again_status) ? WEXITSTATUS(again_status) : -1, job_state.c_str(), Seconds(r0, Clock::now()),
              ok ? "" : (": " + ReadAll(work / "inspectctl.err").substr(0, 300)).c_str());
  std::printf("- server log for the rerun:\n%s", LogLines(work / "inspectd.out", log_at_rerun).c_str());
  std::printf("- afterwards: uploads/ %s; jobs: %s\n", UploadsState(data).c_str(),
              JobsSummary(inspectctl, address, work).c_str());
  kill(server, SIGTERM);
  waitpid(server, nullptr, 0);
  std::fflush(stdout);
  fs::remove_all(images);
  fs::remove_all(data);
  fs::remove_all(out);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app("large-stack-bench: 24 MP stacks through inspectctl reconstruct --images and inspectd");
  std::string inspectd, inspectctl, work, formats = "tiff16,jpeg", frame_list = "30,100";
  int width = 6000, height = 4000;
  std::vector<std::string> extra;
  double interrupt_at = 0;
  app.add_option("--inspectd", inspectd)->required();
  app.add_option("--inspectctl", inspectctl)->required();
  app.add_option("--work", work, "Folder for the frames and the server's data (removed after each run)")->required();
  app.add_option("--format", formats, "tiff16, jpeg or both (comma-separated)");
  app.add_option("--frames", frame_list, "Frame counts, comma-separated");
  app.add_option("--width", width);
  app.add_option("--height", height);
  app.add_option("--extra", extra, "More inspectctl reconstruct arguments (e.g. --alignment none)");
  app.add_option("--interrupt-at", interrupt_at,
                 "Instead of the table: kill the client when the server holds this fraction of the upload "
                 "(0 < f < 1), show what the server keeps, run the upload again")
      ->check(CLI::Range(0.01, 0.99));
  CLI11_PARSE(app, argc, argv);
  fs::create_directories(work);

  std::vector<Run> runs;
  std::vector<int> counts;
  for (std::stringstream ss(frame_list); ss.good();) {
    std::string item;
    std::getline(ss, item, ',');
    if (!item.empty()) counts.push_back(std::stoi(item));
  }
  std::vector<std::string> format_list;
  for (std::stringstream ss(formats); ss.good();) {
    std::string item;
    std::getline(ss, item, ',');
    if (!item.empty()) format_list.push_back(item);
  }
  if (interrupt_at > 0) {
    for (const auto& format : format_list) {
      for (int n : counts) {
        RunInterrupted(inspectd, inspectctl, fs::path(work), format, n, cv::Size(width, height), extra, interrupt_at);
      }
    }
    return 0;
  }
  const double pixels = double(width) * height;
  const double target_mb = (40.0 * pixels + 500e6) / 1e6;
  std::printf("frames %dx%d (%.1f MP); server target: peak RSS <= 40 B/px + 500 MB = %.0f MB\n\n", width, height,
              pixels / 1e6, target_mb);
  std::printf("| format | frames | stack on disk | generate | client wall | per frame | server reconstruct | server CPU | "
              "CPU per frame | server peak RSS | B/px | <= target | client peak RSS | peak data dir | peak client tmp | "
              "alignment | valid | result |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  for (const auto& format : format_list) {
    for (int n : counts) {
      const Run r = RunOne(inspectd, inspectctl, fs::path(work), format, n, cv::Size(width, height), extra);
      const double server_mb = r.server_peak_kb / 1024.0;
      std::printf("| %s | %d | %.2f GB | %.0f s | %.1f s | %.3f s | %.1f s | %.1f s | %.3f s | %.0f MB | %.1f | %s | "
                  "%.0f MB | %.2f GB | %.3f GB | %s | %.1f %% | %s |\n",
                  r.format == "jpeg" ? "JPEG 8-bit colour" : "TIFF 16-bit grey", r.frames, r.stack_bytes / 1e9,
                  r.generate_s, r.client_s, r.frames ? r.client_s / r.frames : 0.0, r.engine_s, r.server_cpu_s,
                  r.frames ? r.server_cpu_s / r.frames : 0.0, server_mb,
                  r.server_peak_kb * 1024.0 / pixels, server_mb * 1.048576 <= target_mb ? "yes" : "NO",
                  r.client_peak_kb / 1024.0, r.peak_data_bytes / 1e9, r.peak_tmp_bytes / 1e9,
                  r.alignment.empty() ? "-" : r.alignment.c_str(), r.valid_percent, r.ok ? "ok" : r.note.c_str());
      std::fflush(stdout);
    }
  }
  return 0;
}
