// pool-bench: the reconstruct pool end to end with the real binaries on loopback: a private
// PostgreSQL 15 (tests/lib/postgres_server.h), `inspectd --no-rig --database postgresql://...`
// replicas on one shared data folder, clients uploading small synthetic stacks over channels to
// different replicas.
//
//   pool-bench --bin DIR --scenario kill [--jobs 20] [--replicas 3] [--clients 6]
//     One replica is killed with -9 while it holds a job and restarted later. Every job must end
//     SUCCEEDED exactly once (one terminal event, one set of artifact rows, nothing left in the
//     queue or on the shared folder's work areas), and every artifact must download
//     sha256-verified from every replica. Prints the kill/restart table.
//   pool-bench --bin DIR --scenario throughput [--jobs 40]
//     The same jobs on 1 and on 2 replicas, each replica's engine, decoding and artifact writing
//     on one thread each. Run twice: replicas free to use every core, and each replica confined
//     to one core of its own (as a Kubernetes pod with a CPU limit of 1). One free replica already
//     overlaps decoding, the engine and artifact writing on the two cores, so the free run shows
//     what a second replica adds on the same two cores, the confined run how the pool scales when
//     each replica brings its own core. Prints each replica's CPU seconds beside the wall time.
//   pool-bench --bin DIR --scenario latency [--jobs 10]
//     One rig (simulated) on SQLite and one on PostgreSQL, both up, called in turn: sequential
//     scans and reconstructions, medians and the median of the per-round ratios.
//
// Exit 0 when every check held. Waits poll a condition with a deadline; the run is bounded by
// --timeout-s.
#include <fcntl.h>
#include <libpq-fe.h>
#include <signal.h>
#include <spawn.h>
#include <sched.h>
#include <sys/mount.h>
#include <sys/resource.h>
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
#include <functional>
#include <iostream>
#include <map>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "client_cli/inspection_client.h"
#include "server/storage/data_store.h"
#include "tests/lib/postgres_server.h"

extern char** environ;

namespace fs = std::filesystem;
namespace v1 = inspection::v1;
using inspection::client::ClientOptions;
using inspection::client::InspectionClient;
using Clock = std::chrono::steady_clock;

namespace {

double Since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

int g_failures = 0;
#define CHECK_OR_COUNT(cond, msg)                         \
  do {                                                    \
    if (!(cond)) {                                        \
      ++g_failures;                                       \
      std::cerr << "CHECK FAILED: " << msg << std::endl; \
    }                                                     \
  } while (0)

// A textured plane seen through focus: frame k is sharpest near k = frames / 2.
void WriteSyntheticStack(const fs::path& dir, int width, int height, int frames) {
  fs::create_directories(dir);
  cv::Mat texture(height, width, CV_8UC1);
  cv::RNG rng(7);
  rng.fill(texture, cv::RNG::UNIFORM, 40, 215);
  std::ofstream json(dir / "stack.json");
  json << R"({"format": "inspection-stack", "version": 1, "pixel_size_um": 1.0, "bit_depth": 8, "frames": [)";
  for (int k = 0; k < frames; ++k) {
    cv::Mat frame;
    const double sigma = 0.3 + std::abs(k - (frames - 1) / 2.0) * 0.8;
    cv::GaussianBlur(texture, frame, cv::Size(0, 0), sigma);
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", k);
    cv::imwrite((dir / name).string(), frame);
    json << (k ? "," : "") << R"({"file": ")" << name << R"(", "z_um": )" << 10.0 * k << "}";
  }
  json << "]}";
}

int FreePort() {
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(a);
  int port = 0;
  if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
    port = ntohs(a.sin_port);
  }
  close(fd);
  return port;
}

bool PollUntil(const std::function<bool()>& cond, double seconds, double step_s = 0.05) {
  const auto deadline = Clock::now() + std::chrono::duration<double>(seconds);
  while (Clock::now() < deadline) {
    if (cond()) return true;
    // Polling a condition that another process changes: the step only paces the checks.
    std::this_thread::sleep_for(std::chrono::duration<double>(step_s));
  }
  return cond();
}

std::string ReadFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// One inspectd process.
struct Process {
  std::string name;
  std::vector<std::string> args;
  fs::path log;
  pid_t pid = 0;
  int port = 0;
  int cpu = -1;              // >= 0: the process runs on this core only
  double cpu_seconds = 0;    // user + system time of the process, read when it is reaped

  bool Start() {
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const size_t before = ReadFile(log).size();
    // The child inherits the spawning thread's affinity: set it for the spawn, then restore.
    cpu_set_t saved;
    const bool pin = cpu >= 0 && sched_getaffinity(0, sizeof saved, &saved) == 0;
    if (pin) {
      cpu_set_t one;
      CPU_ZERO(&one);
      CPU_SET(cpu, &one);
      if (sched_setaffinity(0, sizeof one, &one) != 0) std::cerr << name << ": cannot pin to core " << cpu << "\n";
    }
    const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
    if (pin) sched_setaffinity(0, sizeof saved, &saved);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) {
      std::cerr << name << ": cannot start " << args[0] << "\n";
      return false;
    }
    // Listening once its database answers and its port is bound.
    const bool up = PollUntil(
        [&] {
          const std::string text = ReadFile(log);
          return text.find("inspectd listening on", before) != std::string::npos;
        },
        60);
    if (!up) std::cerr << name << ": not listening after 60 s; log:\n" << ReadFile(log).substr(before) << "\n";
    return up;
  }
  void Kill9() {
    if (pid > 0) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
    }
    pid = 0;
  }
  int Term() {
    if (pid <= 0) return -1;
    kill(pid, SIGTERM);
    int status = 0;
    struct rusage ru {};
    wait4(pid, &status, 0, &ru);
    cpu_seconds = double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) + 1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
    pid = 0;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  bool alive() const { return pid > 0; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port); }
};

