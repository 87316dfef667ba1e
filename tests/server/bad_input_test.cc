// Bad input gets a clear status naming the field or frame, and loses nothing.
#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>

#include "core/stack.h"
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
