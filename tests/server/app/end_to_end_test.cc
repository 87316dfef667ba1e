// End-to-end: the real server on loopback, driven through the real client library, on the
// simulated rig. Mid-scan actions use a held capture (RigControl), never sleeps.
#include <google/protobuf/util/time_util.h>
#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <set>

#include "common/sha256_file.h"
#include "core/io/depth_export.h"
#include "core/metrology/depth_metrics.h"
#include "core/io/stack.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

const v1::Artifact* FindArtifact(const v1::Job& job, v1::ArtifactKind kind) {
  for (const auto& a : job.result().artifacts()) {
    if (a.kind() == kind) return &a;
  }
  return nullptr;
}

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

v1::ScanRequest SmallScan(double z_step_um = 5.0) {
  v1::ScanRequest r;
  r.set_z_step_um(z_step_um);
  return r;
}

class EndToEndTest : public ServerTest {
 protected:
  // Fills z range from the rig's defaults, keeping the given step.
  v1::ScanRequest DefaultRangeScan() {
    v1::RigStatus st;
    EXPECT_TRUE(client_->GetRigStatus(&st).ok());
    v1::ScanRequest r;
    r.set_z_start_um(st.scan_defaults().z_start_um());
    r.set_z_end_um(st.scan_defaults().z_end_um());
    r.set_z_step_um(st.scan_defaults().z_step_um());
    return r;
  }
};

// depth of the simulated tilted textured plane against its ground truth.
// Bound: 0.2 z step. Gaussian interpolation of a well-textured focus curve resolves well below
// one step (thesis 3.1.4); half a step would be what the maximum method alone reaches.
TEST_F(EndToEndTest, ScanOfTiltedPlaneMatchesGroundTruth) {
  StartServer();
  v1::RigStatus st;
  ASSERT_TRUE(client_->GetRigStatus(&st).ok());
  EXPECT_EQ(st.state(), v1::RIG_STATE_READY);
  EXPECT_TRUE(st.simulated());
  EXPECT_EQ(st.specimen(), "skew5");
  const double step = st.scan_defaults().z_step_um();
  ASSERT_GT(step, 0);

  std::vector<v1::JobEvent> events;
  v1::Job job;
  grpc::Status s = client_->Scan(
      v1::ScanRequest(), [&](const v1::JobEvent& e) { events.push_back(e); }, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);

  // Events: numbered from 1 without gaps, per-frame statistics, one terminal event at the end.
  ASSERT_FALSE(events.empty());
  int frames = 0;
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_EQ(events[i].sequence(), i + 1);
    EXPECT_EQ(events[i].job_id(), job.job_id());
    if (events[i].has_frame()) {
      ++frames;
      EXPECT_GT(events[i].frame().statistics().mean_grey(), 20.0);
      EXPECT_GT(events[i].frame().frame_count(), 2);
    }
  }
  EXPECT_EQ(events.back().state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(frames, job.result().depth().frame_count());

  // Download the results as a user would and compare with the ground truth ourselves.
  const fs::path out = UniqueTempDir("out");
  std::vector<fs::path> written;
  ASSERT_TRUE(client_->DownloadResults(job, out, false, &written).ok());
  for (const char* f :
       {"depth.tiff", "confidence.tiff", "all_in_focus.png", "depth_preview.png", "ground_truth_depth.tiff"}) {
    EXPECT_TRUE(fs::exists(out / f)) << f;
  }
  auto depth = ReadDepthTiff(out / "depth.tiff");
  auto truth = ReadDepthTiff(out / "ground_truth_depth.tiff");
  ASSERT_TRUE(depth.ok() && truth.ok());
  DepthErrorStats e = CompareDepth(*depth, *truth, 2.0 * step, /*border_px=*/3);
  std::printf("skew5 scan: %d frames, step %.2f um, valid %.2f %%, RMSE %.3f um (%.3f step), outliers %.2f %%\n",
              frames, step, e.valid_percent, e.rmse_um, e.rmse_um / step, e.outlier_percent);
  EXPECT_GT(e.valid_percent, 99.0);
  EXPECT_LT(e.rmse_um, 0.2 * step);
  EXPECT_NEAR(job.result().depth().rmse_um(), e.rmse_um, 0.05 * step);
  EXPECT_TRUE(job.result().depth().has_ground_truth());

  // The scan is stored in the stack format and can be reconstructed again by id.
  v1::ReconstructStart start;
  start.set_scan_id(job.result().scan_id());
  v1::Job rec;
  ASSERT_TRUE(client_->ReconstructStored(start, nullptr, &rec).ok());
  EXPECT_EQ(rec.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_NEAR(rec.result().depth().rmse_um(), job.result().depth().rmse_um(), 1e-3);
  fs::remove_all(out);
}

TEST_F(EndToEndTest, WatchJobReattachesAfterDisconnectAndGetsTheResult) {
  StartServer();
  control_->hold_at_frame = 3;
  v1::ScanRequest req = SmallScan();
  std::string job_id;
  {
    // First client: reads the stream until the scan is held mid-way, then disconnects.
    auto stub = v1::InspectionService::NewStub(client_->channel());
    grpc::ClientContext ctx;
    auto reader = stub->Scan(&ctx, DefaultRangeScan());
    v1::JobEvent e;
    ASSERT_TRUE(reader->Read(&e));
    job_id = e.job_id();
    ASSERT_TRUE(control_->WaitUntilHolding());
    ctx.TryCancel();
    while (reader->Read(&e)) {
    }
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  v1::Job mid;
  ASSERT_TRUE(client_->GetJob(job_id, &mid).ok());
  EXPECT_EQ(mid.state(), v1::JOB_STATE_RUNNING);  // the job does not die with its first client
  control_->Release();

  auto second = NewClient();
  std::vector<v1::JobEvent> events;
  v1::Job job;
  grpc::Status s = second->Watch(
      job_id, [&](const v1::JobEvent& e) { events.push_back(e); }, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.front().sequence(), 1u);  // replayed from the start
  EXPECT_NE(FindArtifact(job, v1::ARTIFACT_KIND_DEPTH_TIFF), nullptr);
}

class LargeArtifactTest : public EndToEndTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o = EndToEndTest::SimOptions();
    o.camera_size = {640, 480};
    return o;
  }
};