// libpq for the few questions the DataStore interface does not answer (lease holders, row counts).
class Sql {
 public:
  Sql(const std::string& url, const std::string& password) {
    const std::string conninfo = url + "?password=" + password;
    conn_ = PQconnectdb(conninfo.c_str());
  }
  ~Sql() { PQfinish(conn_); }
  int64_t Count(const std::string& sql) {
    PGresult* r = PQexec(conn_, sql.c_str());
    int64_t n = -1;
    if (PQresultStatus(r) == PGRES_TUPLES_OK && PQntuples(r) == 1) n = std::atoll(PQgetvalue(r, 0, 0));
    PQclear(r);
    return n;
  }

 private:
  PGconn* conn_;
};

struct Pool {
  fs::path work;
  std::string url, password_file, password;
  std::string inspectd;
  std::vector<Process> replicas;
  int engine_threads = 0;
  int decode_threads = 0;
  int artifact_threads = 0;
  int lease_s = 3;
  int drain_s = 10;
  bool pin = false;  // replica i on core i % cores

  Process MakeReplica(int i) {
    Process p;
    p.name = "replica " + std::to_string(i + 1);
    p.port = FreePort();
    p.log = work / ("replica-" + std::to_string(i + 1) + ".log");
    if (pin) p.cpu = i % int(std::max(1u, std::thread::hardware_concurrency()));
    p.args = {inspectd,
              "--no-rig",
              "--listen",
              "127.0.0.1:" + std::to_string(p.port),
              "--data-dir",
              (work / "shared").string(),
              "--database",
              url,
              "--database-password-file",
              password_file,
              "--audit-log",
              (work / ("audit-" + std::to_string(i + 1) + ".jsonl")).string(),
              "--pool-lease-s",
              std::to_string(lease_s),
              "--pool-poll-ms",
              "100",
              "--drain-timeout-s",
              std::to_string(drain_s),
              "--engine-threads",
              std::to_string(engine_threads),
              "--decode-threads",
              std::to_string(decode_threads),
              "--artifact-threads",
              std::to_string(artifact_threads)};
    return p;
  }
  bool Start(int n) {
    for (int i = 0; i < n; ++i) {
      replicas.push_back(MakeReplica(i));
      if (!replicas.back().Start()) return false;
    }
    return true;
  }
  void StopAll() {
    for (Process& p : replicas) p.Term();
  }
};

ClientOptions ClientFor(const std::string& address) {
  ClientOptions o;
  o.target = address;
  o.connect_timeout_seconds = 2;
  return o;
}

struct Submission {
  std::string request_id;
  std::string job_id;
  int accepted_by = -1;  // replica index whose upload created the job
  bool succeeded = false;
  int resubmits = 0;     // uploads repeated (the replica died before the job existed)
  int follow_overs = 0;  // watches on another replica (the accepting one died)
  std::string error;
};

// Runs `jobs` uploads from `clients` threads, job i to replica i % replicas (the next live one
// when that one is down); a broken stream is followed on another replica. Replicas may be
// killed and restarted meanwhile (alive() read under `mu`).
class Submitter {
 public:
  Submitter(Pool* pool, std::mutex* mu, fs::path stack, std::string prefix)
      : pool_(pool), mu_(mu), stack_(std::move(stack)), prefix_(std::move(prefix)) {}

  std::vector<Submission> Run(int jobs, int clients) {
    results_.assign(size_t(jobs), {});
    std::vector<std::thread> threads;
    for (int c = 0; c < clients; ++c) {
      threads.emplace_back([&] {
        for (int i = next_.fetch_add(1); i < jobs; i = next_.fetch_add(1)) One(i);
      });
    }
    for (auto& t : threads) t.join();
    return results_;
  }
  int succeeded() const { return succeeded_.load(); }

 private:
  int PickReplica(int preferred) {
    std::lock_guard<std::mutex> lock(*mu_);
    const int n = int(pool_->replicas.size());
    for (int k = 0; k < n; ++k) {
      const int r = (preferred + k) % n;
      if (pool_->replicas[size_t(r)].alive()) return r;
    }
    return preferred % n;
  }
  std::string AddressOf(int r) {
    std::lock_guard<std::mutex> lock(*mu_);
    return pool_->replicas[size_t(r)].address();
  }

  void One(int i) {
    Submission& s = results_[size_t(i)];
    s.request_id = prefix_ + std::to_string(i);
    const auto deadline = Clock::now() + std::chrono::seconds(600);
    int target = i;
    while (Clock::now() < deadline) {
      const int r = PickReplica(target);
      InspectionClient client(ClientFor(AddressOf(r)));
      v1::Job job;
      grpc::Status st;
      if (s.job_id.empty()) {
        v1::ReconstructStart start;
        start.set_request_id(s.request_id);
        start.set_label("pool-bench");
        std::string seen;
        st = client.ReconstructUpload(stack_, start, [&](const v1::JobEvent& e) { seen = e.job_id(); }, &job);
        if (!seen.empty()) {
          s.job_id = seen;
          if (s.accepted_by < 0) s.accepted_by = r;
        } else {
          ++s.resubmits;
        }
      } else {
        ++s.follow_overs;
        st = client.Watch(s.job_id, {}, &job);
      }
      if (st.ok()) {
        s.succeeded = true;
        ++succeeded_;
        return;
      }
      // The job ended otherwise: a real failure, not a replica that went away.
      if (job.state() == v1::JOB_STATE_FAILED || job.state() == v1::JOB_STATE_CANCELLED) {
        s.error = v1::JobState_Name(job.state()) + ": " + job.error_message();
        return;
      }
      if (st.error_code() != grpc::StatusCode::UNAVAILABLE && st.error_code() != grpc::StatusCode::CANCELLED &&
          st.error_code() != grpc::StatusCode::DEADLINE_EXCEEDED) {
        s.error = std::to_string(int(st.error_code())) + ": " + st.error_message();
        return;
      }
      target = r + 1;  // that replica is gone: another one
    }
    s.error = "not finished within 600 s";
  }

  Pool* pool_;
  std::mutex* mu_;
  fs::path stack_;
  std::string prefix_;
  std::vector<Submission> results_;
  std::atomic<int> next_{0};
  std::atomic<int> succeeded_{0};
};

struct Common {
  std::string bin;
  int jobs = 20;
  int replicas = 3;
  int clients = 6;
  int width = 320, height = 240, frames = 12;
  std::string keep;  // keep the work folder
};

