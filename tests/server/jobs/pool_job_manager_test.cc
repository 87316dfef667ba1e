// JobManager in pool mode as a specification, in process, on a real private PostgreSQL
// (tests/lib/postgres_server.h) with a fake runner: the `inspectd_queue_depth` gauge scraped from
// /metrics over HTTP is the number of jobs no worker can take yet, and 0 once they ran (and on
// SQLite, one rig: the queued reconstructs); a job's events reach the store complete and in
// order, the terminal one last; partial uploads of a dead writer on the shared folder are swept,
// a live writer's are not.
// Synchronisation: the fake runner's condition variable and the jobs' event streams; the gauge
// and the sweep are sampled by the manager's heartbeat, so those checks poll with a deadline.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "server/http/operations_http.h"
#include "server/jobs/job_manager.h"
#include "server/storage/data_store.h"
#include "tests/server/jobs/job_events.h"
#include "tests/lib/postgres_server.h"
// Last: httplib.h pulls in <resolv.h>, whose `_res` macro breaks Eigen's headers.
#include <httplib.h>

namespace inspection {
namespace {
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// Only keeps a broken test from hanging; no assert depends on how long anything takes.
constexpr auto kDeadline = std::chrono::seconds(60);

testing::PostgresServer& Postgres() {
  static testing::PostgresServer server;  // one per test process
  return server;
}

// Each job blocks until the test releases it, then reports `progress_events` frames and returns a
// result naming the job.
class BlockingRunner final : public JobRunner {
 public:
  explicit BlockingRunner(int progress_events = 1) : progress_events_(progress_events) {}
  StatusOr<v1::JobResult> Run(const JobWork&, const JobContext& context) override {
    {
      std::unique_lock<std::mutex> lock(mu_);
      started_.push_back(context.job_id);
      cv_.notify_all();
      cv_.wait(lock, [&] { return released_; });
    }
    for (int i = 0; i < progress_events_; ++i) {
      context.emit([&](v1::JobEvent& e) {
        e.set_phase(v1::JOB_PHASE_RECONSTRUCTING);
        e.mutable_frame()->set_frame_index(i);
        e.mutable_frame()->set_frame_count(progress_events_);
      });
    }
    v1::JobResult result;
    result.set_scan_id(context.job_id);
    return result;
  }
  void WaitStarted(size_t n) {
    std::unique_lock<std::mutex> lock(mu_);
    EXPECT_TRUE(cv_.wait_for(lock, kDeadline, [&] { return started_.size() >= n; }))
        << started_.size() << " of " << n << " jobs started";
  }
  size_t started() {
    std::lock_guard<std::mutex> lock(mu_);
    return started_.size();
  }
  void ReleaseAll() {
    std::lock_guard<std::mutex> lock(mu_);
    released_ = true;
    cv_.notify_all();
  }

 private:
  const int progress_events_;
  std::mutex mu_;  // guards the members below
  std::condition_variable cv_;
  std::vector<std::string> started_;
  bool released_ = false;
};

using RecordPtr = std::shared_ptr<JobRecord>;

// Polls `cond` until it holds or the deadline passes (for values the heartbeat samples).
bool PollUntil(const std::function<bool()>& cond) {
  const auto deadline = Clock::now() + kDeadline;
  while (Clock::now() < deadline) {
    if (cond()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // paces the checks only
  }
  return cond();
}

std::vector<v1::JobEvent> WaitForEnd(const RecordPtr& r) { return WaitForJobEnd(r, kDeadline); }

class PoolJobManagerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static int counter = 0;
    const std::string tag = std::to_string(::getpid()) + "_" + std::to_string(++counter);
    dir_ = fs::temp_directory_path() / ("inspect_pool_jobs_" + tag);
    fs::remove_all(dir_);
    ASSERT_TRUE(Postgres().started());
    database_.url = Postgres().CreateDatabase("pool_jobs_" + tag);
    database_.password_file = Postgres().PasswordFile();
  }
  void TearDown() override {
    for (auto& r : runners_) r->ReleaseAll();  // a job still held would keep Shutdown waiting
    http_.reset();  // it asks a manager for the gauge
    managers_.clear();
    stores_.clear();
    fs::remove_all(dir_);
  }

