// Data lifecycle through the real server: DeleteJob / DeleteScan / PinJob, the retention sweep
// (bytes before and after, pinned and newest kept, running jobs untouched), the free-space
// reserve, and a scan that fills a small tmpfs data directory: RESOURCE_EXHAUSTED "data disk
// full", nothing partial left, the job FAILED the same way after a restart.
#include <gtest/gtest.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <thread>

#include "core/io/stack.h"
#include "server/jobs/retention_sweeper.h"
#include "tests/server/server_fixture.h"
#include "tests/lib/skip_or_fail.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

class DataLifecycleServerTest : public ServerTest {
 protected:
  v1::Job ScanOk(const std::string& label = "") {
    v1::ScanRequest req;
    req.set_label(label);
    v1::Job job;
    grpc::Status s = client_->Scan(req, {}, &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return job;
  }
  fs::path ArtifactDir(const std::string& id) { return data_dir_ / "artifacts" / id; }
  static int CountEntries(const fs::path& dir) {
    std::error_code ec;
    int n = 0;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) ++n;
    return n;
  }
};

TEST_F(DataLifecycleServerTest, DeleteJobRemovesRecordEventsArtifactsAndStack) {
  StartServer();
  const v1::Job job = ScanOk();
  ASSERT_TRUE(fs::is_directory(ArtifactDir(job.job_id())));
  const int64_t bytes = FolderBytes(ArtifactDir(job.job_id()));
  ASSERT_GT(bytes, 0);
  const std::string artifact_id = job.result().artifacts(0).artifact_id();

  v1::DeleteResponse deleted;
  ASSERT_TRUE(client_->DeleteJob(job.job_id(), &deleted).ok());
  EXPECT_EQ(deleted.id(), job.job_id());
  EXPECT_EQ(deleted.bytes_freed(), bytes);
  EXPECT_EQ(deleted.artifacts_deleted(), job.result().artifacts_size());
  EXPECT_FALSE(fs::exists(ArtifactDir(job.job_id())));
  v1::Job gone;
  EXPECT_EQ(client_->GetJob(job.job_id(), &gone).error_code(), grpc::StatusCode::NOT_FOUND);
  std::string data, sha;
  int64_t total = 0;
  EXPECT_EQ(client_->DownloadRange(artifact_id, 0, 0, &data, &sha, &total).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->DeleteJob(job.job_id(), &deleted).error_code(), grpc::StatusCode::NOT_FOUND);
  v1::ListJobsResponse list;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &list).ok());
  EXPECT_EQ(list.jobs_size(), 0);
}