// Every job SUCCEEDED once, with one terminal event and one set of artifacts, and nothing of
// the queue or the work areas left; every artifact from every replica, sha256-verified.
void VerifyPool(Pool& pool, const std::vector<Submission>& subs, const std::string& prefix, int* reruns_out,
                int64_t* downloads_out) {
  inspection::DatabaseOptions dbo;
  dbo.url = pool.url;
  dbo.password_file = pool.password_file;
  auto store = inspection::DataStore::Open(pool.work / "verify", dbo);
  CHECK_OR_COUNT(store.ok(), "open the pool's store: " << store.status().ToString());
  if (!store.ok()) return;
  Sql sql(pool.url, pool.password);
  auto jobs = (*store)->ListJobs(v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_UNSPECIFIED, 100000, 0);
  CHECK_OR_COUNT(jobs.ok(), "ListJobs");
  std::map<std::string, v1::Job> by_request;
  int duplicates = 0;
  for (const v1::Job& j : *jobs) {
    if (j.request_id().rfind(prefix, 0) != 0) continue;
    if (!by_request.emplace(j.request_id(), j).second) ++duplicates;
  }
  CHECK_OR_COUNT(duplicates == 0, duplicates << " request ids became more than one job");
  CHECK_OR_COUNT(by_request.size() == subs.size(), by_request.size() << " jobs stored for " << subs.size() << " submissions");
  int reruns = 0;
  for (const Submission& s : subs) {
    CHECK_OR_COUNT(s.succeeded, s.request_id << " did not succeed: " << s.error);
    auto it = by_request.find(s.request_id);
    if (it == by_request.end()) continue;
    const v1::Job& j = it->second;
    CHECK_OR_COUNT(j.job_id() == s.job_id, s.request_id << ": client saw " << s.job_id << ", store has " << j.job_id());
    CHECK_OR_COUNT(j.state() == v1::JOB_STATE_SUCCEEDED, j.job_id() << " is " << v1::JobState_Name(j.state()));
    auto events = (*store)->Events(j.job_id());
    int terminal = 0;
    bool rerun = false;
    for (const v1::JobEvent& e : *events) {
      if (e.phase() == v1::JOB_PHASE_DONE) ++terminal;
      if (e.message().find(", attempt ") != std::string::npos) rerun = true;
    }
    reruns += rerun;
    CHECK_OR_COUNT(terminal == 1, j.job_id() << " has " << terminal << " terminal events");
    const int64_t rows = sql.Count("SELECT count(*) FROM artifacts WHERE job_id = '" + j.job_id() + "'");
    CHECK_OR_COUNT(rows == j.result().artifacts_size() && rows >= 4,
                   j.job_id() << ": " << rows << " artifact rows, the job lists " << j.result().artifacts_size());
  }
  // Ended rows go once their input folder is removed (by the replica that ended the job, or the
  // others' sweep when it died right after).
  PollUntil([&] { return sql.Count("SELECT count(*) FROM work_queue") == 0; }, 30, 0.1);
  CHECK_OR_COUNT(sql.Count("SELECT count(*) FROM work_queue") == 0, "rows left in the work queue");
  auto left_in = [&](const char* sub) {
    std::error_code ec;
    int n = 0;
    for (auto it = fs::directory_iterator(pool.work / "shared" / sub, ec); !ec && it != fs::directory_iterator(); ++it) ++n;
    return n;
  };
  // A replica killed while it was still receiving an upload leaves that partial folder (no job
  // refers to it): the live replicas' sweep removes it once it has been untouched for two leases
  // (server/storage/work_folders.h). Every stored input of a job is gone with its job.
  PollUntil([&] { return left_in("uploads") == 0; }, 30, 0.1);
  CHECK_OR_COUNT(left_in("uploads") == 0, left_in("uploads") << " folders left in uploads/ (partial uploads or stored inputs)");
  CHECK_OR_COUNT(left_in("tmp") == 0, left_in("tmp") << " folders left in tmp/");
  // Every artifact from every replica: the client verifies each file's sha256 against the server's.
  std::atomic<int64_t> downloads{0};
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (size_t r = 0; r < pool.replicas.size(); ++r) {
    threads.emplace_back([&, r] {
      InspectionClient client(ClientFor(pool.replicas[r].address()));
      for (const auto& [rid, j] : by_request) {
        const fs::path dir = pool.work / ("dl-" + std::to_string(r)) / j.job_id();
        std::vector<fs::path> written;
        grpc::Status st = client.DownloadResults(j, dir, /*include_stack=*/false, &written);
        if (!st.ok() || int(written.size()) != j.result().artifacts_size()) {
          if (failures.fetch_add(1) < 5) {
            std::cerr << "download of " << j.job_id() << " from replica " << r + 1 << ": " << st.error_message() << " ("
                      << written.size() << " files)\n";
          }
        }
        downloads += int64_t(written.size());
        std::error_code ec;
        fs::remove_all(dir, ec);
      }
    });
  }
  for (auto& t : threads) t.join();
  CHECK_OR_COUNT(failures == 0, failures << " job downloads failed");
  *reruns_out = reruns;
  *downloads_out = downloads;
}

