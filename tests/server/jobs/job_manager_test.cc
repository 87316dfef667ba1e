// JobManager as a specification, with a fake runner in place of the rig and no gRPC server:
// rig jobs run one at a time in submission order from a bounded queue, reconstructions beside
// them; scans and calibrations never interleave; cancel ends a queued job at once and reaches a
// running job's runner; a request id returns the earlier job (also after a restart); jobs left
// queued or running by a stopped server end FAILED with ABORTED at the next start.
// Synchronisation: the fake runner's condition variable and the jobs' event streams.
#include "server/jobs/job_manager.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "server/storage/data_store.h"
#include "tests/server/jobs/job_events.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

// Only keeps a broken test from hanging; no assert depends on how long anything takes.
constexpr auto kDeadline = std::chrono::seconds(60);

// Stands in for the rig. Each job blocks in Run until the test releases it, so the test decides
// what runs and what waits; then, like a procedure between frames, it checks the cancel flag,
// reports one frame and returns a result naming the job (or the error set for it).
class FakeRunner final : public JobRunner {
 public:
  StatusOr<v1::JobResult> Run(const JobWork& work, const JobContext& context) override {
    {
      std::unique_lock<std::mutex> lock(mu_);
      started_.push_back(context.job_id);
      cv_.notify_all();
      cv_.wait(lock, [&] { return release_all_ || released_.count(context.job_id) > 0; });
    }
    if (context.cancel->load()) return Status::Cancelled("fake runner saw the cancel at frame 1");
    context.emit([](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_ACQUIRING);
      e.mutable_frame()->set_frame_index(0);
      e.mutable_frame()->set_frame_count(1);
    });
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = errors_.find(context.job_id); it != errors_.end()) return it->second;
    v1::JobResult result;
    result.set_scan_id(context.job_id);
    return result;
  }

  // Blocks until at least n jobs have started; returns the ids of all started jobs, in order.
  std::vector<std::string> WaitStarted(size_t n) {
    std::unique_lock<std::mutex> lock(mu_);
    EXPECT_TRUE(cv_.wait_for(lock, kDeadline, [&] { return started_.size() >= n; }))
        << "only " << started_.size() << " of " << n << " jobs started";
    return started_;
  }
  std::vector<std::string> started() {
    std::lock_guard<std::mutex> lock(mu_);
    return started_;
  }
  void Release(const std::string& job_id) {
    std::lock_guard<std::mutex> lock(mu_);
    released_.insert(job_id);
    cv_.notify_all();
  }
  void ReleaseAll() {
    std::lock_guard<std::mutex> lock(mu_);
    release_all_ = true;
    cv_.notify_all();
  }
  void FailWith(const std::string& job_id, Status status) {
    std::lock_guard<std::mutex> lock(mu_);
    errors_.emplace(job_id, std::move(status));
  }

 private:
  std::mutex mu_;  // guards the members below
  std::condition_variable cv_;
  std::vector<std::string> started_;
  std::set<std::string> released_;
  bool release_all_ = false;
  std::map<std::string, Status> errors_;
};

using RecordPtr = std::shared_ptr<JobRecord>;

class JobManagerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("inspect_jobs_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    OpenStore();
  }
  void TearDown() override {
    runner_.ReleaseAll();  // a job still held would keep Shutdown waiting
    manager_.reset();
    store_.reset();
    fs::remove_all(dir_);
  }

  void OpenStore() {
    auto store = DataStore::Open(dir_);
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    store_ = std::move(*store);
  }
  void StartManager(int rig_capacity = 4, int reconstruct_capacity = 8) {
    JobManagerOptions o;
    o.rig_queue_capacity = rig_capacity;
    o.reconstruct_queue_capacity = reconstruct_capacity;
    manager_ = std::make_unique<JobManager>(o, store_.get(), &runner_);
    Status s = manager_->Start();
    ASSERT_TRUE(s.ok()) << s.ToString();
  }
  // A server restart: the manager and the store go, both come back on the same data dir. Jobs of
  // the new run are not held by the runner.
  void Restart() {
    runner_.ReleaseAll();
    manager_.reset();
    store_.reset();
    OpenStore();
    StartManager();
  }

  StatusOr<RecordPtr> Submit(v1::JobKind kind, const std::string& request_id = "", int* prepared = nullptr) {
    return manager_->Submit(kind, request_id, "label", [kind, prepared]() -> StatusOr<JobWork> {
      if (prepared) ++*prepared;
      switch (kind) {
        case v1::JOB_KIND_CALIBRATE:
          return JobWork(CalibrateWork());
        case v1::JOB_KIND_RECONSTRUCT:
          return JobWork(ReconstructWork());
        default:
          return JobWork(ScanWork());
      }
    });
  }
  RecordPtr SubmitOk(v1::JobKind kind, const std::string& request_id = "") {
    auto r = Submit(kind, request_id);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return r.ok() ? *r : nullptr;
  }

  // Follows the job's event stream to its terminal event; returns every event.
  static std::vector<v1::JobEvent> WaitForEnd(const RecordPtr& r) { return WaitForJobEnd(r, kDeadline); }
  static std::vector<v1::JobPhase> Phases(const std::vector<v1::JobEvent>& events) {
    std::vector<v1::JobPhase> phases;
    for (const v1::JobEvent& e : events) phases.push_back(e.phase());
    return phases;
  }
  int StoredJobs() {
    auto jobs = store_->ListJobs(v1::JOB_KIND_UNSPECIFIED, v1::JOB_STATE_UNSPECIFIED, 100, 0);
    EXPECT_TRUE(jobs.ok());
    return jobs.ok() ? int(jobs->size()) : -1;
  }

  fs::path dir_;
  FakeRunner runner_;  // outlives the manager (declared first, destroyed last)
  std::unique_ptr<DataStore> store_;
  std::unique_ptr<JobManager> manager_;
};

