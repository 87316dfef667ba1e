// inspect-load: N concurrent clients for T seconds against a real inspectd on loopback, mixing
// status, list, scan, watch, reconstruct upload and download. Prints calls per method and code,
// p50/p99 latency per method, the server's peak RSS (with --server-pid) and verifies every
// finished job's artifacts by sha256 (the client library checks each download against the
// server's hash). Bounded in calls and time; refuses non-loopback targets.
//
//   inspect-load --server 127.0.0.1:50051 [--server-pid PID] [--clients 8] [--seconds 30]
//                [--max-calls 5000] [--token-file F]
// Exit 0 when no call ended INTERNAL/UNKNOWN/DATA_LOSS and every artifact verified.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <thread>

#include "client_cli/inspection_client.h"
#include "common/sha256_file.h"

namespace fs = std::filesystem;
using inspection::client::ClientOptions;
using inspection::client::InspectionClient;
namespace v1 = inspection::v1;

namespace {

using Clock = std::chrono::steady_clock;

struct Tally {
  std::mutex mu;                                                // guards the members below
  std::map<std::string, std::map<std::string, int64_t>> codes;  // method -> code name -> calls
  std::map<std::string, std::vector<double>> latency_ms;        // method -> samples
  std::vector<std::string> finished_jobs;                       // succeeded jobs to verify
  void Add(const std::string& method, const grpc::Status& st, double ms) {
    static const char* kNames[] = {
        "OK",        "CANCELLED",      "UNKNOWN",           "INVALID_ARGUMENT",   "DEADLINE_EXCEEDED",
        "NOT_FOUND", "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED", "FAILED_PRECONDITION",
        "ABORTED",   "OUT_OF_RANGE",   "UNIMPLEMENTED",     "INTERNAL",           "UNAVAILABLE",
        "DATA_LOSS", "UNAUTHENTICATED"};
    const int c = st.error_code();
    std::lock_guard lock(mu);
    codes[method][c >= 0 && c <= 16 ? kNames[c] : "?"]++;
    latency_ms[method].push_back(ms);
  }
};

// A small synthetic stack (a tilted textured plane, defocus growing with |z - surface|) for the
// upload path: the load tool must not depend on files outside the repository.
fs::path WriteSyntheticStack(const fs::path& dir) {
  fs::create_directories(dir);
  cv::Mat texture(120, 160, CV_8UC1);
  cv::RNG rng(7);
  rng.fill(texture, cv::RNG::UNIFORM, 40, 215);
  std::ofstream json(dir / "stack.json");
  json << R"({"format": "inspection-stack", "version": 1, "pixel_size_um": 1.0, "bit_depth": 8, "frames": [)";
  for (int k = 0; k < 8; ++k) {
    cv::Mat frame;
    const double sigma = 0.3 + std::abs(k - 3.5) * 0.8;
    cv::GaussianBlur(texture, frame, cv::Size(0, 0), sigma);
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", k);
    cv::imwrite((dir / name).string(), frame);
    json << (k ? "," : "") << R"({"file": ")" << name << R"(", "z_um": )" << 10.0 * k << "}";
  }
  json << "]}";
  return dir;
}

int64_t PeakRssKb(int pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stoll(line.substr(6));
  }
  return -1;
}