  // One replica: its own store (connection) on the shared database and folder, its manager.
  JobManager* StartReplica(const std::string& name, int progress_events = 1) {
    auto store = DataStore::Open(dir_, database_);
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    if (!store.ok()) return nullptr;
    stores_.push_back(std::move(*store));
    runners_.push_back(std::make_unique<BlockingRunner>(progress_events));
    JobManagerOptions o;
    o.pool.enabled = true;
    o.pool.worker_id = name;
    o.pool.workers = 1;
    o.pool.lease = std::chrono::milliseconds(600);  // the heartbeat samples every 200 ms
    o.pool.poll = std::chrono::milliseconds(50);
    managers_.push_back(std::make_unique<JobManager>(o, stores_.back().get(), runners_.back().get()));
    Status s = managers_.back()->Start();
    EXPECT_TRUE(s.ok()) << s.ToString();
    return managers_.back().get();
  }
  // A reconstruction of an "uploaded" stack: the folder the service would have received.
  RecordPtr SubmitUpload(JobManager* manager, DataStore* store) {
    auto r = manager->Submit(v1::JOB_KIND_RECONSTRUCT, "", "label", [store]() -> StatusOr<JobWork> {
      ReconstructWork w;
      w.upload = store->NewUploadFolder("upload");
      fs::create_directories(w.upload->path());
      std::ofstream(w.upload->path() / "stack.json") << "{}";
      w.stack_dir = w.upload->path();
      w.pool_input = "start";
      return JobWork(std::move(w));
    });
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return r.ok() ? *r : nullptr;
  }
  // /metrics over HTTP, as Prometheus reads it.
  void StartHttp(JobManager* manager, DataStore* store) {
    http_ = std::make_unique<OperationsHttp>("test");
    HttpEndpointOptions endpoint;
    endpoint.listen_address = "127.0.0.1:0";
    DashboardSources sources;
    sources.store = store;
    sources.jobs = manager;
    Status s = http_->Start(endpoint, sources, dir_);
    ASSERT_TRUE(s.ok()) << s.ToString();
  }
  // The value of the inspectd_queue_depth sample in a real scrape; -1 when absent.
  double ScrapeQueueDepth() {
    httplib::Client client("127.0.0.1", http_->port());
    auto res = client.Get("/metrics");
    EXPECT_TRUE(res && res->status == 200) << "GET /metrics";
    if (!res) return -1;
    std::istringstream in(res->body);
    for (std::string line; std::getline(in, line);) {
      if (line.rfind("inspectd_queue_depth ", 0) == 0) return std::stod(line.substr(line.find(' ') + 1));
    }
    ADD_FAILURE() << "no inspectd_queue_depth sample in:\n" << res->body;
    return -1;
  }
  int UploadFolders() {
    int n = 0;
    for (const auto& e : fs::directory_iterator(dir_ / "uploads")) n += e.is_directory();
    return n;
  }

  fs::path dir_;
  DatabaseOptions database_;
  std::vector<std::unique_ptr<BlockingRunner>> runners_;  // outlive the managers
  std::vector<std::unique_ptr<DataStore>> stores_;
  std::unique_ptr<OperationsHttp> http_;
  std::vector<std::unique_ptr<JobManager>> managers_;
};

TEST_F(PoolJobManagerTest, TheQueueDepthGaugeIsTheJobsNoWorkerCanTakeAndZeroOnceTheyRan) {
  JobManager* replica = StartReplica("replica-1");
  ASSERT_NE(replica, nullptr);
  DataStore* store = stores_.back().get();
  StartHttp(replica, store);
  EXPECT_EQ(ScrapeQueueDepth(), 0.0);

  // The only worker takes the first job and is held there; the next three wait in the pool.
  std::vector<RecordPtr> jobs{SubmitUpload(replica, store)};
  runners_.back()->WaitStarted(1);
  for (int i = 0; i < 3; ++i) jobs.push_back(SubmitUpload(replica, store));
  EXPECT_EQ(*store->QueueDepth(), 3);
  double seen = -1;
  EXPECT_TRUE(PollUntil([&] { return (seen = ScrapeQueueDepth()) == 3.0; })) << "gauge " << seen;
  EXPECT_EQ(replica->reconstruct_queue_depth(), 3);
  EXPECT_EQ(runners_.back()->started(), 1u);  // nothing else ran meanwhile: the 3 really waited

  runners_.back()->ReleaseAll();
  for (const RecordPtr& r : jobs) {
    WaitForEnd(r);
    EXPECT_EQ(r->Snapshot().state(), v1::JOB_STATE_SUCCEEDED) << r->Snapshot().error_message();
  }
  EXPECT_EQ(*store->QueueDepth(), 0);
  EXPECT_TRUE(PollUntil([&] { return (seen = ScrapeQueueDepth()) == 0.0; })) << "gauge " << seen;
  EXPECT_EQ(runners_.back()->started(), 4u);
  // Every job's stored input went with its end.
  EXPECT_TRUE(PollUntil([&] { return UploadFolders() == 0; })) << UploadFolders() << " folders in uploads/";
}

TEST_F(PoolJobManagerTest, AJobsEventsReachTheStoreCompleteAndInOrderTheTerminalOneLast) {
  JobManager* replica = StartReplica("replica-1", /*progress_events=*/25);
  ASSERT_NE(replica, nullptr);
  DataStore* store = stores_.back().get();
  runners_.back()->ReleaseAll();
  RecordPtr r = SubmitUpload(replica, store);
  const std::vector<v1::JobEvent> streamed = WaitForEnd(r);
  ASSERT_EQ(r->Snapshot().state(), v1::JOB_STATE_SUCCEEDED) << r->Snapshot().error_message();
  auto stored = store->Events(r->job_id());
  ASSERT_TRUE(stored.ok()) << stored.status().ToString();
  // QUEUED, PREPARING, 25 frames, DONE: what the client was streamed is what the store holds.
  ASSERT_EQ(stored->size(), 28u);
  ASSERT_EQ(streamed.size(), stored->size());
  for (size_t i = 0; i < stored->size(); ++i) {
    EXPECT_EQ((*stored)[i].sequence(), i + 1);
    EXPECT_EQ((*stored)[i].SerializeAsString(), streamed[i].SerializeAsString()) << "event " << i + 1;
  }
  EXPECT_EQ(stored->front().phase(), v1::JOB_PHASE_QUEUED);
  EXPECT_EQ(stored->back().phase(), v1::JOB_PHASE_DONE);
  EXPECT_EQ(stored->back().job().state(), v1::JOB_STATE_SUCCEEDED);
  auto job = store->GetJob(r->job_id());
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state(), v1::JOB_STATE_SUCCEEDED);
}