TEST_F(JobManagerTest, RigJobsRunOneAtATimeInSubmissionOrder) {
  StartManager();
  RecordPtr a = SubmitOk(v1::JOB_KIND_SCAN);
  ASSERT_EQ(runner_.WaitStarted(1), std::vector<std::string>{a->job_id()});
  RecordPtr b = SubmitOk(v1::JOB_KIND_SCAN);
  RecordPtr c = SubmitOk(v1::JOB_KIND_SCAN);
  RecordPtr d = SubmitOk(v1::JOB_KIND_SCAN);

  EXPECT_EQ(manager_->running_rig_job(), a->job_id());
  EXPECT_EQ(manager_->queued_rig_jobs(), 3);
  int expected_position = 1;
  for (const RecordPtr& r : {b, c, d}) {
    auto found = manager_->Find(r->job_id());
    ASSERT_TRUE(found.ok());
    EXPECT_EQ((*found)->Snapshot().state(), v1::JOB_STATE_QUEUED);
    EXPECT_EQ((*found)->Snapshot().queue_position(), expected_position++);
  }
  // Only the running job has started while the others wait.
  EXPECT_EQ(runner_.started().size(), 1u);

  // Each job starts only after the one before it ended.
  std::vector<RecordPtr> order = {a, b, c, d};
  for (size_t i = 0; i < order.size(); ++i) {
    // ASSERT: after a wrong start the test could only wait for jobs that never come.
    ASSERT_EQ(runner_.WaitStarted(i + 1).back(), order[i]->job_id()) << "job " << i;
    EXPECT_EQ(runner_.started().size(), i + 1);
    runner_.Release(order[i]->job_id());
    std::vector<v1::JobEvent> events = WaitForEnd(order[i]);
    const v1::Job job = order[i]->Snapshot();
    EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
    EXPECT_EQ(job.result().scan_id(), job.job_id());  // the runner's result is recorded
    EXPECT_EQ(Phases(events),
              (std::vector<v1::JobPhase>{v1::JOB_PHASE_QUEUED, v1::JOB_PHASE_ACQUIRING, v1::JOB_PHASE_DONE}));
    for (size_t k = 0; k < events.size(); ++k) EXPECT_EQ(events[k].sequence(), k + 1);
    EXPECT_EQ(events.front().message(), "queued at position " + std::to_string(i == 0 ? 1 : i));
    EXPECT_EQ(events.back().job().state(), v1::JOB_STATE_SUCCEEDED);
  }
  EXPECT_EQ(manager_->queued_rig_jobs(), 0);
  EXPECT_EQ(manager_->running_rig_job(), "");
}

TEST_F(JobManagerTest, FullRigQueueIsResourceExhaustedAndCreatesNoJob) {
  StartManager(/*rig_capacity=*/2);
  RecordPtr a = SubmitOk(v1::JOB_KIND_SCAN);
  runner_.WaitStarted(1);
  RecordPtr b = SubmitOk(v1::JOB_KIND_SCAN);
  RecordPtr c = SubmitOk(v1::JOB_KIND_SCAN);
  auto d = Submit(v1::JOB_KIND_SCAN);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(d.status().message().find("queue is full"), std::string::npos) << d.status().message();
  EXPECT_EQ(StoredJobs(), 3);

  // A place frees when the running job ends and the next one starts.
  runner_.Release(a->job_id());
  WaitForEnd(a);
  runner_.WaitStarted(2);
  EXPECT_TRUE(Submit(v1::JOB_KIND_SCAN).ok());
  EXPECT_EQ(StoredJobs(), 4);
}