int ScenarioKill(const Common& c, inspection::testing::PostgresServer& pg, const fs::path& work) {
  Pool pool;
  pool.work = work;
  pool.url = pg.CreateDatabase("pool_kill");
  pool.password_file = pg.PasswordFile();
  pool.password = inspection::testing::PostgresServer::Password();
  pool.inspectd = c.bin + "/inspectd";
  // Each replica its share of the two cores.
  pool.engine_threads = 1;
  pool.decode_threads = 1;
  pool.artifact_threads = 1;
  const fs::path stack = work / "stack";
  WriteSyntheticStack(stack, c.width, c.height, c.frames);
  const auto t0 = Clock::now();
  if (!pool.Start(c.replicas)) return 1;
  std::printf("%d replicas up in %.1f s (lease %d s); %d jobs of %dx%d px x %d frames from %d clients\n", c.replicas,
              Since(t0), pool.lease_s, c.jobs, c.width, c.height, c.frames, c.clients);
  const size_t victim = c.replicas > 1 ? 1 : 0;
  // An upload the victim is still receiving when it is killed: a start and half a file, the
  // stream left open. Opened before the run starts, so the others' sweeps see it alive
  // (touched by the victim) for many leases before the kill, and as an orphan after it.
  const fs::path uploads = pool.work / "shared" / "uploads";
  auto partial_stub = v1::InspectionService::NewStub(
      grpc::CreateChannel(pool.replicas[victim].address(), grpc::InsecureChannelCredentials()));
  grpc::ClientContext partial_ctx;
  auto partial = partial_stub->Reconstruct(&partial_ctx);  // held open until the kill
  {
    v1::ReconstructRequest req;
    req.mutable_start()->set_request_id("partial-upload-of-the-victim");
    req.mutable_start()->mutable_upload()->set_file_count(2);
    req.mutable_start()->mutable_upload()->set_total_bytes(1 << 20);
    partial->Write(req);
    v1::ReconstructRequest chunk;
    chunk.mutable_file_chunk()->set_path("partial_frame.png");
    chunk.mutable_file_chunk()->set_data(std::string(4096, 'x'));
    partial->Write(chunk);
  }
  fs::path partial_dir;
  PollUntil([&] {
    std::error_code ec;
    for (auto it = fs::directory_iterator(uploads, ec); !ec && it != fs::directory_iterator(); ++it) {
      if (fs::exists(it->path() / "partial_frame.png")) partial_dir = it->path();
    }
    return !partial_dir.empty();
  }, 30, 0.02);
  CHECK_OR_COUNT(!partial_dir.empty(), "the partial upload's folder never appeared");
  // Alive for longer than the sweep's bound (two leases) plus a sweep before any job runs: the
  // other replicas' sweeps must leave it (its writer touches it).
  const auto partial_open = Clock::now();
  const bool partial_swept_alive =
      PollUntil([&] { return !fs::exists(partial_dir / "partial_frame.png"); }, 2.0 * pool.lease_s + 2.0, 0.1);
  CHECK_OR_COUNT(!partial_swept_alive, "the live replica's partial upload was removed while it was receiving it");
  std::mutex mu;
  Submitter submitter(&pool, &mu, stack, "pool-kill-");
  std::vector<Submission> subs;
  const auto run0 = Clock::now();
  std::thread clients([&] { subs = submitter.Run(c.jobs, c.clients); });

  struct Row {
    double t;
    std::string event;
    int succeeded;
    std::string detail;
  };
  std::vector<Row> table;
  Sql sql(pool.url, pool.password);
  // Kill once a quarter of the jobs are done and the victim is mid-job: it holds a lease on a
  // RUNNING job early in its frames (a job about to end could finish between the look and the kill).
  const std::string held_by_victim =
      "SELECT count(*) FROM work_queue q JOIN jobs j USING (job_id) WHERE q.ended = 0 AND q.lease_owner LIKE '%-" +
      std::to_string(pool.replicas[victim].pid) + "-%' AND j.state = 2 AND "
      "(SELECT count(*) FROM events e WHERE e.job_id = q.job_id) BETWEEN 3 AND 8";
  PollUntil([&] { return submitter.succeeded() >= c.jobs / 4 && sql.Count(held_by_victim) > 0; }, 300, 0.02);
  std::string held_ids;
  {
    PGconn* conn = PQconnectdb((pool.url + "?password=" + pool.password).c_str());
    PGresult* r = PQexec(conn, ("SELECT job_id FROM work_queue WHERE ended = 0 AND lease_owner LIKE '%-" +
                                std::to_string(pool.replicas[victim].pid) + "-%'")
                                   .c_str());
    for (int i = 0; i < PQntuples(r); ++i) held_ids += std::string(i ? ", " : "") + PQgetvalue(r, i, 0);
    PQclear(r);
    PQfinish(conn);
  }
  const pid_t killed_pid = pool.replicas[victim].pid;
  // A live upload is never taken for an orphan: the run so far lasted many leases.
  const bool partial_alive = !partial_dir.empty() && fs::exists(partial_dir / "partial_frame.png");
  const double partial_open_s = Since(partial_open);
  {
    std::lock_guard<std::mutex> lock(mu);
    pool.replicas[victim].Kill9();
  }
  table.push_back({Since(run0), "kill -9 " + pool.replicas[victim].name + " (pid " + std::to_string(killed_pid) + ")",
                   submitter.succeeded(),
                   "it held: " + (held_ids.empty() ? std::string("-") : held_ids) + "; and a partial upload " +
                       partial_dir.filename().string() + (partial_alive ? " (kept while it lived, " : " (LOST while it lived, ") +
                       std::to_string(int(partial_open_s)) + " s)"});
  CHECK_OR_COUNT(!held_ids.empty(), "the killed replica held no job");
  CHECK_OR_COUNT(partial_alive, "the live replica's partial upload was removed while it was receiving it");
  partial_ctx.TryCancel();
  partial.reset();
  if (PollUntil([&] { return !partial_dir.empty() && !fs::exists(partial_dir); }, 60, 0.05)) {
    table.push_back({Since(run0), "its partial upload removed by another replica's sweep", submitter.succeeded(),
                     "untouched for 2 leases, no job refers to it"});
  }
  // Its jobs are taken over once their leases run out.
  const std::string still_dead_lease = "SELECT count(*) FROM work_queue WHERE ended = 0 AND lease_owner LIKE '%-" +
                                       std::to_string(killed_pid) + "-%'";
  if (PollUntil([&] { return sql.Count(still_dead_lease) == 0; }, 60, 0.05)) {
    table.push_back({Since(run0), "its leases taken over by the other replicas", submitter.succeeded(),
                     "lease " + std::to_string(pool.lease_s) + " s"});
  }
  PollUntil([&] { return submitter.succeeded() >= (3 * c.jobs) / 4; }, 600, 0.05);
  {
    std::lock_guard<std::mutex> lock(mu);
    const bool up = pool.replicas[victim].Start();
    CHECK_OR_COUNT(up, "restart of " << pool.replicas[victim].name);
    table.push_back({Since(run0), pool.replicas[victim].name + " restarted (pid " +
                                      std::to_string(pool.replicas[victim].pid) + ")",
                     submitter.succeeded(), "same port, same database and folder"});
  }
  clients.join();
  const double run_s = Since(run0);
  int resubmits = 0, follow_overs = 0;
  std::map<int, int> accepted;
  for (const Submission& s : subs) {
    resubmits += s.resubmits;
    follow_overs += s.follow_overs;
    accepted[s.accepted_by]++;
  }
  table.push_back({run_s, "all jobs ended", submitter.succeeded(),
                   std::to_string(resubmits) + " uploads repeated, " + std::to_string(follow_overs) +
                       " streams followed on another replica"});
  int reruns = 0;
  int64_t downloads = 0;
  const auto v0 = Clock::now();
  VerifyPool(pool, subs, "pool-kill-", &reruns, &downloads);
  const double verify_s = Since(v0);

  std::printf("\n| t (s) | event | jobs succeeded | detail |\n|---:|---|---:|---|\n");
  for (const Row& r : table) std::printf("| %.1f | %s | %d/%d | %s |\n", r.t, r.event.c_str(), r.succeeded, c.jobs, r.detail.c_str());
  std::printf("\naccepted by replica:");
  for (const auto& [r, n] : accepted) std::printf(" %d: %d", r + 1, n);
  std::printf("\njobs rerun after the kill (an \"attempt 2\" event): %d\n", reruns);
  std::printf("artifacts downloaded sha256-verified: %lld (every job's from each of %d replicas) in %.1f s\n",
              (long long)downloads, c.replicas, verify_s);
  std::printf("run: %.1f s for %d jobs (%.2f jobs/s)\n", run_s, c.jobs, c.jobs / run_s);
  CHECK_OR_COUNT(reruns >= 1, "no job was rerun after the kill");
  pool.StopAll();
  return g_failures == 0 ? 0 : 1;
}

