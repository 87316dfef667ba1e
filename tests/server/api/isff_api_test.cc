// Integral SFF through the real server and inspectctl (thesis 5.4, 6.4; ReconstructionOptions.method):
// after the integral_psf calibration step a Scan with ISFF measures the simulated SKEW5 within
// the procedures test's bound (sigma within 10 % of STD's on the same frames, |bias| < 0.1 um),
// ISFF-FAST searches fewer frames for the same depth, ISFF-GT runs on the simulated rig; what a
// method lacks is FAILED_PRECONDITION naming it (the calibration step, the simulated rig) and a
// bad threshold INVALID_ARGUMENT naming the field, before any job exists.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>

#include "core/io/depth_export.h"
#include "core/metrology/depth_metrics.h"
#include "tests/client_cli/cli_fixture.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

constexpr int kBorderPx = 7;  // the 7 x 7 windows see the image border there (isff_rig_test.cc)

// IsffRig(): tests/server/server_fixture.h.

v1::ScanRequest ScanWith(v1::ReconstructionMethod method) {
  v1::ScanRequest r;
  r.mutable_reconstruction()->set_method(method);
  return r;
}

class IsffApiTest : public ServerTest {
 protected:
  SimulatedRigOptions SimOptions() override { return IsffRig(); }
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
  }

  void CalibrateIntegralPsf() {
    v1::CalibrateRequest req;
    req.add_steps(v1::CALIBRATION_STEP_INTEGRAL_PSF);
    v1::Job cal;
    grpc::Status s = client_->Calibrate(req, nullptr, &cal);
    ASSERT_TRUE(s.ok()) << s.error_message();
    ASSERT_EQ(cal.state(), v1::JOB_STATE_SUCCEEDED) << cal.error_message();
  }

  // The job's depth map against the simulated ground truth, as a user downloads them.
  DepthErrorStats ErrorOf(const v1::Job& job) {
    const fs::path out = UniqueTempDir("isff_" + job.job_id());
    std::vector<fs::path> written;
    EXPECT_TRUE(client_->DownloadResults(job, out, false, &written).ok());
    auto depth = ReadDepthTiff(out / "depth.tiff");
    auto truth = ReadDepthTiff(out / "ground_truth_depth.tiff");
    // A reconstruction of a stored scan: the scan job's ground-truth artifact.
    if (!truth.ok())
      truth = ReadDepthTiff(data_dir_ / "artifacts" / job.result().scan_id() / "ground_truth_depth.tiff");
    EXPECT_TRUE(depth.ok() && truth.ok());
    for (const char* f : {"depth.tiff", "confidence.tiff", "all_in_focus.png", "depth_preview.png"}) {
      EXPECT_TRUE(fs::exists(out / f)) << f;
    }
    DepthErrorStats e;
    if (depth.ok() && truth.ok()) e = CompareDepth(*depth, *truth, 10.0, kBorderPx);
    fs::remove_all(out);
    return e;
  }

  v1::Job Scan(const v1::ScanRequest& r) {
    v1::Job job;
    grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
    return job;
  }

  v1::Job ReconstructScan(const std::string& scan_id, v1::ReconstructionMethod method) {
    v1::ReconstructStart start;
    start.set_scan_id(scan_id);
    start.mutable_options()->set_method(method);
    v1::Job job;
    grpc::Status s = client_->ReconstructStored(start, nullptr, &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
    return job;
  }

  int JobCount() {
    v1::ListJobsResponse jobs;
    EXPECT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
    return jobs.jobs_size();
  }
};

void Print(const char* what, const DepthErrorStats& e, const v1::DepthSummary& d) {
  std::printf("%-22s sigma %.3f um, bias %+.3f um, RMSE %.3f um, valid %.1f %%, frames searched %.3f, noise %.3f\n",
              what, e.stddev_error_um, e.mean_error_um, e.rmse_um, e.valid_percent, d.frames_searched_fraction(),
              d.frame_noise_sigma());
}

