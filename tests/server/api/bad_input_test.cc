// Bad input gets a clear status naming the field or frame, and loses nothing.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/io/stack.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

class BadInputTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    stack_ = UniqueTempDir("stack");
    StartServer();
  }
  void TearDown() override {
    fs::remove_all(stack_);
    ServerTest::TearDown();
  }
  // A valid 4-frame stack of textured frames.
  StackManifest WriteStack(int n = 4) {
    StackManifest m;
    m.pixel_size_um = 0.74;
    cv::Mat img(48, 64, CV_8UC1);
    cv::randu(img, 0, 255);
    for (int i = 0; i < n; ++i) {
      const std::string name = "f" + std::to_string(i) + ".png";
      cv::imwrite((stack_ / name).string(), img);
      m.frames.push_back({name, 5.0 * i, 1000, "uniform:128"});
    }
    EXPECT_TRUE(WriteStackManifest(stack_, m).ok());
    return m;
  }
  grpc::Status Upload() {
    v1::Job job;
    return client_->ReconstructUpload(stack_, v1::ReconstructStart(), nullptr, &job);
  }
  void ExpectNothingLeft() {
    EXPECT_TRUE(fs::is_empty(data_dir_ / "uploads"));
    v1::ListJobsResponse jobs;
    ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
    EXPECT_EQ(jobs.jobs_size(), 0) << "bad input must not become a job";
  }
  fs::path stack_;
};

TEST_F(BadInputTest, UploadedStackReconstructs) {
  WriteStack();
  v1::Job job;
  grpc::Status s = client_->ReconstructUpload(stack_, v1::ReconstructStart(), nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(job.result().depth().width(), 64);
  EXPECT_TRUE(fs::is_empty(data_dir_ / "uploads"));  // the upload is removed after the job
}

TEST_F(BadInputTest, MissingStackJsonIsInvalidArgumentNamingIt) {
  WriteStack();
  // Upload the frames with a hand-made stream that leaves stack.json out.
  auto stub = v1::InspectionService::NewStub(client_->channel());
  grpc::ClientContext ctx;
  auto stream = stub->Reconstruct(&ctx);
  v1::ReconstructRequest start;
  start.mutable_start()->mutable_upload()->set_file_count(1);
  ASSERT_TRUE(stream->Write(start));
  v1::ReconstructRequest chunk;
  chunk.mutable_file_chunk()->set_path("f0.png");
  chunk.mutable_file_chunk()->set_data("x");
  chunk.mutable_file_chunk()->set_last(true);
  ASSERT_TRUE(stream->Write(chunk));
  stream->WritesDone();
  v1::JobEvent e;
  EXPECT_FALSE(stream->Read(&e));
  grpc::Status s = stream->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("stack.json is missing"), std::string::npos) << s.error_message();
  ExpectNothingLeft();
}

TEST_F(BadInputTest, FramesOfDifferentSizesNameTheFrame) {
  StackManifest m = WriteStack();
  cv::imwrite((stack_ / m.frames[2].file).string(), cv::Mat(10, 10, CV_8UC1, cv::Scalar(3)));
  grpc::Status s = Upload();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("frame 2 (f2.png): size 10x10 differs"), std::string::npos) << s.error_message();
  ExpectNothingLeft();
}

TEST_F(BadInputTest, NonMonotonicZNamesTheFrame) {
  StackManifest m = WriteStack();
  m.frames[3].z_um = 1.0;
  // WriteStackManifest does not validate; the server must.
  ASSERT_TRUE(WriteStackManifest(stack_, m).ok());
  grpc::Status s = Upload();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("frames[3].z_um"), std::string::npos) << s.error_message();
  ExpectNothingLeft();
}

TEST_F(BadInputTest, UnreadableFrameNamesTheFrame) {
  StackManifest m = WriteStack();
  std::ofstream(stack_ / m.frames[1].file) << "garbage";
  grpc::Status s = Upload();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("frame 1 (f1.png)"), std::string::npos) << s.error_message();
  ExpectNothingLeft();
}

