// Lateral alignment through the real server: ReconstructionOptions.alignment, the
// focus_breathing calibration step, the DepthSummary figures, and bad input: ESTIMATE on a scan,
// CALIBRATED without the model, alignment with an integral method, frames too small to register
// (INVALID_ARGUMENT naming the field) and frames that do not register (the job fails with
// FAILED_PRECONDITION instead of a smeared map).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/io/stack.h"
#include "core/registration/frame_registration.h"
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

  // An imported stack (stack.json names no illumination) of n frames of a smooth random texture:
  // frame i's grid is the scene's scaled by 1 + scale_total * u^1.3 and shifted by (sx, sy) * u,
  // u = i / (n - 1), defocus blur 0.7 .. 2.2 px varying with i, sensor noise. truth[i]: reference
  // (middle) grid -> frame i. out_of_line >= 0: that frame shows an unrelated texture.
  fs::path WriteImportedStack(const std::string& name, int n, double scale_total, double sx, double sy,
                              std::vector<cv::Matx23d>* truth, int out_of_line = -1, double exponent = 1.3) {
    const cv::Size size(320, 240);
    const fs::path dir = UniqueTempDir(name);
    auto texture = [&](unsigned seed) {
      cv::Mat t(size, CV_32F);
      cv::RNG rng(seed);
      rng.fill(t, cv::RNG::NORMAL, 0.0, 1.0);
      cv::GaussianBlur(t, t, cv::Size(0, 0), 2.0);
      cv::Scalar mean, sd;
      cv::meanStdDev(t, mean, sd);
      return cv::Mat(128.0 + (t - mean[0]) * (40.0 / sd[0]));
    };
    const cv::Mat scene = texture(11), other = texture(12);
    const cv::Point2d c((size.width - 1) * 0.5, (size.height - 1) * 0.5);
    std::vector<cv::Matx23d> world;  // frame pixel -> scene position
    for (int i = 0; i < n; ++i) {
      const double u = double(i) / (n - 1);
      SimilarityTransform t;
      t.scale = 1.0 + scale_total * std::pow(u, exponent);
      t.shift_x_px = sx * u;
      t.shift_y_px = sy * u;
      world.push_back(FrameFromReference(t, c));
    }
    const int ref = (n - 1) / 2;
    StackManifest m;
    m.pixel_size_um = 1.0;
    cv::RNG rng(5);
    if (truth) truth->clear();
    for (int i = 0; i < n; ++i) {
      if (truth) truth->push_back(Compose(Invert(world[size_t(i)]), world[size_t(ref)]));
      cv::Mat f;
      cv::warpAffine(i == out_of_line ? other : scene, f, world[size_t(i)], size, cv::INTER_CUBIC | cv::WARP_INVERSE_MAP,
                     cv::BORDER_REFLECT_101);
      cv::GaussianBlur(f, f, cv::Size(0, 0), 0.7 + 1.5 * std::abs(double(i - n / 3)) / n);
      cv::Mat noise(size, CV_32F);
      rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
      cv::Mat out;
      cv::Mat(f + noise).convertTo(out, CV_8U);
      const std::string file = "frame_" + std::to_string(i) + ".png";
      EXPECT_TRUE(cv::imwrite((dir / file).string(), out));
      m.frames.push_back({file, 10.0 * i, 1000.0, ""});
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
  EXPECT_NE(s.error_message().find("could not register 5 of 5 neighbouring frame pairs"), std::string::npos)
      << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED);
  EXPECT_TRUE(job.result().artifacts().empty());

  // The default (UNSPECIFIED) reconstructs such stacks unaligned and says so.
  v1::ReconstructStart plain;
  s = client_->ReconstructUpload(flat, plain, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.result().depth().alignment(), v1::FRAME_ALIGNMENT_NONE);
  EXPECT_DOUBLE_EQ(job.result().depth().alignment_seen_percent(), 100.0);
  EXPECT_FALSE(job.result().depth().alignment_detail().fallback_reason().empty())
      << job.result().depth().alignment_detail().DebugString();
  EXPECT_EQ(job.result().depth().alignment_detail().frames_size(), 0);
  s = client_->ReconstructUpload(tiny, plain, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.result().depth().alignment(), v1::FRAME_ALIGNMENT_NONE);
  EXPECT_FALSE(job.result().depth().alignment_detail().fallback_reason().empty())
      << job.result().depth().alignment_detail().DebugString();
}