TEST_F(LargeArtifactTest, DownloadsArtifactLargerThan4MiBVerifiedAndResumed) {
  StartServer();
  v1::Job job;
  ASSERT_TRUE(client_->Scan(DefaultRangeScan(), nullptr, &job).ok());
  const v1::Artifact* zip = FindArtifact(job, v1::ARTIFACT_KIND_STACK_ZIP);
  ASSERT_NE(zip, nullptr);
  ASSERT_GT(zip->size_bytes(), 4 << 20) << "the test needs an artifact beyond gRPC's 4 MiB message limit";

  const fs::path out = UniqueTempDir("dl");
  ASSERT_TRUE(client_->DownloadArtifact(zip->artifact_id(), out / "stack.zip", false).ok());
  EXPECT_EQ(int64_t(fs::file_size(out / "stack.zip")), zip->size_bytes());
  EXPECT_EQ(Sha256FileHex(out / "stack.zip"), zip->sha256());
  const std::string full = ReadAll(out / "stack.zip");

  // A range from an offset returns exactly those bytes, with the whole file's sha256.
  std::string part, sha;
  int64_t total = 0;
  const int64_t offset = 3 * (1 << 20) + 12345;
  ASSERT_TRUE(client_->DownloadRange(zip->artifact_id(), offset, 2 << 20, &part, &sha, &total).ok());
  EXPECT_EQ(total, zip->size_bytes());
  EXPECT_EQ(sha, zip->sha256());
  EXPECT_EQ(part, full.substr(size_t(offset), 2 << 20));

  // Resume: an interrupted download (the first 60 % on disk as .part) completes and verifies.
  const int64_t interrupted_at = zip->size_bytes() * 6 / 10;
  {
    std::ofstream p(out / "resumed.zip.part", std::ios::binary);
    p.write(full.data(), interrupted_at);
  }
  int64_t first_progress = -1;
  ASSERT_TRUE(client_
                  ->DownloadArtifact(zip->artifact_id(), out / "resumed.zip", true,
                                     [&](int64_t done, int64_t) {
                                       if (first_progress < 0) first_progress = done;
                                     })
                  .ok());
  EXPECT_GT(first_progress, interrupted_at);  // continued, did not start again from zero
  EXPECT_EQ(ReadAll(out / "resumed.zip"), full);

  // Offsets beyond the end are refused naming the field.
  grpc::Status s = client_->DownloadRange(zip->artifact_id(), zip->size_bytes() + 1, 0, &part, &sha, &total);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::OUT_OF_RANGE);
  EXPECT_NE(s.error_message().find("offset"), std::string::npos);
  fs::remove_all(out);
}