TEST_F(JobManagerTest, ReconstructionsRunBesideRigJobsInTheirOwnQueue) {
  StartManager(/*rig_capacity=*/4, /*reconstruct_capacity=*/1);
  RecordPtr scan = SubmitOk(v1::JOB_KIND_SCAN);
  runner_.WaitStarted(1);
  RecordPtr r1 = SubmitOk(v1::JOB_KIND_RECONSTRUCT);
  // Starts although the scan holds the rig worker.
  EXPECT_EQ(runner_.WaitStarted(2).back(), r1->job_id());
  RecordPtr r2 = SubmitOk(v1::JOB_KIND_RECONSTRUCT);
  auto r3 = Submit(v1::JOB_KIND_RECONSTRUCT);
  ASSERT_FALSE(r3.ok());
  EXPECT_EQ(r3.status().code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(manager_->queued_rig_jobs(), 0);  // reconstructions do not occupy the rig queue
  runner_.Release(r1->job_id());
  EXPECT_EQ(runner_.WaitStarted(3).back(), r2->job_id());
  runner_.Release(r2->job_id());
  runner_.Release(scan->job_id());
  for (const RecordPtr& r : {scan, r1, r2}) {
    WaitForEnd(r);
    EXPECT_EQ(r->Snapshot().state(), v1::JOB_STATE_SUCCEEDED);
  }
}

TEST_F(JobManagerTest, ScansAndCalibrationsNeverInterleave) {
  StartManager();
  RecordPtr scan = SubmitOk(v1::JOB_KIND_SCAN);
  runner_.WaitStarted(1);
  auto cal = Submit(v1::JOB_KIND_CALIBRATE);
  ASSERT_FALSE(cal.ok());
  EXPECT_EQ(cal.status().code(), StatusCode::kAborted);
  EXPECT_NE(cal.status().message().find("a scan is running or queued"), std::string::npos);
  runner_.Release(scan->job_id());
  WaitForEnd(scan);

  RecordPtr calibration = SubmitOk(v1::JOB_KIND_CALIBRATE);
  auto second_scan = Submit(v1::JOB_KIND_SCAN);
  ASSERT_FALSE(second_scan.ok());
  EXPECT_EQ(second_scan.status().code(), StatusCode::kAborted);
  EXPECT_NE(second_scan.status().message().find("a calibration is running or queued"), std::string::npos);
  runner_.Release(calibration->job_id());
  WaitForEnd(calibration);
  EXPECT_EQ(calibration->Snapshot().state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(StoredJobs(), 2);
}

TEST_F(JobManagerTest, CancelledQueuedJobEndsAtOnceAndNeverRuns) {
  StartManager();
  RecordPtr a = SubmitOk(v1::JOB_KIND_SCAN);
  runner_.WaitStarted(1);
  RecordPtr b = SubmitOk(v1::JOB_KIND_SCAN);
  RecordPtr c = SubmitOk(v1::JOB_KIND_SCAN);

  auto cancelled = manager_->Cancel(b->job_id());
  ASSERT_TRUE(cancelled.ok());
  EXPECT_EQ(cancelled->state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(cancelled->error_code(), int(StatusCode::kCancelled));
  EXPECT_EQ(cancelled->queue_position(), 0);
  EXPECT_EQ(Phases(WaitForEnd(b)), (std::vector<v1::JobPhase>{v1::JOB_PHASE_QUEUED, v1::JOB_PHASE_DONE}));
  EXPECT_EQ(manager_->queued_rig_jobs(), 1);
  auto found_c = manager_->Find(c->job_id());
  ASSERT_TRUE(found_c.ok());
  EXPECT_EQ((*found_c)->Snapshot().queue_position(), 1);  // moved up

  runner_.Release(a->job_id());
  runner_.Release(c->job_id());
  WaitForEnd(c);
  EXPECT_EQ(runner_.started(), (std::vector<std::string>{a->job_id(), c->job_id()}));
  // The stored copy agrees.
  auto stored = store_->GetJob(b->job_id());
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->state(), v1::JOB_STATE_CANCELLED);
  // Cancelling a job that ended returns it unchanged.
  auto again = manager_->Cancel(b->job_id());
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->state(), v1::JOB_STATE_CANCELLED);
}

TEST_F(JobManagerTest, CancelledQueuedUploadIsRemovedWithItsWork) {
  StartManager();
  RecordPtr first = SubmitOk(v1::JOB_KIND_RECONSTRUCT);
  runner_.WaitStarted(1);
  const fs::path upload_dir = dir_ / "uploads" / "upload-test";
  fs::create_directories(upload_dir);
  auto upload = std::make_shared<OwnedFolder>(upload_dir);
  auto queued = manager_->Submit(v1::JOB_KIND_RECONSTRUCT, "", "", [&upload]() -> StatusOr<JobWork> {
    ReconstructWork w;
    w.upload = std::move(upload);
    return JobWork(std::move(w));
  });
  ASSERT_TRUE(queued.ok());
  EXPECT_TRUE(fs::exists(upload_dir));  // held by the queued work
  ASSERT_TRUE(manager_->Cancel((*queued)->job_id()).ok());
  EXPECT_FALSE(fs::exists(upload_dir));
}

TEST_F(JobManagerTest, CancelOfARunningJobReachesItsRunner) {
  StartManager();
  RecordPtr a = SubmitOk(v1::JOB_KIND_SCAN);
  runner_.WaitStarted(1);
  RecordPtr b = SubmitOk(v1::JOB_KIND_SCAN);

  auto running = manager_->Cancel(a->job_id());
  ASSERT_TRUE(running.ok());
  EXPECT_EQ(running->state(), v1::JOB_STATE_RUNNING);  // ends when the runner sees the flag
  EXPECT_TRUE(a->cancel_requested.load());
  runner_.Release(a->job_id());
  WaitForEnd(a);
  const v1::Job job = a->Snapshot();
  EXPECT_EQ(job.state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(job.error_code(), int(StatusCode::kCancelled));
  EXPECT_EQ(job.error_message(), "fake runner saw the cancel at frame 1");
  EXPECT_FALSE(job.has_result());

  // The queue moves on.
  EXPECT_EQ(runner_.WaitStarted(2).back(), b->job_id());
  EXPECT_FALSE(b->cancel_requested.load());
}

TEST_F(JobManagerTest, FailedRunKeepsTheRunnersCodeAndMessage) {
  StartManager();
  RecordPtr a = SubmitOk(v1::JOB_KIND_SCAN);
  runner_.WaitStarted(1);
  runner_.FailWith(a->job_id(), Status::Unavailable("camera disappeared"));
  runner_.Release(a->job_id());
  std::vector<v1::JobEvent> events = WaitForEnd(a);
  const v1::Job job = a->Snapshot();
  EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(job.error_code(), int(StatusCode::kUnavailable));
  EXPECT_EQ(job.error_message(), "camera disappeared");
  EXPECT_FALSE(job.has_result());
  EXPECT_EQ(events.back().message(), "UNAVAILABLE: camera disappeared");
}

TEST_F(JobManagerTest, RequestIdReturnsTheEarlierJobOfItsKind) {
  StartManager();
  int prepared = 0;
  auto first = Submit(v1::JOB_KIND_SCAN, "req-1", &prepared);
  ASSERT_TRUE(first.ok());
  runner_.WaitStarted(1);
  auto again = Submit(v1::JOB_KIND_SCAN, "req-1", &prepared);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ((*again)->job_id(), (*first)->job_id());
  EXPECT_EQ(prepared, 1);  // the duplicate was not even built
  EXPECT_EQ(manager_->queued_rig_jobs(), 0);

  // The key is per kind: a reconstruction with the same request id is a new job.
  auto other_kind = Submit(v1::JOB_KIND_RECONSTRUCT, "req-1", &prepared);
  ASSERT_TRUE(other_kind.ok());
  EXPECT_NE((*other_kind)->job_id(), (*first)->job_id());

  runner_.Release((*first)->job_id());
  WaitForEnd(*first);
  auto after_end = Submit(v1::JOB_KIND_SCAN, "req-1", &prepared);
  ASSERT_TRUE(after_end.ok());
  EXPECT_EQ((*after_end)->job_id(), (*first)->job_id());
  EXPECT_EQ((*after_end)->Snapshot().state(), v1::JOB_STATE_SUCCEEDED);

  // And after a restart, from the store, with its events.
  Restart();
  auto after_restart = Submit(v1::JOB_KIND_SCAN, "req-1", &prepared);
  ASSERT_TRUE(after_restart.ok());
  EXPECT_EQ((*after_restart)->job_id(), (*first)->job_id());
  EXPECT_EQ((*after_restart)->Snapshot().state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(Phases(WaitForEnd(*after_restart)),
            (std::vector<v1::JobPhase>{v1::JOB_PHASE_QUEUED, v1::JOB_PHASE_ACQUIRING, v1::JOB_PHASE_DONE}));
  EXPECT_EQ(prepared, 2);  // only the reconstruction was built besides the first scan
  EXPECT_EQ(StoredJobs(), 2);
}

TEST_F(JobManagerTest, PrepareErrorsComeBackUnchangedAndCreateNoJob) {
  StartManager();
  auto r = manager_->Submit(v1::JOB_KIND_SCAN, "req-bad", "", []() -> StatusOr<JobWork> {
    return Status::InvalidArgument("reconstruction.window_px 4 must be odd");
  });
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(r.status().message(), "reconstruction.window_px 4 must be odd");
  EXPECT_EQ(StoredJobs(), 0);
  // The request id was not used up by the failed request.
  auto ok = Submit(v1::JOB_KIND_SCAN, "req-bad");
  ASSERT_TRUE(ok.ok());
  EXPECT_EQ(StoredJobs(), 1);
}

// What a server that was killed leaves behind: the job rows as the manager last stored them.
TEST_F(JobManagerTest, JobsLeftQueuedOrRunningAreAbortedAtTheNextStart) {
  const std::pair<const char*, v1::JobState> left[] = {{"scan-queued", v1::JOB_STATE_QUEUED},
                                                       {"scan-running", v1::JOB_STATE_RUNNING}};
  for (const auto& [id, state] : left) {
    v1::Job job;
    job.set_job_id(id);
    job.set_kind(v1::JOB_KIND_SCAN);
    job.set_state(state);
    job.set_request_id(std::string("req-") + id);
    ASSERT_TRUE(store_->PutJob(job).ok());
    v1::JobEvent queued;
    queued.set_job_id(id);
    queued.set_sequence(1);
    queued.set_state(v1::JOB_STATE_QUEUED);
    queued.set_phase(v1::JOB_PHASE_QUEUED);
    ASSERT_TRUE(store_->AppendEvent(queued).ok());
  }
  StartManager();
  for (const auto& [id, state] : left) {
    auto r = manager_->Find(id);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    const v1::Job job = (*r)->Snapshot();
    EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED) << id;
    EXPECT_EQ(job.error_code(), int(StatusCode::kAborted)) << id;
    EXPECT_NE(
        job.error_message().find(state == v1::JOB_STATE_RUNNING ? "while the job was running" : "before the job ran"),
        std::string::npos)
        << job.error_message();
    std::vector<v1::JobEvent> events = WaitForEnd(*r);
    ASSERT_EQ(events.size(), 2u);
    EXPECT_EQ(events[1].sequence(), 2u);
    EXPECT_EQ(events[1].phase(), v1::JOB_PHASE_DONE);
    EXPECT_EQ(events[1].job().state(), v1::JOB_STATE_FAILED);
  }
  // Nothing of the earlier run is run again, and the rig queue is free.
  EXPECT_EQ(manager_->queued_rig_jobs(), 0);
  RecordPtr fresh = SubmitOk(v1::JOB_KIND_SCAN);
  EXPECT_EQ(runner_.WaitStarted(1), std::vector<std::string>{fresh->job_id()});
}

TEST_F(JobManagerTest, ShutdownAbortsQueuedJobsAndCancelsTheRunningOne) {
  StartManager();
  RecordPtr a = SubmitOk(v1::JOB_KIND_SCAN);
  runner_.WaitStarted(1);
  RecordPtr b = SubmitOk(v1::JOB_KIND_SCAN);
  std::thread shutdown([&] { manager_->Shutdown(); });
  WaitForEnd(b);  // ended by Shutdown while the running job still holds the worker
  EXPECT_EQ(b->Snapshot().state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(b->Snapshot().error_code(), int(StatusCode::kAborted));
  runner_.Release(a->job_id());
  shutdown.join();
  EXPECT_EQ(a->Snapshot().state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(runner_.started(), std::vector<std::string>{a->job_id()});
  auto refused = Submit(v1::JOB_KIND_SCAN);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kUnavailable);

  // After a restart both are served from the store as they ended, and not marked again.
  Restart();
  for (const auto& [r, state] : {std::pair{a, v1::JOB_STATE_CANCELLED}, std::pair{b, v1::JOB_STATE_FAILED}}) {
    auto found = manager_->Find(r->job_id());
    ASSERT_TRUE(found.ok());
    EXPECT_EQ((*found)->Snapshot().state(), state);
    EXPECT_EQ(WaitForEnd(*found).back().job().state(), state);
  }
}

}  // namespace
}  // namespace inspection