TEST_F(IsffApiTest, IsffScanMeetsTheStdBoundAndFastSearchesFewerFrames) {
  CalibrateIntegralPsf();
  v1::ScanRequest isff_request = ScanWith(v1::RECONSTRUCTION_METHOD_ISFF);
  const v1::Job isff = Scan(isff_request);
  ASSERT_EQ(isff.state(), v1::JOB_STATE_SUCCEEDED);
  const v1::DepthSummary& d = isff.result().depth();
  EXPECT_EQ(d.method(), v1::RECONSTRUCTION_METHOD_ISFF);
  EXPECT_DOUBLE_EQ(d.frames_searched_fraction(), 1.0);  // the global maximum search
  // The rig's read noise is 0.8 grey; shot noise adds to it at mid grey.
  EXPECT_GT(d.frame_noise_sigma(), 0.8);
  EXPECT_LT(d.frame_noise_sigma(), 3.0);
  EXPECT_TRUE(d.has_ground_truth());

  // STD (SFF, Tenengrad 7 x 7) on the very same frames: the stored scan reconstructed.
  const std::string scan_id = isff.result().scan_id();
  const v1::Job sff = ReconstructScan(scan_id, v1::RECONSTRUCTION_METHOD_UNSPECIFIED);
  EXPECT_EQ(sff.result().depth().method(), v1::RECONSTRUCTION_METHOD_SFF);
  const DepthErrorStats e_isff = ErrorOf(isff), e_std = ErrorOf(sff);
  Print("skew5 ISFF (scan)", e_isff, d);
  Print("skew5 STD (same stack)", e_std, sff.result().depth());
  EXPECT_LE(e_isff.stddev_error_um, 1.10 * e_std.stddev_error_um);
  EXPECT_LT(std::abs(e_isff.mean_error_um), 0.1);  // a fiftieth of the 5 um step
  EXPECT_GT(e_isff.valid_percent, 99.0);
  EXPECT_EQ(e_isff.outlier_percent, 0.0);
  EXPECT_LT(e_isff.stddev_error_um, 0.5);  // absolute: a tenth of the step

  // Reconstruct runs the same ISFF over the stored stack: the same depth map.
  const v1::Job again = ReconstructScan(scan_id, v1::RECONSTRUCTION_METHOD_ISFF);
  EXPECT_EQ(again.result().depth().method(), v1::RECONSTRUCTION_METHOD_ISFF);
  EXPECT_NEAR(again.result().depth().rmse_um(), d.rmse_um(), 1e-6);
  EXPECT_NEAR(again.result().depth().frame_noise_sigma(), d.frame_noise_sigma(), 1e-9);

  // ISFF-FAST on the same stack: the default threshold 0.9 recorded, fewer frames searched, the
  // same accuracy (procedures test: within 5 % of ISFF's sigma).
  const v1::Job fast = ReconstructScan(scan_id, v1::RECONSTRUCTION_METHOD_ISFF_FAST);
  const v1::DepthSummary& df = fast.result().depth();
  EXPECT_EQ(df.method(), v1::RECONSTRUCTION_METHOD_ISFF_FAST);
  EXPECT_DOUBLE_EQ(df.isff_fast_threshold(), 0.9);
  EXPECT_LT(df.frames_searched_fraction(), 0.8);
  EXPECT_GT(df.frames_searched_fraction(), 0.2);
  const DepthErrorStats e_fast = ErrorOf(fast);
  Print("skew5 ISFF-FAST", e_fast, df);
  EXPECT_LE(e_fast.stddev_error_um, 1.05 * e_isff.stddev_error_um);
  EXPECT_LT(std::abs(e_fast.mean_error_um), 0.1);
  EXPECT_GT(e_fast.valid_percent, 99.0);
}