struct ThroughputRun {
  double jobs_per_s = 0;
  double wall_s = 0;
  std::vector<double> replica_cpu_s;  // each replica's CPU seconds over the run
  double client_cpu_s = 0;            // this process (the uploading clients) over the run
  double postgres_cpu_s = 0;          // every postgres process over the run
};

double SelfCpuSeconds() {
  struct rusage ru {};
  getrusage(RUSAGE_SELF, &ru);
  return double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) + 1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

// CPU seconds of every process named postgres so far (its backends live only as long as their
// connection, so a run's figure is the difference of two readings plus the backends that ended:
// close enough while the replicas keep their connections for the whole run).
double PostgresCpuSeconds() {
  double total = 0;
  const double tick = double(sysconf(_SC_CLK_TCK));
  for (const auto& e : fs::directory_iterator("/proc")) {
    const std::string pid = e.path().filename().string();
    if (pid.empty() || !std::all_of(pid.begin(), pid.end(), [](char ch) { return ch >= '0' && ch <= '9'; })) continue;
    const std::string stat = ReadFile(e.path() / "stat");
    const size_t open = stat.find('('), close = stat.rfind(')');
    if (open == std::string::npos || close == std::string::npos) continue;
    if (stat.substr(open + 1, close - open - 1) != "postgres") continue;
    std::istringstream rest(stat.substr(close + 2));
    std::string field;
    double utime = 0, stime = 0;
    for (int i = 3; i <= 15 && rest >> field; ++i) {
      if (i == 14) utime = std::atof(field.c_str());
      if (i == 15) stime = std::atof(field.c_str());
    }
    total += (utime + stime) / tick;
  }
  return total;
}

// Jobs per second with `n` replicas on a fresh database and folder.
ThroughputRun Throughput(const Common& c, inspection::testing::PostgresServer& pg, const fs::path& work, int n,
                         const fs::path& stack, bool pin) {
  ThroughputRun run;
  Pool pool;
  const std::string tag = std::to_string(n) + (pin ? "_pinned" : "");
  pool.work = work / ("tp-" + tag);
  fs::create_directories(pool.work);
  pool.url = pg.CreateDatabase("pool_tp_" + tag);
  pool.password_file = pg.PasswordFile();
  pool.password = inspection::testing::PostgresServer::Password();
  pool.inspectd = c.bin + "/inspectd";
  pool.engine_threads = 1;
  pool.decode_threads = 1;
  pool.artifact_threads = 1;
  pool.lease_s = 30;
  pool.pin = pin;
  if (!pool.Start(n)) return run;
  std::mutex mu;
  Submitter submitter(&pool, &mu, stack, "pool-tp-" + tag + "-");
  // Enough uploads in flight to keep every replica busy.
  const auto t0 = Clock::now();
  const double self0 = SelfCpuSeconds(), pg0 = PostgresCpuSeconds();
  std::vector<Submission> subs = submitter.Run(c.jobs, 2 * n + 2);
  run.wall_s = Since(t0);
  run.client_cpu_s = SelfCpuSeconds() - self0;
  run.postgres_cpu_s = PostgresCpuSeconds() - pg0;
  for (const Submission& x : subs) CHECK_OR_COUNT(x.succeeded, x.request_id << ": " << x.error);
  pool.StopAll();
  for (const Process& p : pool.replicas) run.replica_cpu_s.push_back(p.cpu_seconds);
  run.jobs_per_s = c.jobs / run.wall_s;
  return run;
}

