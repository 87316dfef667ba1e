// Lateral alignment through the real server: ReconstructionOptions.alignment, the
// focus_breathing calibration step, the DepthSummary figures, and bad input: ESTIMATE on a scan,
// CALIBRATED without the model, alignment with an integral method, frames too small to register
// (INVALID_ARGUMENT naming the field) and frames that do not register (the job fails with
// FAILED_PRECONDITION instead of a smeared map).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "core/io/stack.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

class AlignmentApiTest : public ServerTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o;
    o.specimen = "skew5";
    o.seed = 4;
    o.camera_size = {320, 240};
    o.focus_breathing_percent_per_100um = 2.0;
    o.lateral_drift_x_px_per_100um = 5.0;
    o.lateral_drift_y_px_per_100um = -3.0;
    return o;
  }
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
  }

  v1::ScanRequest ScanWith(v1::FrameAlignment a) {
    v1::ScanRequest r;
    r.mutable_reconstruction()->set_alignment(a);
    return r;
  }

  int JobCount() {
    v1::ListJobsResponse jobs;
    EXPECT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
    return jobs.jobs_size();
  }

  // A stack folder of n frames of size x size: random texture (or flat grey with noise).
  fs::path WriteStack(const std::string& name, int size, int n, bool textured) {
    const fs::path dir = UniqueTempDir(name);
    StackManifest m;
    m.pixel_size_um = 1.0;
    cv::RNG rng(3);
    for (int i = 0; i < n; ++i) {
      cv::Mat f(size, size, CV_8U);
      if (textured) {
        rng.fill(f, cv::RNG::UNIFORM, 0, 256);
      } else {
        rng.fill(f, cv::RNG::NORMAL, 128, 1);
      }
      const std::string file = "frame_" + std::to_string(i) + ".png";
      EXPECT_TRUE(cv::imwrite((dir / file).string(), f));
      m.frames.push_back({file, 10.0 * i, 1000.0, "uniform:128"});
    }
    EXPECT_TRUE(WriteStackManifest(dir, m).ok());
    return dir;
  }
};

TEST_F(AlignmentApiTest, ScanRequestsNameTheAlignmentField) {
  v1::Job job;
  grpc::Status s = client_->Scan(ScanWith(v1::FRAME_ALIGNMENT_ESTIMATE), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("reconstruction.alignment"), std::string::npos) << s.error_message();
  s = client_->Scan(ScanWith(v1::FRAME_ALIGNMENT_CALIBRATED), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("focus_breathing"), std::string::npos) << s.error_message();
  v1::ScanRequest isff = ScanWith(v1::FRAME_ALIGNMENT_CALIBRATED);
  isff.mutable_reconstruction()->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
  s = client_->Scan(isff, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("reconstruction.alignment"), std::string::npos) << s.error_message();
  EXPECT_NE(s.error_message().find("SFF only"), std::string::npos) << s.error_message();
  s = client_->Scan(ScanWith(static_cast<v1::FrameAlignment>(42)), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("reconstruction.alignment"), std::string::npos) << s.error_message();
  EXPECT_EQ(JobCount(), 0);  // refused before a job exists
}

TEST_F(AlignmentApiTest, FramesTooSmallOrFeaturelessFailAnExplicitEstimateButNotTheDefault) {
  const fs::path tiny = WriteStack("tiny", 16, 5, true);
  v1::ReconstructStart start;
  start.mutable_options()->set_alignment(v1::FRAME_ALIGNMENT_ESTIMATE);
  v1::Job job;
  grpc::Status s = client_->ReconstructUpload(tiny, start, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("options.alignment"), std::string::npos) << s.error_message();
  EXPECT_NE(s.error_message().find("32x32"), std::string::npos) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED);
  EXPECT_TRUE(job.result().artifacts().empty());  // no half-written result

  const fs::path flat = WriteStack("flat", 96, 6, false);
  s = client_->ReconstructUpload(flat, start, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("alignment did not converge"), std::string::npos) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED);
  EXPECT_TRUE(job.result().artifacts().empty());

  // The default (UNSPECIFIED) reconstructs such stacks unaligned and says so.
  v1::ReconstructStart plain;
  s = client_->ReconstructUpload(flat, plain, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.result().depth().alignment(), v1::FRAME_ALIGNMENT_NONE);
  EXPECT_DOUBLE_EQ(job.result().depth().alignment_seen_percent(), 100.0);
  s = client_->ReconstructUpload(tiny, plain, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.result().depth().alignment(), v1::FRAME_ALIGNMENT_NONE);
}

TEST_F(AlignmentApiTest, CalibratedScansAndEstimatedReconstructionsReportTheirAlignment) {
  // Before the calibration a scan runs unaligned by default.
  v1::Job before;
  ASSERT_TRUE(client_->Scan(v1::ScanRequest(), nullptr, &before).ok());
  EXPECT_EQ(before.result().depth().alignment(), v1::FRAME_ALIGNMENT_NONE);

  v1::CalibrateRequest req;
  req.add_steps(v1::CALIBRATION_STEP_FOCUS_BREATHING);
  v1::Job cal;
  grpc::Status s = client_->Calibrate(req, nullptr, &cal);
  ASSERT_TRUE(s.ok()) << s.error_message();
  const auto& figures = cal.result().calibration().figures();
  ASSERT_TRUE(figures.count("focus_breathing.scale_change_percent_per_100um"))
      << cal.result().calibration().DebugString();
  EXPECT_NEAR(figures.at("focus_breathing.scale_change_percent_per_100um"), 2.0, 0.15);
  EXPECT_NEAR(figures.at("focus_breathing.shift_x_px_per_100um"), 5.0, 0.3);

  v1::Job scan;
  ASSERT_TRUE(client_->Scan(v1::ScanRequest(), nullptr, &scan).ok());
  const v1::DepthSummary& d = scan.result().depth();
  EXPECT_EQ(d.alignment(), v1::FRAME_ALIGNMENT_CALIBRATED);
  EXPECT_GT(d.alignment_max_scale_change_percent(), 0.1);
  EXPECT_GT(d.alignment_max_shift_px(), 0.2);
  EXPECT_LT(d.alignment_seen_percent(), 100.0);
  EXPECT_GT(d.alignment_seen_percent(), 85.0);
  EXPECT_TRUE(d.has_ground_truth());
  std::printf("calibrated scan: RMSE %.3f um (unaligned before calibration %.3f um)\n", d.rmse_um(),
              before.result().depth().rmse_um());
  EXPECT_LT(d.rmse_um(), before.result().depth().rmse_um());

  // The stored scan, reconstructed: ESTIMATE by default, close to the calibrated result.
  v1::ReconstructStart start;
  start.set_scan_id(scan.result().scan_id());
  v1::Job rec;
  ASSERT_TRUE(client_->ReconstructStored(start, nullptr, &rec).ok());
  EXPECT_EQ(rec.result().depth().alignment(), v1::FRAME_ALIGNMENT_ESTIMATE);
  EXPECT_NEAR(rec.result().depth().alignment_max_scale_change_percent(), d.alignment_max_scale_change_percent(), 0.1);
  EXPECT_LT(rec.result().depth().rmse_um(), 1.1 * d.rmse_um());
}

}  // namespace
}  // namespace inspection::testing