TEST_F(IsffApiTest, FastScanAndGroundTruthScanOnTheSimulatedRig) {
  CalibrateIntegralPsf();
  v1::ScanRequest fast_request = ScanWith(v1::RECONSTRUCTION_METHOD_ISFF_FAST);
  fast_request.mutable_reconstruction()->set_isff_fast_threshold(0.8);
  const v1::Job fast = Scan(fast_request);
  ASSERT_EQ(fast.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(fast.result().depth().method(), v1::RECONSTRUCTION_METHOD_ISFF_FAST);
  EXPECT_DOUBLE_EQ(fast.result().depth().isff_fast_threshold(), 0.8);
  EXPECT_LT(fast.result().depth().frames_searched_fraction(), 0.8);
  const DepthErrorStats e_fast = ErrorOf(fast);

  // ISFF-GT needs no calibration, only the simulated rig's ground-truth texture.
  const v1::Job gt = Scan(ScanWith(v1::RECONSTRUCTION_METHOD_ISFF_GT));
  ASSERT_EQ(gt.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(gt.result().depth().method(), v1::RECONSTRUCTION_METHOD_ISFF_GT);
  EXPECT_DOUBLE_EQ(gt.result().depth().frames_searched_fraction(), 1.0);
  const DepthErrorStats e_gt = ErrorOf(gt);
  const v1::Job std_on_gt = ReconstructScan(gt.result().scan_id(), v1::RECONSTRUCTION_METHOD_SFF);
  const DepthErrorStats e_std = ErrorOf(std_on_gt);
  Print("skew5 ISFF-FAST 0.8", e_fast, fast.result().depth());
  Print("skew5 ISFF-GT (scan)", e_gt, gt.result().depth());
  Print("skew5 STD (GT's stack)", e_std, std_on_gt.result().depth());
  EXPECT_LE(e_gt.stddev_error_um, 1.10 * e_std.stddev_error_um);
  EXPECT_LT(std::abs(e_gt.mean_error_um), 0.1);
  EXPECT_GT(e_gt.valid_percent, 99.0);
  // Another scan of the same specimen: ISFF-FAST at 0.8 stays near STD's error.
  EXPECT_LE(e_fast.stddev_error_um, 1.25 * e_std.stddev_error_um);
  EXPECT_LT(std::abs(e_fast.mean_error_um), 0.1);
  EXPECT_GT(e_fast.valid_percent, 99.0);
}

TEST_F(IsffApiTest, WithoutTheIntegralPsfStepIsffFailsNamingIt) {
  for (auto method : {v1::RECONSTRUCTION_METHOD_ISFF, v1::RECONSTRUCTION_METHOD_ISFF_FAST}) {
    v1::Job job;
    grpc::Status s = client_->Scan(ScanWith(method), nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << v1::ReconstructionMethod_Name(method);
    EXPECT_NE(s.error_message().find("integral_psf"), std::string::npos) << s.error_message();
  }
  EXPECT_EQ(JobCount(), 0);  // refused before a job exists

  // Reconstruct of a stored STD scan: the job fails with the step's name.
  const v1::Job std_scan = Scan(v1::ScanRequest());
  v1::ReconstructStart start;
  start.set_scan_id(std_scan.result().scan_id());
  start.mutable_options()->set_method(v1::RECONSTRUCTION_METHOD_ISFF);
  v1::Job rec;
  grpc::Status s = client_->ReconstructStored(start, nullptr, &rec);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("integral_psf"), std::string::npos) << s.error_message();
  EXPECT_EQ(rec.state(), v1::JOB_STATE_FAILED);
  EXPECT_TRUE(rec.result().artifacts().empty());
}

TEST_F(IsffApiTest, BadThresholdAndConflictingOptionsNameTheField) {
  const double bad[] = {0.0, -0.5, 1.01, std::numeric_limits<double>::quiet_NaN()};
  for (double t : bad) {
    v1::ScanRequest r = ScanWith(v1::RECONSTRUCTION_METHOD_ISFF_FAST);
    r.mutable_reconstruction()->set_isff_fast_threshold(t);
    v1::Job job;
    grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << t;
    EXPECT_NE(s.error_message().find("reconstruction.isff_fast_threshold must be in (0, 1]"), std::string::npos)
        << s.error_message();
  }
  struct Case {
    v1::ScanRequest request;
    const char* field;
  };
  Case threshold_without_fast{ScanWith(v1::RECONSTRUCTION_METHOD_ISFF), "reconstruction.isff_fast_threshold"};
  threshold_without_fast.request.mutable_reconstruction()->set_isff_fast_threshold(0.9);
  Case focus_measure{ScanWith(v1::RECONSTRUCTION_METHOD_ISFF_GT), "reconstruction.focus_measure"};
  focus_measure.request.mutable_reconstruction()->set_focus_measure(v1::FOCUS_MEASURE_TENENGRAD);
  Case illumination{ScanWith(v1::RECONSTRUCTION_METHOD_ISFF_GT), "illumination"};
  illumination.request.set_illumination(v1::ILLUMINATION_MODE_TEXTURE);
  Case unknown{ScanWith(static_cast<v1::ReconstructionMethod>(42)), "reconstruction.method"};
  Case invariant{ScanWith(v1::RECONSTRUCTION_METHOD_ISFF), "reconstruction.illumination_invariant applies to SFF only"};
  invariant.request.mutable_reconstruction()->set_illumination_invariant(true);
  for (const Case& c : {threshold_without_fast, focus_measure, illumination, unknown, invariant}) {
    v1::Job job;
    grpc::Status s = client_->Scan(c.request, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field;
    EXPECT_NE(s.error_message().find(c.field), std::string::npos) << c.field << ": " << s.error_message();
  }
  // Reconstruct names its own field path, before anything is uploaded or read.
  v1::ReconstructStart start;
  start.set_scan_id("no-such-scan");
  start.mutable_options()->set_method(v1::RECONSTRUCTION_METHOD_ISFF_FAST);
  start.mutable_options()->set_isff_fast_threshold(2.0);
  v1::Job rec;
  grpc::Status s = client_->ReconstructStored(start, nullptr, &rec);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("options.isff_fast_threshold"), std::string::npos) << s.error_message();
  EXPECT_EQ(JobCount(), 0);
}

TEST_F(IsffApiTest, GroundTruthMethodIsRefusedForStoredAndUploadedStacks) {
  const v1::Job std_scan = Scan(v1::ScanRequest());
  const fs::path stored = ExtractStoredStack(data_dir_, std_scan.result().scan_id(), UniqueTempDir("isff_gt_stack"));
  ASSERT_TRUE(fs::exists(stored / "stack.json"));
  v1::ReconstructStart start;
  start.mutable_options()->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
  v1::Job rec;
  grpc::Status s = client_->ReconstructUpload(stored, start, nullptr, &rec);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("ISFF-GT"), std::string::npos) << s.error_message();
  EXPECT_NE(s.error_message().find("simulated rig"), std::string::npos) << s.error_message();
  start.set_scan_id(std_scan.result().scan_id());
  s = client_->ReconstructStored(start, nullptr, &rec);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(JobCount(), 1);  // only the scan
}

// The reconstruct-only pool (`inspectd --no-rig`): ISFF takes the IPSF of the calibration active
// in its data directory, and without one fails naming the step.
TEST_F(IsffApiTest, NoRigServerUsesTheStoredCalibrationOrNamesTheMissingStep) {
  CalibrateIntegralPsf();
  const v1::Job isff = Scan(ScanWith(v1::RECONSTRUCTION_METHOD_ISFF));
  const std::string scan_id = isff.result().scan_id();
  const fs::path stack = ExtractStoredStack(data_dir_, scan_id, UniqueTempDir("isff_stack"));
  StopServer();

  auto start_no_rig = [&](const fs::path& data_dir) {
    ServerOptions opt;
    opt.listen_address = "127.0.0.1:0";
    opt.data_dir = data_dir;
    opt.simulation = SimOptions();
    opt.no_rig = true;
    auto server = InspectionServer::Start(opt, nullptr);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
    client_ = NewClient();
  };
  start_no_rig(data_dir_);  // the rig server's data directory: its calibration is active
  const v1::Job again = ReconstructScan(scan_id, v1::RECONSTRUCTION_METHOD_ISFF);
  EXPECT_NEAR(again.result().depth().rmse_um(), isff.result().depth().rmse_um(), 1e-6);
  StopServer();

  const fs::path empty = UniqueTempDir("isff_no_rig");
  start_no_rig(empty);
  v1::ReconstructStart start;
  start.mutable_options()->set_method(v1::RECONSTRUCTION_METHOD_ISFF);
  v1::Job rec;
  grpc::Status s = client_->ReconstructUpload(stack, start, nullptr, &rec);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("integral_psf"), std::string::npos) << s.error_message();
  StopServer();
  fs::remove_all(empty);
  fs::remove_all(stack);
}