bool IsLoopback(const std::string& target) {
  return target.rfind("127.", 0) == 0 || target.rfind("localhost:", 0) == 0 || target.rfind("[::1]:", 0) == 0;
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t i = std::min(v.size() - 1, static_cast<size_t>(p * double(v.size() - 1) + 0.5));
  return v[i];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"inspect-load: concurrent mixed load against a local inspectd"};
  std::string server = "127.0.0.1:50051", token_file, tls_ca;
  int server_pid = 0, clients = 8;
  double seconds = 30;
  int64_t max_calls = 5000;
  app.add_option("--server", server, "inspectd address (loopback only)");
  app.add_option("--server-pid", server_pid, "inspectd's pid, for its peak RSS");
  app.add_option("--clients", clients, "concurrent clients")->check(CLI::Range(1, 256));
  app.add_option("--seconds", seconds, "duration")->check(CLI::Range(1.0, 3600.0));
  app.add_option("--max-calls", max_calls, "stop after this many calls in all")->check(CLI::Range(1, 10000000));
  app.add_option("--token-file", token_file, "bearer token file");
  app.add_option("--tls-ca", tls_ca, "CA of the server certificate");
  CLI11_PARSE(app, argc, argv);
  if (!IsLoopback(server)) {
    std::cerr << "inspect-load: --server must be a loopback address (127.x, localhost, [::1])\n";
    return 2;
  }
  ClientOptions co;
  co.target = server;
  co.tls_ca_file = tls_ca;
  if (!token_file.empty()) {
    std::ifstream in(token_file);
    std::getline(in, co.auth_token);
  }
  const fs::path stack = WriteSyntheticStack(fs::temp_directory_path() / ("inspect-load-" + std::to_string(getpid())));
  const fs::path downloads = stack.parent_path() / (stack.filename().string() + "-dl");
  fs::create_directories(downloads);

  Tally tally;
  std::atomic<int64_t> calls{0};
  const auto deadline = Clock::now() + std::chrono::duration<double>(seconds);
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c) {
    threads.emplace_back([&, c] {
      InspectionClient client(co);
      std::mt19937 rng(1000 + c);
      std::uniform_int_distribution<int> pick(0, 99);
      std::string last_job;
      while (Clock::now() < deadline && calls.fetch_add(1) < max_calls) {
        const int r = pick(rng);
        const auto t0 = Clock::now();
        std::string method;
        grpc::Status st;
        if (r < 30) {
          method = "GetRigStatus";
          v1::RigStatus s;
          st = client.GetRigStatus(&s);
        } else if (r < 50) {
          method = "ListJobs";
          v1::ListJobsRequest req;
          req.set_page_size(20);
          v1::ListJobsResponse resp;
          st = client.ListJobs(req, &resp);
          if (st.ok() && !resp.jobs().empty()) last_job = resp.jobs(0).job_id();
        } else if (r < 58) {
          method = "Scan";
          v1::ScanRequest req;
          req.set_label("load-" + std::to_string(c));
          v1::Job job;
          st = client.Scan(req, {}, &job);
          if (st.ok()) {
            std::lock_guard lock(tally.mu);
            tally.finished_jobs.push_back(job.job_id());
          }
        } else if (r < 66) {
          method = "WatchJob";
          if (last_job.empty()) continue;
          v1::Job job;
          st = client.Watch(last_job, {}, &job);
          // A watched job may have failed or been cancelled by its owner: that is its status, not ours.
          if (!st.ok() && job.state() != v1::JOB_STATE_UNSPECIFIED) st = grpc::Status::OK;
        } else if (r < 76) {
          method = "Reconstruct";
          v1::ReconstructStart start;
          start.set_label("load-upload");
          v1::Job job;
          st = client.ReconstructUpload(stack, start, {}, &job);
          if (st.ok()) {
            std::lock_guard lock(tally.mu);
            tally.finished_jobs.push_back(job.job_id());
          }
        } else {
          method = "DownloadArtifact";
          v1::Job job;
          if (last_job.empty()) continue;
          st = client.GetJob(last_job, &job);
          if (st.ok() && job.state() == v1::JOB_STATE_SUCCEEDED && job.result().artifacts_size() > 0) {
            const auto& a = job.result().artifacts(pick(rng) % job.result().artifacts_size());
            st = client.DownloadArtifact(a.artifact_id(), downloads / ("c" + std::to_string(c) + "-" + a.file_name()),
                                         false);
          }
        }
        tally.Add(method, st, std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      }
    });
  }
  for (auto& t : threads) t.join();

  // Verify every finished job's artifacts end to end (the client checks each against the server's sha256).
  InspectionClient verifier(co);
  int64_t verified = 0, mismatched = 0;
  for (const auto& id : tally.finished_jobs) {
    v1::Job job;
    if (!verifier.GetJob(id, &job).ok()) {
      ++mismatched;
      continue;
    }
    for (const auto& a : job.result().artifacts()) {
      const fs::path dest = downloads / ("verify-" + a.artifact_id());
      grpc::Status st = verifier.DownloadArtifact(a.artifact_id(), dest, false);
      if (st.ok() && inspection::Sha256FileHex(dest) == a.sha256())
        ++verified;
      else
        ++mismatched;
      fs::remove(dest);
    }
  }

  int64_t total = 0;
  bool bad = mismatched > 0;
  std::printf("%-18s %-20s %8s\n", "method", "code", "calls");
  for (const auto& [method, by_code] : tally.codes) {
    for (const auto& [code, n] : by_code) {
      std::printf("%-18s %-20s %8lld\n", method.c_str(), code.c_str(), static_cast<long long>(n));
      total += n;
      if (code == "INTERNAL" || code == "UNKNOWN" || code == "DATA_LOSS") bad = true;
    }
  }
  std::printf("\n%-18s %8s %10s %10s\n", "method", "calls", "p50 ms", "p99 ms");
  for (const auto& [method, v] : tally.latency_ms) {
    std::printf("%-18s %8zu %10.1f %10.1f\n", method.c_str(), v.size(), Percentile(v, 0.5), Percentile(v, 0.99));
  }
  std::printf("\nclients %d, seconds %.0f, calls %lld, finished jobs %zu, artifacts verified %lld, mismatched %lld",
              clients, seconds, static_cast<long long>(total), tally.finished_jobs.size(),
              static_cast<long long>(verified), static_cast<long long>(mismatched));
  if (server_pid > 0) std::printf(", server peak RSS %.1f MiB", PeakRssKb(server_pid) / 1024.0);
  std::printf("\n");
  fs::remove_all(stack);
  fs::remove_all(downloads);
  return bad ? 1 : 0;
}