int ScenarioThroughput(const Common& c, inspection::testing::PostgresServer& pg, const fs::path& work) {
  const fs::path stack = work / "stack";
  WriteSyntheticStack(stack, c.width, c.height, c.frames);
  std::printf("\n%d jobs of %dx%d px x %d frames; each replica: engine, decode and artifact threads 1; %u cores\n",
              c.jobs, c.width, c.height, c.frames, std::thread::hardware_concurrency());
  std::printf("| replicas | placement | wall s | jobs/s | vs 1 replica | replicas' CPU s | replica cores busy | client CPU s | "
              "PostgreSQL CPU s |\n|---:|---|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const bool pin : {false, true}) {
    const ThroughputRun one = Throughput(c, pg, work, 1, stack, pin);
    const ThroughputRun two = Throughput(c, pg, work, 2, stack, pin);
    for (const ThroughputRun* r : {&one, &two}) {
      double cpu = 0;
      for (double x : r->replica_cpu_s) cpu += x;
      std::printf("| %zu | %s | %.2f | %.2f | %.2fx | %.1f | %.2f | %.1f | %.1f |\n", r->replica_cpu_s.size(),
                  pin ? "one core each" : "free", r->wall_s, r->jobs_per_s,
                  one.jobs_per_s > 0 ? r->jobs_per_s / one.jobs_per_s : 0.0, cpu, r->wall_s > 0 ? cpu / r->wall_s : 0.0,
                  r->client_cpu_s, r->postgres_cpu_s);
    }
  }
  return g_failures == 0 ? 0 : 1;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

// One simulated rig on SQLite (database empty) or PostgreSQL, listening.
bool StartRig(const Common& c, const fs::path& work, const std::string& database, const std::string& password_file,
              Process* p) {
  fs::create_directories(work);
  p->name = database.empty() ? "rig on SQLite" : "rig on PostgreSQL";
  p->port = FreePort();
  p->log = work / (database.empty() ? "rig-sqlite.log" : "rig-postgres.log");
  p->args = {c.bin + "/inspectd", "--listen", p->address(), "--data-dir",
             (work / (database.empty() ? "rig-sqlite" : "rig-postgres")).string(), "--camera-size", "320x240"};
  if (!database.empty()) {
    for (const std::string& a : {std::string("--database"), database, std::string("--database-password-file"), password_file}) {
      p->args.push_back(a);
    }
  }
  return p->Start();
}

// Two rigs up at once, one on SQLite and one on PostgreSQL, called in turn (the order swapped at
// every round), so a load that comes and goes on a shared host falls on both alike. Per call
// kind: the median latency of each store and the median of the per-round ratios.
int ScenarioLatency(const Common& c, inspection::testing::PostgresServer& pg, const fs::path& work) {
  const fs::path stack = work / "stack";
  WriteSyntheticStack(stack, c.width, c.height, c.frames);
  const std::string url = pg.CreateDatabase("rig_latency");
  Process rigs[2];
  if (!StartRig(c, work, "", "", &rigs[0]) || !StartRig(c, work, url, pg.PasswordFile(), &rigs[1])) {
    ++g_failures;
    for (Process& p : rigs) p.Term();
    return 1;
  }
  const std::string load_before = ReadFile("/proc/loadavg").substr(0, 14);
  std::vector<double> scans[2], recs[2], scan_ratio, rec_ratio;
  auto call = [&](int k, bool timed) {
    InspectionClient client(ClientFor(rigs[k].address()));
    v1::ScanRequest req;
    v1::Job job;
    auto t0 = Clock::now();
    grpc::Status st = client.Scan(req, {}, &job);
    const double scan_s = Since(t0);
    CHECK_OR_COUNT(st.ok(), rigs[k].name << " scan: " << st.error_message());
    v1::ReconstructStart start;
    t0 = Clock::now();
    st = client.ReconstructUpload(stack, start, {}, &job);
    const double rec_s = Since(t0);
    CHECK_OR_COUNT(st.ok(), rigs[k].name << " reconstruct: " << st.error_message());
    if (timed) {
      scans[k].push_back(scan_s);
      recs[k].push_back(rec_s);
    }
  };
  for (int k = 0; k < 2; ++k) call(k, false);  // warm-up: connections, caches, first files
  for (int i = 0; i < c.jobs; ++i) {
    for (int j = 0; j < 2; ++j) call((i + j) % 2, true);
    scan_ratio.push_back(scans[1].back() / scans[0].back());
    rec_ratio.push_back(recs[1].back() / recs[0].back());
  }
  // What a reconstruct writes to the database (each a round trip or part of one).
  Sql sql(url, inspection::testing::PostgresServer::Password());
  const int64_t rec_jobs = sql.Count("SELECT count(*) FROM jobs WHERE kind = " + std::to_string(int(v1::JOB_KIND_RECONSTRUCT)));
  const int64_t rec_events = sql.Count("SELECT count(*) FROM events e JOIN jobs j USING (job_id) WHERE j.kind = " +
                                       std::to_string(int(v1::JOB_KIND_RECONSTRUCT)));
  const int64_t rec_artifacts = sql.Count("SELECT count(*) FROM artifacts a JOIN jobs j USING (job_id) WHERE j.kind = " +
                                          std::to_string(int(v1::JOB_KIND_RECONSTRUCT)));
  // One database round trip on this host now: what each statement on a reconstruct's path costs.
  std::vector<double> trips;
  for (int i = 0; i < 200; ++i) {
    const auto t0 = Clock::now();
    sql.Count("SELECT 1");
    trips.push_back(Since(t0));
  }
  for (Process& p : rigs) p.Term();
  std::printf("\none simulated rig (camera 320x240) on each store, both up, called in turn; %d rounds; load %s -> %s\n",
              c.jobs, load_before.c_str(), ReadFile("/proc/loadavg").substr(0, 14).c_str());
  std::printf("database round trip (SELECT 1 on loopback, median of 200): %.3f ms\n", 1000 * Median(trips));
  std::printf("| store | scan (s) | reconstruct %dx%dx%d (s) |\n|---|---:|---:|\n", c.width, c.height, c.frames);
  std::printf("| SQLite | %.3f | %.3f |\n| PostgreSQL | %.3f | %.3f |\n", Median(scans[0]), Median(recs[0]),
              Median(scans[1]), Median(recs[1]));
  std::printf("| PostgreSQL / SQLite (medians) | %.2fx | %.2fx |\n", Median(scans[1]) / Median(scans[0]),
              Median(recs[1]) / Median(recs[0]));
  std::printf("| PostgreSQL / SQLite (median of the rounds' ratios) | %.2fx | %.2fx |\n", Median(scan_ratio),
              Median(rec_ratio));
  if (rec_jobs > 0) {
    std::printf("per reconstruct on PostgreSQL: %.1f events, %.1f artifact rows\n", double(rec_events) / double(rec_jobs),
                double(rec_artifacts) / double(rec_jobs));
  }
  return g_failures == 0 ? 0 : 1;
}

// Faults: the database lost while a job runs (the job is not lost; calls that need the database
// get UNAVAILABLE meanwhile), and a shared folder that is full (RESOURCE_EXHAUSTED, nothing left).
int ScenarioFaults(const Common& c, inspection::testing::PostgresServer& pg, const fs::path& work) {
  Pool pool;
  pool.work = work;
  pool.url = pg.CreateDatabase("pool_faults");
  pool.password_file = pg.PasswordFile();
  pool.password = inspection::testing::PostgresServer::Password();
  pool.inspectd = c.bin + "/inspectd";
  pool.engine_threads = 1;
  pool.decode_threads = 1;
  pool.artifact_threads = 1;
  pool.lease_s = 30;  // longer than the outage: the replica that runs the job keeps it
  const fs::path stack = work / "stack";
  WriteSyntheticStack(stack, c.width, c.height, c.frames);
  if (!pool.Start(2)) return 1;
  std::printf("\n| fault | expected | seen |\n|---|---|---|\n");
  {
    InspectionClient a(ClientFor(pool.replicas[0].address()));
    InspectionClient b(ClientFor(pool.replicas[1].address()));
    std::string job_id;
    std::atomic<bool> running{false};
    grpc::Status upload;
    v1::Job ended;
    std::thread submit([&] {
      v1::ReconstructStart start;
      start.set_request_id("faults-db-lost");
      upload = a.ReconstructUpload(stack, start, [&](const v1::JobEvent& e) {
        job_id = e.job_id();
        if (e.state() == v1::JOB_STATE_RUNNING) running = true;
      }, &ended);
    });
    const bool was_running = PollUntil([&] { return running.load(); }, 120, 0.01);
    CHECK_OR_COUNT(was_running, "the job never ran");
    // Asked on the replica that does not run it: its answer needs the database.
    const bool a_runs = Sql(pool.url, pool.password)
                            .Count("SELECT count(*) FROM work_queue WHERE lease_owner LIKE '%-" +
                                   std::to_string(pool.replicas[0].pid) + "-%'") > 0;
    InspectionClient& other = a_runs ? b : a;
    const bool stopped = pg.Stop();
    CHECK_OR_COUNT(stopped, "pg_ctl stop");
    v1::Job seen;
    grpc::Status during = other.GetJob(job_id, &seen);
    std::printf("| database stopped while %s runs: GetJob on the other replica | UNAVAILABLE | %s: %s |\n",
                job_id.c_str(), during.error_code() == grpc::StatusCode::UNAVAILABLE ? "UNAVAILABLE" : "other",
                during.error_message().substr(0, 90).c_str());
    CHECK_OR_COUNT(during.error_code() == grpc::StatusCode::UNAVAILABLE,
                   "GetJob while the database is down: " << int(during.error_code()) << " " << during.error_message());
    // Down for a few seconds: the job's end waits for it.
    std::this_thread::sleep_for(std::chrono::seconds(3));  // the outage itself, not a synchronisation
    CHECK_OR_COUNT(pg.Start(), "pg_ctl start");
    submit.join();
    v1::Job after;
    grpc::Status got;
    PollUntil([&] {
      got = b.GetJob(job_id, &after);
      return got.ok() && after.state() == v1::JOB_STATE_SUCCEEDED;
    }, 120, 0.1);
    std::printf("| database back after 3 s | the job SUCCEEDED once | %s, upload stream %s |\n",
                v1::JobState_Name(after.state()).c_str(), upload.ok() ? "OK" : upload.error_message().substr(0, 60).c_str());
    CHECK_OR_COUNT(after.state() == v1::JOB_STATE_SUCCEEDED, "after the outage the job is " << v1::JobState_Name(after.state()));
    Sql sql(pool.url, pool.password);
    CHECK_OR_COUNT(sql.Count("SELECT count(*) FROM events WHERE job_id = '" + job_id + "'") > 0, "no events");
    CHECK_OR_COUNT(sql.Count("SELECT count(*) FROM work_queue") == 0, "the job is still queued after it ended");
  }
  pool.StopAll();
  // SIGTERM with drain_timeout_s 0: the running job is handed back at once, another replica
  // finishes it, the drained replica exits 0.
  {
    Pool drain;
    drain.work = work / "drain";
    fs::create_directories(drain.work);
    drain.url = pg.CreateDatabase("pool_drain");
    drain.password_file = pg.PasswordFile();
    drain.password = pool.password;
    drain.inspectd = pool.inspectd;
    drain.engine_threads = 1;
    drain.decode_threads = 1;
    drain.artifact_threads = 1;
    drain.lease_s = 30;
    drain.drain_s = 0;
    if (drain.Start(2)) {
      Sql sql(drain.url, drain.password);
      InspectionClient a(ClientFor(drain.replicas[0].address()));
      std::string job_id;
      std::thread submit([&] {
        v1::ReconstructStart start;
        start.set_request_id("faults-drain");
        v1::Job job;
        a.ReconstructUpload(stack, start, [&](const v1::JobEvent& e) { job_id = e.job_id(); }, &job);
      });
      size_t holder = 0;
      PollUntil([&] {
        for (size_t r = 0; r < 2; ++r) {
          if (sql.Count("SELECT count(*) FROM work_queue q JOIN jobs j USING (job_id) WHERE q.ended = 0 AND j.state = 2 "
                        "AND q.lease_owner LIKE '%-" + std::to_string(drain.replicas[r].pid) + "-%'") > 0) {
            holder = r;
            return true;
          }
        }
        return false;
      }, 120, 0.01);
      const int rc = drain.replicas[holder].Term();
      submit.join();
      InspectionClient other(ClientFor(drain.replicas[1 - holder].address()));
      v1::Job after;
      PollUntil([&] { return other.GetJob(job_id, &after).ok() && after.state() == v1::JOB_STATE_SUCCEEDED; }, 120, 0.1);
      const int64_t handed = sql.Count("SELECT count(*) FROM jobs WHERE job_id = '" + job_id + "'");
      const std::string log = ReadFile(drain.replicas[holder].log);
      const bool said = log.find("handing them back") != std::string::npos;
      std::printf("| SIGTERM (drain_timeout_s 0) while %s runs | exit 0, handed back, SUCCEEDED on the other | exit %d, %s, %s |\n",
                  job_id.c_str(), rc, said ? "handed back" : "not handed back", v1::JobState_Name(after.state()).c_str());
      CHECK_OR_COUNT(rc == 0, "the drained replica exited " << rc);
      CHECK_OR_COUNT(said, "the drained replica did not hand its job back");
      CHECK_OR_COUNT(handed == 1 && after.state() == v1::JOB_STATE_SUCCEEDED,
                     "after the drain the job is " << v1::JobState_Name(after.state()));
      drain.StopAll();
    } else {
      ++g_failures;
    }
  }
  // A full shared folder: a replica on a tmpfs too small for the upload (root: mount).
  if (geteuid() == 0) {
    Pool full;
    full.work = work / "full";
    fs::create_directories(full.work / "shared");
    if (mount("inspect-pool-test", (full.work / "shared").c_str(), "tmpfs", 0, "size=1536k") == 0) {
      full.url = pg.CreateDatabase("pool_full");
      full.password_file = pg.PasswordFile();
      full.password = pool.password;
      full.inspectd = pool.inspectd;
      if (full.Start(1)) {
        // Noise frames barely compress: 8 of 640x480 are ~2.4 MB, more than the folder holds.
        const fs::path big = work / "big";
        fs::create_directories(big);
        std::ofstream json(big / "stack.json");
        json << R"({"format": "inspection-stack", "version": 1, "pixel_size_um": 1.0, "bit_depth": 8, "frames": [)";
        cv::RNG rng(5);
        for (int k = 0; k < 8; ++k) {
          cv::Mat f(480, 640, CV_8UC1);
          rng.fill(f, cv::RNG::UNIFORM, 0, 256);
          char name[32];
          std::snprintf(name, sizeof name, "f%02d.png", k);
          cv::imwrite((big / name).string(), f);
          json << (k ? "," : "") << R"({"file": ")" << name << R"(", "z_um": )" << 5.0 * k << "}";
        }
        json << "]}";
        json.close();
        InspectionClient client(ClientFor(full.replicas[0].address()));
        v1::Job job;
        v1::ReconstructStart start;
        grpc::Status st = client.ReconstructUpload(big, start, {}, &job);
        Sql sql(full.url, full.password);
        int left = 0;
        std::error_code ec;
        for (auto it = fs::recursive_directory_iterator(full.work / "shared" / "uploads", ec);
             !ec && it != fs::recursive_directory_iterator(); ++it) {
          ++left;
        }
        std::printf("| shared folder full during an upload | RESOURCE_EXHAUSTED, nothing left | %s: %s; %d files in uploads/, %lld jobs |\n",
                    st.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED ? "RESOURCE_EXHAUSTED" : "other",
                    st.error_message().substr(0, 70).c_str(), left,
                    (long long)sql.Count("SELECT count(*) FROM jobs"));
        CHECK_OR_COUNT(st.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED,
                       "full folder: " << int(st.error_code()) << " " << st.error_message());
        CHECK_OR_COUNT(left == 0, left << " files left in uploads/");
        CHECK_OR_COUNT(sql.Count("SELECT count(*) FROM jobs") == 0 && sql.Count("SELECT count(*) FROM work_queue") == 0,
                       "a job or queue row was left by the refused upload");
        full.StopAll();
      } else {
        ++g_failures;
      }
      umount2((full.work / "shared").c_str(), MNT_DETACH);
    } else {
      std::printf("| shared folder full | (not run: cannot mount a tmpfs: %s) | |\n", std::strerror(errno));
      ++g_failures;
    }
  } else {
    std::printf("| shared folder full | (not run: mounting a tmpfs needs root) | |\n");
    ++g_failures;
  }
  return g_failures == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pool-bench: the reconstruct pool on a real PostgreSQL, loopback only"};
  Common c;
  std::string scenario = "kill";
  app.add_option("--bin", c.bin, "folder with inspectd")->required();
  app.add_option("--scenario", scenario, "kill, throughput or latency")
      ->check(CLI::IsMember({"kill", "throughput", "latency", "faults"}));
  app.add_option("--jobs", c.jobs, "reconstructions (latency: calls of each kind)")->check(CLI::Range(1, 5000));
  app.add_option("--replicas", c.replicas, "replicas (kill)")->check(CLI::Range(1, 8));
  app.add_option("--clients", c.clients, "concurrent clients (kill)")->check(CLI::Range(1, 64));
  app.add_option("--width", c.width, "stack frame width")->check(CLI::Range(32, 4096));
  app.add_option("--height", c.height, "stack frame height")->check(CLI::Range(32, 4096));
  app.add_option("--frames", c.frames, "stack frames")->check(CLI::Range(3, 200));
  app.add_option("--keep", c.keep, "keep the work folder (logs) here");
  CLI11_PARSE(app, argc, argv);

  signal(SIGPIPE, SIG_IGN);
  char tmpl[] = "/tmp/inspect-pool-XXXXXX";
  if (!mkdtemp(tmpl)) return 2;
  const fs::path work = tmpl;
  int rc = 1;
  {
    inspection::testing::PostgresServer pg;
    if (!pg.started()) {
      std::cerr << "pool-bench: PostgreSQL did not start (Debian postgresql 15 is needed)\n";
      return 1;
    }
    if (scenario == "kill") rc = ScenarioKill(c, pg, work);
    if (scenario == "throughput") rc = ScenarioThroughput(c, pg, work);
    if (scenario == "latency") rc = ScenarioLatency(c, pg, work);
    if (scenario == "faults") rc = ScenarioFaults(c, pg, work);
  }
  if (rc != 0) {
    std::cerr << "pool-bench: " << g_failures << " check(s) failed; logs in " << work << "\n";
    return rc;
  }
  if (!c.keep.empty()) {
    std::error_code ec;
    fs::rename(work, c.keep, ec);
  } else {
    std::error_code ec;
    fs::remove_all(work, ec);
  }
  std::printf("PASS\n");
  return 0;
}