// inspectctl: --method and --isff-fast-threshold reach the server; bad values exit with one line.
class IsffCliTest : public CliTest {
 protected:
  SimulatedRigOptions SimOptions() override { return IsffRig(); }
};

TEST_F(IsffCliTest, MethodFlagsReachTheServerAndBadValuesExitWithOneLine) {
  StartServer();
  EXPECT_EQ(Run({"scan", "--out", (work_ / "x").string(), "--method", "isff-turbo"}).exit_code, 2);
  CliResult r =
      Run({"scan", "--out", (work_ / "bad").string(), "--method", "isff-fast", "--isff-fast-threshold", "1.5"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("inspectctl: INVALID_ARGUMENT: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("reconstruction.isff_fast_threshold"), std::string::npos) << r.err;
  r = Run({"scan", "--out", (work_ / "bad").string(), "--method", "ISFF"});  // case-insensitive; uncalibrated
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.err.rfind("inspectctl: FAILED_PRECONDITION: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("integral_psf"), std::string::npos) << r.err;

  const json result = JsonScan("gt", {"--method", "isff-gt"});
  EXPECT_EQ(result["job"]["result"]["depth"]["method"], "RECONSTRUCTION_METHOD_ISFF_GT") << result.dump();
  EXPECT_TRUE(fs::exists(work_ / "gt" / "depth.tiff"));
  const std::string scan_id = result["job"]["result"]["scan_id"];
  r = Run({"reconstruct", "--scan-id", scan_id, "--out", (work_ / "rec").string(), "--method", "isff-gt"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.err.rfind("inspectctl: FAILED_PRECONDITION: ", 0), 0u) << r.err;
}

}  // namespace
}  // namespace inspection::testing