TEST_F(DataLifecycleServerTest, DeleteScanKeepsTheJobAndItsDepthResults) {
  StartServer();
  const v1::Job job = ScanOk();
  std::string zip_id, depth_id;
  for (const auto& a : job.result().artifacts()) {
    if (a.kind() == v1::ARTIFACT_KIND_STACK_ZIP) zip_id = a.artifact_id();
    if (a.kind() == v1::ARTIFACT_KIND_DEPTH_TIFF) depth_id = a.artifact_id();
  }
  ASSERT_FALSE(zip_id.empty());
  ASSERT_FALSE(depth_id.empty());
  const int64_t zip_bytes = fs::file_size(ArtifactDir(job.job_id()) / "stack.zip");

  v1::DeleteResponse deleted;
  ASSERT_TRUE(client_->DeleteScan(job.job_id(), &deleted).ok());
  EXPECT_EQ(deleted.bytes_freed(), zip_bytes);
  EXPECT_EQ(deleted.artifacts_deleted(), 1);
  EXPECT_FALSE(fs::exists(ArtifactDir(job.job_id()) / "stack.zip"));
  v1::Job kept;
  ASSERT_TRUE(client_->GetJob(job.job_id(), &kept).ok());
  EXPECT_EQ(kept.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(kept.result().artifacts_size(), job.result().artifacts_size() - 1);
  std::string data, sha;
  int64_t total = 0;
  EXPECT_TRUE(client_->DownloadRange(depth_id, 0, 0, &data, &sha, &total).ok());
  EXPECT_EQ(client_->DownloadRange(zip_id, 0, 0, &data, &sha, &total).error_code(), grpc::StatusCode::NOT_FOUND);
  v1::ReconstructStart start;
  start.set_scan_id(job.job_id());
  v1::Job rec;
  EXPECT_EQ(client_->ReconstructStored(start, {}, &rec).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->DeleteScan(job.job_id(), &deleted).error_code(), grpc::StatusCode::NOT_FOUND);
}

// The raw stack is stored once, as the stack.zip artifact; a reconstruction of the stored scan
// reads a private extraction that goes with its job.
TEST_F(DataLifecycleServerTest, TheStackIsStoredOnceAndReconstructionsReadTheArchive) {
  StartServer();
  const v1::Job job = ScanOk();
  int64_t zip_bytes = 0, frame_count = job.result().depth().frame_count();
  for (const auto& a : job.result().artifacts()) {
    if (a.kind() == v1::ARTIFACT_KIND_STACK_ZIP) zip_bytes = a.size_bytes();
  }
  ASSERT_GT(zip_bytes, 0);
  EXPECT_EQ(CountEntries(data_dir_ / "scans"), 0);
  EXPECT_EQ(CountEntries(data_dir_ / "tmp"), 0);
  // Every byte of the job is its artifacts: the frames are not kept a second time.
  int64_t artifact_sum = 0;
  for (const auto& a : job.result().artifacts()) artifact_sum += a.size_bytes();
  EXPECT_EQ(FolderBytes(ArtifactDir(job.job_id())), artifact_sum);
  std::cout << "scan of " << frame_count << " frames: " << artifact_sum << " bytes stored, stack.zip " << zip_bytes
            << "\n";

  v1::ReconstructStart start;
  start.set_scan_id(job.job_id());
  v1::Job rec;
  grpc::Status s = client_->ReconstructStored(start, {}, &rec);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(rec.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(rec.result().depth().frame_count(), frame_count);
  // Same stack, same engine, same options: the same depth map as the scan's streaming one.
  EXPECT_TRUE(rec.result().depth().has_ground_truth());
  EXPECT_NEAR(rec.result().depth().rmse_um(), job.result().depth().rmse_um(), 1e-6);
  EXPECT_EQ(CountEntries(data_dir_ / "uploads"), 0);  // the extraction went with the job
}

TEST_F(DataLifecycleServerTest, RunningJobsAreNeverDeleted) {
  control_ = std::make_shared<RigControl>();
  control_->hold_at_frame = 2;
  StartServer();
  v1::Job job;
  std::thread scan([&] {
    auto c = NewClient();
    c->Scan(v1::ScanRequest(), {}, &job).IgnoreError();
  });
  ASSERT_TRUE(control_->WaitUntilHolding());
  v1::RigStatus st;
  ASSERT_TRUE(client_->GetRigStatus(&st).ok());
  ASSERT_FALSE(st.running_job_id().empty());
  v1::DeleteResponse deleted;
  grpc::Status s = client_->DeleteJob(st.running_job_id(), &deleted);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(s.error_message(), "job " + st.running_job_id() + " is JOB_STATE_RUNNING; cancel it before deleting it");
  control_->Release();
  scan.join();
  EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_TRUE(client_->DeleteJob(job.job_id(), &deleted).ok());
}

TEST_F(DataLifecycleServerTest, RetentionSweepDeletesOldestUnpinnedAndKeepsTheNewest) {
  ServerOptions opt;
  opt.listen_address = "127.0.0.1:0";
  opt.data_dir = data_dir_;
  opt.simulation = SimOptions();
  opt.retention.max_bytes = 1;  // over budget whatever is stored: only pins and keep_last hold
  opt.retention.keep_last = 1;
  opt.retention_interval_s = 3600;  // the background sweep runs at start; the test sweeps itself
  auto server = InspectionServer::Start(opt);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  server_ = std::move(*server);
  client_ = NewClient();
  std::vector<v1::Job> jobs;
  for (int i = 0; i < 4; ++i) jobs.push_back(ScanOk("part-" + std::to_string(i)));
  v1::PinJobResponse pin;
  ASSERT_TRUE(client_->PinJob(jobs[0].job_id(), true, &pin).ok());
  EXPECT_TRUE(pin.pinned());
  v1::Job pinned;
  ASSERT_TRUE(client_->GetJob(jobs[0].job_id(), &pinned).ok());
  EXPECT_TRUE(pinned.pinned());
  ASSERT_TRUE(client_->GetJob(jobs[1].job_id(), &pinned).ok());
  EXPECT_FALSE(pinned.pinned());
  int64_t bytes_before = 0, bytes_kept = 0;
  for (const auto& j : jobs) {
    const int64_t b = FolderBytes(ArtifactDir(j.job_id()));
    bytes_before += b;
    if (j.job_id() == jobs[0].job_id() || j.job_id() == jobs[3].job_id()) bytes_kept += b;
  }

  auto report = server_->retention().SweepNow();
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_EQ(report->deleted, (std::vector<std::string>{jobs[1].job_id(), jobs[2].job_id()}));  // oldest first
  EXPECT_EQ(report->bytes_before, bytes_before);
  EXPECT_EQ(report->bytes_after, bytes_kept);
  std::cout << "retention sweep: " << jobs.size() << " scans, " << report->bytes_before << " -> " << report->bytes_after
            << " bytes, deleted " << report->deleted.size() << "\n";
  v1::ListJobsResponse list;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &list).ok());
  ASSERT_EQ(list.jobs_size(), 2);
  EXPECT_EQ(list.jobs(0).job_id(), jobs[3].job_id());
  EXPECT_EQ(list.jobs(1).job_id(), jobs[0].job_id());
  EXPECT_FALSE(list.jobs(0).pinned());
  EXPECT_TRUE(list.jobs(1).pinned());
  EXPECT_TRUE(fs::exists(ArtifactDir(jobs[0].job_id()) / "stack.zip"));
  EXPECT_FALSE(fs::exists(ArtifactDir(jobs[1].job_id())));
  // Unpinned, the oldest goes at the next sweep; the newest stays (keep_last).
  ASSERT_TRUE(client_->PinJob(jobs[0].job_id(), false, &pin).ok());
  report = server_->retention().SweepNow();
  ASSERT_TRUE(report.ok());
  EXPECT_EQ(report->deleted, (std::vector<std::string>{jobs[0].job_id()}));
}