TEST_F(PoolJobManagerTest, ADeadWritersPartialUploadIsSweptALiveWritersIsKept) {
  JobManager* sweeper = StartReplica("replica-1");
  JobManager* writer = StartReplica("replica-2");
  ASSERT_NE(sweeper, nullptr);
  ASSERT_NE(writer, nullptr);
  // Replica 2 is receiving an upload (its folder held, so its manager keeps touching it); a
  // replica killed mid-upload left another one, held by nobody, that no job refers to.
  std::shared_ptr<OwnedFolder> live = stores_[1]->NewUploadFolder("upload");
  fs::create_directories(live->path());
  std::ofstream(live->path() / "frame_0000.png") << "partial";
  const fs::path orphan = dir_ / "uploads" / "upload-killed";
  fs::create_directories(orphan);
  std::ofstream(orphan / "frame_0000.png") << "partial";

  EXPECT_TRUE(PollUntil([&] { return !fs::exists(orphan); })) << "the orphaned upload is still there";
  // Both were seen by the same sweeps: only the touching tells them apart.
  EXPECT_TRUE(fs::exists(live->path() / "frame_0000.png"));

  // Replica 2 dies too (its hold gone, its folder left as kill -9 leaves it).
  const fs::path left = live->path();
  live->Release();
  EXPECT_TRUE(PollUntil([&] { return !fs::exists(left); })) << "the second orphan is still there";
  EXPECT_EQ(UploadFolders(), 0);
}

TEST(SingleRigQueueDepth, TheGaugeIsTheReconstructsQueuedBehindTheRunningOne) {
  const fs::path dir = fs::temp_directory_path() / ("inspect_rig_depth_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  auto store = DataStore::Open(dir);  // SQLite: one rig, this process's queue
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  BlockingRunner runner;
  {
    JobManager manager(JobManagerOptions{}, store->get(), &runner);
    ASSERT_TRUE(manager.Start().ok());
    OperationsHttp http("test");
    HttpEndpointOptions endpoint;
    endpoint.listen_address = "127.0.0.1:0";
    DashboardSources sources;
    sources.store = store->get();
    sources.jobs = &manager;
    ASSERT_TRUE(http.Start(endpoint, sources, dir).ok());
    auto scrape = [&] {
      httplib::Client client("127.0.0.1", http.port());
      auto res = client.Get("/metrics");
      EXPECT_TRUE(res && res->status == 200);
      std::istringstream in(res ? res->body : "");
      for (std::string line; std::getline(in, line);) {
        if (line.rfind("inspectd_queue_depth ", 0) == 0) return std::stod(line.substr(line.find(' ') + 1));
      }
      return -1.0;
    };
    auto submit = [&] {
      auto r = manager.Submit(v1::JOB_KIND_RECONSTRUCT, "", "label", [] { return StatusOr<JobWork>(ReconstructWork()); });
      EXPECT_TRUE(r.ok()) << r.status().ToString();
      return r.ok() ? *r : nullptr;
    };
    std::vector<RecordPtr> jobs{submit()};
    runner.WaitStarted(1);
    jobs.push_back(submit());
    jobs.push_back(submit());
    // Not sampled: this process's own queue, exact at every scrape.
    EXPECT_EQ(scrape(), 2.0);
    runner.ReleaseAll();
    for (const RecordPtr& r : jobs) {
      WaitForEnd(r);
      EXPECT_EQ(r->Snapshot().state(), v1::JOB_STATE_SUCCEEDED);
    }
    EXPECT_EQ(scrape(), 0.0);
    http.Stop();
  }
  store->reset();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace inspection