// frames decode on a pool while the upload arrives. A bad frame in the middle (and a
// later frame of another size, which may finish decoding first) gets the sequential path's
// INVALID_ARGUMENT naming the first bad frame, and leaves no job, upload or result file.
TEST_F(BadInputTest, BadFrameMidUploadOfParallelDecodeNamesItLikeTheSequentialPath) {
  StackManifest m = WriteStack(16);
  std::ofstream(stack_ / m.frames[7].file, std::ios::binary | std::ios::trunc) << "garbage";
  cv::imwrite((stack_ / m.frames[11].file).string(), cv::Mat(10, 10, CV_8UC1, cv::Scalar(3)));
  const grpc::Status parallel = Upload();
  EXPECT_EQ(parallel.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(parallel.error_message().rfind("frame 7 (f7.png): cannot decode", 0), 0u) << parallel.error_message();
  ExpectNothingLeft();
  auto empty_or_missing = [](const fs::path& p) { return !fs::exists(p) || fs::is_empty(p); };
  EXPECT_TRUE(empty_or_missing(data_dir_ / "artifacts"));
  EXPECT_TRUE(empty_or_missing(data_dir_ / "tmp"));

  StopServer();
  pipeline_.sequential = true;
  StartServer();
  const grpc::Status sequential = Upload();
  EXPECT_EQ(sequential.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(sequential.error_message(), parallel.error_message());
  ExpectNothingLeft();
}

// The same upload through the parallel pipeline and the sequential path: the downloaded depth,
// confidence and all-in-focus images agree bit for bit.
TEST_F(BadInputTest, ParallelAndSequentialPipelinesGiveBitIdenticalResults) {
  StackManifest m;
  m.pixel_size_um = 0.74;
  cv::Mat texture(60, 80, CV_8UC1);
  cv::randu(texture, 0, 255);
  for (int i = 0; i < 12; ++i) {
    // Sharpest at frame 4 on the left, frame 8 on the right.
    cv::Mat frame;
    const double left = 0.4 + 0.7 * std::abs(i - 4), right = 0.4 + 0.7 * std::abs(i - 8);
    cv::Mat l, r;
    cv::GaussianBlur(texture, l, cv::Size(0, 0), left);
    cv::GaussianBlur(texture, r, cv::Size(0, 0), right);
    cv::hconcat(l.colRange(0, 40), r.colRange(40, 80), frame);
    const std::string name = "f" + std::to_string(i) + ".png";
    cv::imwrite((stack_ / name).string(), frame);
    m.frames.push_back({name, 2.0 * i, 1000, "uniform:128"});
  }
  ASSERT_TRUE(WriteStackManifest(stack_, m).ok());
  std::vector<std::vector<cv::Mat>> results;
  for (bool sequential : {false, true}) {
    StopServer();
    pipeline_.sequential = sequential;
    StartServer();
    v1::Job job;
    grpc::Status s = client_->ReconstructUpload(stack_, v1::ReconstructStart(), nullptr, &job);
    ASSERT_TRUE(s.ok()) << s.error_message();
    const fs::path out = UniqueTempDir(sequential ? "seq" : "par");
    std::vector<fs::path> written;
    ASSERT_TRUE(client_->DownloadResults(job, out, false, &written).ok());
    std::vector<cv::Mat> images;
    for (const char* f : {"depth.tiff", "confidence.tiff", "all_in_focus.png"}) {
      images.push_back(cv::imread((out / f).string(), cv::IMREAD_UNCHANGED));
      ASSERT_FALSE(images.back().empty()) << f;
    }
    EXPECT_GT(job.result().depth().valid_percent(), 50.0);
    results.push_back(images);
    fs::remove_all(out);
  }
  for (size_t k = 0; k < 3; ++k) {
    const cv::Mat& a = results[0][k];
    const cv::Mat& b = results[1][k];
    ASSERT_EQ(a.size(), b.size());
    ASSERT_EQ(a.type(), b.type());
    EXPECT_EQ(0, std::memcmp(a.data, b.data, a.total() * a.elemSize())) << "image " << k;
  }
}

TEST_F(BadInputTest, UploadPathEscapingTheFolderIsRefused) {
  auto stub = v1::InspectionService::NewStub(client_->channel());
  grpc::ClientContext ctx;
  auto stream = stub->Reconstruct(&ctx);
  v1::ReconstructRequest start;
  start.mutable_start()->mutable_upload();
  ASSERT_TRUE(stream->Write(start));
  v1::ReconstructRequest chunk;
  chunk.mutable_file_chunk()->set_path("../../etc/evil");
  chunk.mutable_file_chunk()->set_data("x");
  stream->Write(chunk);
  stream->WritesDone();
  grpc::Status s = stream->Finish();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("file_chunk.path"), std::string::npos) << s.error_message();
  ExpectNothingLeft();
}

TEST_F(BadInputTest, UnknownIdsAreNotFound) {
  v1::Job job;
  grpc::Status s = client_->GetJob("scan-doesnotexist", &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("job_id 'scan-doesnotexist'"), std::string::npos);
  EXPECT_EQ(client_->Watch("scan-doesnotexist", nullptr, &job).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(client_->CancelJob("scan-doesnotexist", &job).error_code(), grpc::StatusCode::NOT_FOUND);
  std::string data, sha;
  int64_t total;
  s = client_->DownloadRange("art-nope", 0, 0, &data, &sha, &total);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("artifact_id"), std::string::npos);
  v1::ReconstructStart start;
  start.set_scan_id("scan-nope");
  s = client_->ReconstructStored(start, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("scan_id 'scan-nope'"), std::string::npos);
  EXPECT_EQ(client_->GetJob("", &job).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(BadInputTest, BadScanRequestsNameTheField) {
  struct Case {
    std::function<void(v1::ScanRequest&)> mutate;
    const char* field;
  };
  const std::vector<Case> cases = {
      {[](v1::ScanRequest& r) {
         r.set_z_start_um(0);
         r.set_z_end_um(50);
         r.set_z_step_um(-1);
       },
       "z_step_um"},
      {[](v1::ScanRequest& r) {
         r.set_z_start_um(0);
         r.set_z_end_um(5);
         r.set_z_step_um(5);
       },
       "fewer than 3 frames"},
      {[](v1::ScanRequest& r) {
         r.set_z_start_um(-1e9);
         r.set_z_end_um(0);
         r.set_z_step_um(5);
       },
       "z_start_um"},
      {[](v1::ScanRequest& r) { r.mutable_reconstruction()->set_window_px(4); }, "window_px"},
      {[](v1::ScanRequest& r) { r.mutable_reconstruction()->set_window_px(33); }, "window_px"},
      {[](v1::ScanRequest& r) { r.set_exposure_us(-3); }, "exposure_us"},
      {[](v1::ScanRequest& r) { r.mutable_reconstruction()->add_extra_exports(v1::ARTIFACT_KIND_STACK_ZIP); },
       "reconstruction.extra_exports[0]"},
  };
  for (const Case& c : cases) {
    v1::ScanRequest r;
    c.mutate(r);
    v1::Job job;
    grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field;
    EXPECT_NE(s.error_message().find(c.field), std::string::npos) << c.field << ": " << s.error_message();
  }
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 0);
}

TEST_F(BadInputTest, DownloadRequestFieldsAreChecked) {
  std::string data, sha;
  int64_t total;
  grpc::Status s = client_->DownloadRange("", 0, 0, &data, &sha, &total);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("artifact_id"), std::string::npos);
  s = client_->DownloadRange("art-x", -5, 0, &data, &sha, &total);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("offset"), std::string::npos);
}

}  // namespace
}  // namespace inspection::testing