TEST_F(DataLifecycleServerTest, FreeSpaceReserveRefusesNewScansUpFront) {
  ServerOptions opt;
  opt.listen_address = "127.0.0.1:0";
  opt.data_dir = data_dir_;
  opt.simulation = SimOptions();
  opt.min_free_mb = int64_t(1) << 40;  // more than any disk: every new scan and upload is refused
  auto server = InspectionServer::Start(opt);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  server_ = std::move(*server);
  client_ = NewClient();
  v1::Job job;
  grpc::Status s = client_->Scan(v1::ScanRequest(), {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(s.error_message().find("MiB free, below the reserve of 1099511627776 MiB (--min-free-mb)"),
            std::string::npos)
      << s.error_message();
  v1::ListJobsResponse list;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &list).ok());
  EXPECT_EQ(list.jobs_size(), 0);  // refused before any job existed
}

// A data directory on a tmpfs too small for one scan. Needs root (mount): skipped without it,
// a failure in CI (INSPECT_REQUIRE_ALL_TESTS=1).
class DiskFullTest : public DataLifecycleServerTest {
 protected:
  void SetUp() override {
    DataLifecycleServerTest::SetUp();
    if (geteuid() != 0) INSPECT_SKIP_OR_FAIL() << "mounting a small tmpfs needs root";
    if (mount("inspect-test", data_dir_.c_str(), "tmpfs", 0, "size=1536k") != 0) {
      INSPECT_SKIP_OR_FAIL() << "cannot mount a tmpfs: " << std::strerror(errno);
    }
    mounted_ = true;
  }
  void TearDown() override {
    client_.reset();
    server_.reset();
    if (mounted_) umount2(data_dir_.c_str(), MNT_DETACH);
    DataLifecycleServerTest::TearDown();
  }
  bool mounted_ = false;
};

TEST_F(DiskFullTest, ScanThatFillsTheDiskFailsResourceExhaustedLeavingNothingPartial) {
  StartServer();
  v1::Job job;
  grpc::Status s = client_->Scan(v1::ScanRequest(), {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_EQ(s.error_message().rfind("data disk full: ", 0), 0u) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(job.error_code(), int(StatusCode::kResourceExhausted));
  std::cout << "disk full: " << s.error_message() << "\n";
  // Nothing partial: no stored scan, no artifacts, no work folders.
  EXPECT_EQ(CountEntries(data_dir_ / "scans"), 0);
  EXPECT_EQ(CountEntries(data_dir_ / "artifacts"), 0);
  EXPECT_EQ(CountEntries(data_dir_ / "tmp"), 0);
  // The database is consistent: after a restart the job is there, FAILED the same way.
  StopServer();
  StartServer();
  v1::Job stored;
  ASSERT_TRUE(client_->GetJob(job.job_id(), &stored).ok());
  EXPECT_EQ(stored.state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(stored.error_code(), int(StatusCode::kResourceExhausted));
  EXPECT_EQ(stored.error_message(), job.error_message());
}

TEST_F(DiskFullTest, UploadThatFillsTheDiskIsResourceExhaustedAndLeavesNoUpload) {
  StartServer();
  // A valid stack folder on the ordinary disk, larger than the data directory's tmpfs: noise
  // frames barely compress (about 300 KiB each).
  const fs::path stack = UniqueTempDir("bigstack");
  StackManifest m;
  m.pixel_size_um = 1.0;
  cv::RNG rng(5);
  for (int i = 0; i < 8; ++i) {
    cv::Mat noise(480, 640, CV_8UC1);
    rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
    const std::string name = "frame_" + std::to_string(i) + ".png";
    ASSERT_TRUE(cv::imwrite((stack / name).string(), noise));
    m.frames.push_back({name, 10.0 * i, 1000.0, ""});
  }
  ASSERT_TRUE(WriteStackManifest(stack, m).ok());
  v1::Job job;
  grpc::Status s = client_->ReconstructUpload(stack, v1::ReconstructStart(), {}, &job);
  fs::remove_all(stack);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_EQ(s.error_message().rfind("data disk full: cannot write uploaded file 'frame_", 0), 0u) << s.error_message();
  EXPECT_EQ(CountEntries(data_dir_ / "uploads"), 0);  // the partial upload went with the request
  v1::ListJobsResponse list;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &list).ok());
  EXPECT_EQ(list.jobs_size(), 0);
}

}  // namespace
}  // namespace inspection::testing