TEST_F(EndToEndTest, SecondScanIsQueuedAndAFullQueueIsResourceExhausted) {
  StartServer(/*queue_capacity=*/1);
  control_->hold_at_frame = 2;
  auto c1 = NewClient();
  v1::Job job1;
  std::thread t1([&] { ASSERT_TRUE(c1->Scan(SmallScan(), nullptr, &job1).ok()); });
  ASSERT_TRUE(control_->WaitUntilHolding());

  // Second scan: accepted and queued behind the running one.
  auto stub = v1::InspectionService::NewStub(client_->channel());
  grpc::ClientContext ctx2;
  auto reader2 = stub->Scan(&ctx2, DefaultRangeScan());
  v1::JobEvent first;
  ASSERT_TRUE(reader2->Read(&first));
  EXPECT_EQ(first.state(), v1::JOB_STATE_QUEUED);
  v1::Job queued;
  ASSERT_TRUE(client_->GetJob(first.job_id(), &queued).ok());
  EXPECT_EQ(queued.queue_position(), 1);
  v1::RigStatus st;
  ASSERT_TRUE(client_->GetRigStatus(&st).ok());
  EXPECT_EQ(st.state(), v1::RIG_STATE_BUSY);
  EXPECT_EQ(st.queued_jobs(), 1);

  // Third: the queue (capacity 1) is full.
  v1::Job job3;
  grpc::Status s3 = client_->Scan(SmallScan(), nullptr, &job3);
  EXPECT_EQ(s3.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(s3.error_message().find("queue is full"), std::string::npos);

  control_->Release();
  t1.join();
  EXPECT_EQ(job1.state(), v1::JOB_STATE_SUCCEEDED);
  v1::JobEvent e;
  v1::JobEvent last;
  while (reader2->Read(&e)) last = e;
  EXPECT_TRUE(reader2->Finish().ok());
  EXPECT_EQ(last.state(), v1::JOB_STATE_SUCCEEDED);
  // Serialised: the second scan started only after the first ended.
  EXPECT_GE(google::protobuf::util::TimeUtil::TimestampToNanoseconds(last.job().start_time()),
            google::protobuf::util::TimeUtil::TimestampToNanoseconds(job1.end_time()));
}

TEST_F(EndToEndTest, CancelMidScanEndsCancelledWithoutArtifacts) {
  StartServer();
  control_->hold_at_frame = 3;
  v1::Job job;
  grpc::Status scan_status;
  std::string job_id;
  std::mutex mu;
  std::thread t([&] {
    scan_status = client_->Scan(
        SmallScan(),
        [&](const v1::JobEvent& e) {
          std::lock_guard<std::mutex> l(mu);
          job_id = e.job_id();
        },
        &job);
  });
  ASSERT_TRUE(control_->WaitUntilHolding());
  auto other = NewClient();
  v1::Job cancelled;
  std::string id;
  {
    std::lock_guard<std::mutex> l(mu);
    id = job_id;
  }
  ASSERT_FALSE(id.empty());
  ASSERT_TRUE(other->CancelJob(id, &cancelled).ok());
  control_->Release();
  t.join();
  EXPECT_EQ(scan_status.error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_EQ(job.state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(job.result().artifacts_size(), 0);

  v1::Job stored;
  ASSERT_TRUE(other->GetJob(id, &stored).ok());
  EXPECT_EQ(stored.state(), v1::JOB_STATE_CANCELLED);
  EXPECT_FALSE(stored.has_result());
  v1::RigStatus st;
  ASSERT_TRUE(other->GetRigStatus(&st).ok());
  EXPECT_EQ(st.state(), v1::RIG_STATE_READY);
  // Nothing partial is left: no stored scan, no artifacts, empty work area.
  EXPECT_FALSE(fs::exists(data_dir_ / "scans" / id));
  EXPECT_FALSE(fs::exists(data_dir_ / "artifacts" / id));
  EXPECT_TRUE(fs::is_empty(data_dir_ / "tmp"));
  // A new scan works afterwards.
  v1::Job next;
  EXPECT_TRUE(client_->Scan(SmallScan(), nullptr, &next).ok());
}

TEST_F(EndToEndTest, RequestIdMakesARepeatedScanReturnTheSameJob) {
  StartServer();
  v1::ScanRequest req = SmallScan();
  req.set_request_id("mes-order-4711");
  v1::Job a, b;
  ASSERT_TRUE(client_->Scan(req, nullptr, &a).ok());
  ASSERT_TRUE(client_->Scan(req, nullptr, &b).ok());
  EXPECT_EQ(a.job_id(), b.job_id());
  v1::ListJobsRequest lr;
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(lr, &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 1);
}

TEST_F(EndToEndTest, JobsAndResultsSurviveARestart) {
  StartServer();
  v1::Job job;
  ASSERT_TRUE(client_->Scan(SmallScan(), nullptr, &job).ok());
  const v1::Artifact* depth = FindArtifact(job, v1::ARTIFACT_KIND_DEPTH_TIFF);
  ASSERT_NE(depth, nullptr);
  const std::string artifact_id = depth->artifact_id();
  StopServer();

  StartServer();
  v1::Job again;
  ASSERT_TRUE(client_->GetJob(job.job_id(), &again).ok());
  EXPECT_EQ(again.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(again.result().artifacts_size(), job.result().artifacts_size());
  std::vector<v1::JobEvent> replay;
  v1::Job watched;
  ASSERT_TRUE(client_
                  ->Watch(
                      job.job_id(), [&](const v1::JobEvent& e) { replay.push_back(e); }, &watched)
                  .ok());
  EXPECT_EQ(watched.job_id(), job.job_id());
  EXPECT_EQ(replay.back().state(), v1::JOB_STATE_SUCCEEDED);
  const fs::path out = UniqueTempDir("restart");
  ASSERT_TRUE(client_->DownloadArtifact(artifact_id, out / "depth.tiff", false).ok());
  EXPECT_EQ(Sha256FileHex(out / "depth.tiff"), depth->sha256());
  fs::remove_all(out);
}

TEST_F(EndToEndTest, JobLeftRunningByACrashIsMarkedAbortedAtStart) {
  // What a crash leaves behind: a job row still RUNNING.
  {
    auto store = DataStore::Open(data_dir_);
    ASSERT_TRUE(store.ok());
    v1::Job j;
    j.set_job_id("scan-crashed");
    j.set_kind(v1::JOB_KIND_SCAN);
    j.set_state(v1::JOB_STATE_RUNNING);
    ASSERT_TRUE((*store)->PutJob(j).ok());
  }
  StartServer();
  v1::Job j;
  ASSERT_TRUE(client_->GetJob("scan-crashed", &j).ok());
  EXPECT_EQ(j.state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(j.error_code(), int(grpc::StatusCode::ABORTED));
  v1::Job watched;
  grpc::Status s = client_->Watch("scan-crashed", nullptr, &watched);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ABORTED);
  EXPECT_EQ(watched.state(), v1::JOB_STATE_FAILED);
}

TEST_F(EndToEndTest, ShutdownCancelsTheRunningScanAndLeavesNothingPartial) {
  StartServer();
  control_->hold_at_frame = 2;
  std::string job_id;
  std::mutex mu;
  v1::Job j;
  std::thread t([&] {
    client_->Scan(
        SmallScan(),
        [&](const v1::JobEvent& e) {
          std::lock_guard<std::mutex> l(mu);
          job_id = e.job_id();
        },
        &j);
  });
  ASSERT_TRUE(control_->WaitUntilHolding());
  control_->Release();
  server_->Shutdown();
  t.join();
  StopServer();
  control_ = std::make_shared<RigControl>();
  StartServer();
  v1::Job after;
  ASSERT_TRUE(client_->GetJob(job_id, &after).ok());
  EXPECT_TRUE(after.state() == v1::JOB_STATE_CANCELLED || after.state() == v1::JOB_STATE_FAILED) << after.state();
  EXPECT_FALSE(after.has_result());
  EXPECT_FALSE(fs::exists(data_dir_ / "scans" / job_id));
  EXPECT_TRUE(fs::is_empty(data_dir_ / "tmp"));
}

}  // namespace
}  // namespace inspection::testing