TEST_F(AlignmentApiTest, ImportedStacksAreRegisteredAsAChainAndReportEveryFrame) {
  // Moving: 4 % scale change (non-linear in the frame index), 18 / -9 px shift over 11 frames.
  std::vector<cv::Matx23d> truth;
  const fs::path moving = WriteImportedStack("moving", 11, 0.04, 18.0, -9.0, &truth);
  v1::Job job;
  v1::ReconstructStart estimate;
  estimate.mutable_options()->set_alignment(v1::FRAME_ALIGNMENT_ESTIMATE);
  grpc::Status s = client_->ReconstructUpload(moving, estimate, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  const v1::DepthSummary& d = job.result().depth();
  EXPECT_EQ(d.alignment(), v1::FRAME_ALIGNMENT_ESTIMATE);
  const v1::AlignmentDetail& a = d.alignment_detail();
  EXPECT_EQ(a.method(), "chain");
  EXPECT_FALSE(a.still());
  EXPECT_TRUE(a.fallback_reason().empty()) << a.fallback_reason();
  EXPECT_EQ(a.reference_frame(), 5);
  EXPECT_GT(a.still_statistic(), a.still_threshold());
  ASSERT_EQ(a.frames_size(), 11);
  const cv::Point2d c(159.5, 119.5);
  double worst_scale = 0, worst_shift = 0;
  for (int i = 0; i < 11; ++i) {
    const v1::FrameTransform& f = a.frames(i);
    EXPECT_EQ(f.frame(), i);
    ASSERT_EQ(f.affine_size(), 6);
    const SimilarityTransform t = SimilarityOf(truth[size_t(i)], c);
    worst_scale = std::max(worst_scale, std::abs(f.scale() / t.scale - 1));
    worst_shift = std::max(worst_shift, std::hypot(f.shift_x_px() - t.shift_x_px, f.shift_y_px() - t.shift_y_px));
    EXPECT_NEAR(f.affine(2), truth[size_t(i)](0, 2), 0.5) << "frame " << i;
    EXPECT_NEAR(f.affine(5), truth[size_t(i)](1, 2), 0.5) << "frame " << i;
  }
  std::printf("moving imported stack: worst scale error %.4f %%, worst shift error %.3f px\n", 100 * worst_scale,
              worst_shift);
  EXPECT_LT(worst_scale, 0.001);
  EXPECT_LT(worst_shift, 0.5);
  // The summary is max |s - 1| over the frames (proto: a magnitude); the last frame has the largest.
  EXPECT_NEAR(d.alignment_max_scale_change_percent(), 100 * std::abs(SimilarityOf(truth[10], c).scale - 1), 0.1);
  EXPECT_LT(d.alignment_seen_percent(), 100.0);

  // Still: the same scene without motion is decided still, frames used as captured (every
  // pixel seen), and its measured transforms are still reported.
  const fs::path still = WriteImportedStack("still", 11, 0.0, 0.0, 0.0, nullptr);
  s = client_->ReconstructUpload(still, estimate, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.result().depth().alignment(), v1::FRAME_ALIGNMENT_ESTIMATE);
  EXPECT_TRUE(job.result().depth().alignment_detail().still()) << job.result().depth().alignment_detail().DebugString();
  EXPECT_EQ(job.result().depth().alignment_detail().method(), "chain");
  EXPECT_DOUBLE_EQ(job.result().depth().alignment_seen_percent(), 100.0);
  EXPECT_LT(job.result().depth().alignment_detail().max_corner_displacement_px(), 1.0);
  EXPECT_EQ(job.result().depth().alignment_detail().frames_size(), 11);

  // Moving with one frame out of line: the estimate does not fall back silently; the job fails
  // naming the pairs of that frame, and --alignment none is the user's explicit choice.
  const fs::path broken = WriteImportedStack("broken", 11, 0.04, 18.0, -9.0, nullptr, 6);
  s = client_->ReconstructUpload(broken, estimate, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << s.error_message();
  EXPECT_NE(s.error_message().find("options.alignment"), std::string::npos) << s.error_message();
  EXPECT_NE(s.error_message().find("5->6"), std::string::npos) << s.error_message();
  EXPECT_NE(s.error_message().find("6->7"), std::string::npos) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED);
  EXPECT_TRUE(job.result().artifacts().empty());
  v1::ReconstructStart none;
  none.mutable_options()->set_alignment(v1::FRAME_ALIGNMENT_NONE);
  s = client_->ReconstructUpload(broken, none, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.result().depth().alignment(), v1::FRAME_ALIGNMENT_NONE);
  EXPECT_TRUE(job.result().depth().alignment_detail().fallback_reason().empty());
}

// The default (no --alignment) on an imported stack whose motion is not linear in its nominal z,
// as on a focus rail: the linear-in-z model does not fit, and instead of leaving a stack that
// moves unaligned the default registers it as a chain and says why.
TEST_F(AlignmentApiTest, TheDefaultRegistersAStackTheLinearModelDoesNotFitAsAChain) {
  std::vector<cv::Matx23d> truth;
  const fs::path rail = WriteImportedStack("rail", 11, 0.08, 30.0, -12.0, &truth, -1, 3.0);
  v1::Job job;
  grpc::Status s = client_->ReconstructUpload(rail, v1::ReconstructStart(), nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  const v1::DepthSummary& d = job.result().depth();
  EXPECT_EQ(d.alignment(), v1::FRAME_ALIGNMENT_ESTIMATE);
  const v1::AlignmentDetail& a = d.alignment_detail();
  EXPECT_EQ(a.method(), "chain") << a.DebugString();
  EXPECT_FALSE(a.still());
  EXPECT_TRUE(a.fallback_reason().empty()) << a.fallback_reason();
  EXPECT_NE(a.decision().find("linear-in-z focus-breathing model did not fit"), std::string::npos) << a.decision();
  EXPECT_NE(a.decision().find("registered as a chain"), std::string::npos) << a.decision();
  ASSERT_EQ(a.frames_size(), 11);
  const cv::Point2d c(159.5, 119.5);
  for (int i = 0; i < 11; ++i) {
    const SimilarityTransform t = SimilarityOf(truth[size_t(i)], c);
    EXPECT_NEAR(a.frames(i).scale(), t.scale, 0.001 * t.scale) << "frame " << i;
    EXPECT_NEAR(a.frames(i).shift_x_px(), t.shift_x_px, 0.5) << "frame " << i;
    EXPECT_NEAR(a.frames(i).shift_y_px(), t.shift_y_px, 0.5) << "frame " << i;
  }
  // The same stack unmoved: the linear estimate decides it (still), no chain, no decision.
  const fs::path still = WriteImportedStack("rail-still", 11, 0.0, 0.0, 0.0, nullptr);
  s = client_->ReconstructUpload(still, v1::ReconstructStart(), nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(job.result().depth().alignment_detail().method(), "model")
      << job.result().depth().alignment_detail().DebugString();
  EXPECT_TRUE(job.result().depth().alignment_detail().decision().empty());
  EXPECT_DOUBLE_EQ(job.result().depth().alignment_seen_percent(), 100.0);
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
