// Scan requests for the illumination modes of thesis 5: parameters out of range name their
// field, modes whose calibration models are missing fail with FAILED_PRECONDITION naming the
// calibration step before any job is created, and the default mode's depth (figures: sigma,
// bias = mean signed error, RMSE against the simulated truth) has no z offset.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "core/io/depth_export.h"
#include "core/metrology/depth_metrics.h"
#include "server/procedures/scan_procedure.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

class IlluminationRequestTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
  }
};

TEST_F(IlluminationRequestTest, ParametersOutOfRangeNameTheField) {
  struct Case {
    void (*mutate)(v1::ScanRequest&);
    const char* field;
  };
  const Case cases[] = {
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_hdr_exposures(6); },
       "illumination_parameters.hdr_exposures"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_lambda(-0.1); },
       "illumination_parameters.lambda"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_gamma(0.7); },
       "illumination_parameters.gamma"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_psi(1.5); }, "illumination_parameters.psi"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_max_iterations(0); },
       "illumination_parameters.max_iterations"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_target_grey(300); },
       "illumination_parameters.target_grey"},
      {[](v1::ScanRequest& r) { r.set_illumination(static_cast<v1::IlluminationMode>(99)); }, "illumination"},
  };
  for (const Case& c : cases) {
    v1::ScanRequest r;
    c.mutate(r);
    v1::Job job;
    grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field;
    EXPECT_NE(s.error_message().find(c.field), std::string::npos) << c.field << ": " << s.error_message();
  }
}

TEST_F(IlluminationRequestTest, UncalibratedModesNameTheMissingStep) {
  const std::pair<v1::IlluminationMode, const char*> cases[] = {
      {v1::ILLUMINATION_MODE_HDR, "camera_response"},         {v1::ILLUMINATION_MODE_ADAPT, "scatter_matrix"},
      {v1::ILLUMINATION_MODE_ADAPT_IT, "projector_response"}, {v1::ILLUMINATION_MODE_TEXTURE, "psf"},
      {v1::ILLUMINATION_MODE_HF_ADAPT, "geometry"},           {v1::ILLUMINATION_MODE_ADAPTED_HF, "scatter_matrix"},
  };
  for (const auto& [mode, step] : cases) {
    v1::ScanRequest r;
    r.set_illumination(mode);
    v1::Job job;
    grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << v1::IlluminationMode_Name(mode);
    EXPECT_NE(s.error_message().find(step), std::string::npos) << s.error_message();
  }
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 0);
}

class CalibratedIlluminationTest : public ServerTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o = ServerTest::SimOptions();
    o.projector_size = {160, 90};  // small projector: calibration steps stay quick in tests
    return o;
  }
};

// With the models ADAPT needs (but no PSF): ADAPT takes STD's frames + 2 initialisation frames,
// each reported with its grey statistics, and the first frames converge towards the target grey.
// The default is AUTO: its probe finds no saturation on the textured plane and, without the
// texture models, runs STD, says so in the result, and its depth has no offset against the truth
// (docs/illumination.md: |bias| <= max(0.1 um, 0.02 z steps)); TEXTURE names the missing
// psf step.
TEST_F(CalibratedIlluminationTest, AdaptReportsConvergenceAndAutoChoosesWithoutTextureModels) {
  StartServer();
  v1::CalibrateRequest req;
  for (auto step : {v1::CALIBRATION_STEP_CAMERA_RESPONSE, v1::CALIBRATION_STEP_PROJECTOR_RESPONSE,
                    v1::CALIBRATION_STEP_GEOMETRY, v1::CALIBRATION_STEP_SCATTER_MATRIX}) {
    req.add_steps(step);
  }
  v1::Job cal;
  grpc::Status s = client_->Calibrate(req, nullptr, &cal);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(cal.state(), v1::JOB_STATE_SUCCEEDED) << cal.error_message();

  v1::ScanRequest scan;
  scan.set_z_start_um(180);
  scan.set_z_end_um(220);
  scan.set_z_step_um(5);  // 9 stack frames
  scan.set_illumination(v1::ILLUMINATION_MODE_ADAPT);
  std::vector<v1::FrameStatistics> frames;
  std::vector<v1::FrameProgress> progress;
  v1::Job job;
  s = client_->Scan(
      scan,
      [&](const v1::JobEvent& e) {
        if (e.has_frame()) {
          frames.push_back(e.frame().statistics());
          progress.push_back(e.frame());
        }
      },
      &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
  ASSERT_EQ(frames.size(), 9u + 2u);
  // ADAPT: two initialisation captures at the first z, then one stack frame per z.
  for (size_t k = 0; k < progress.size(); ++k) {
    EXPECT_EQ(progress[k].acquisition_index(), int(k));
    EXPECT_EQ(progress[k].stack_frame(), k >= 2) << "capture " << k;
    EXPECT_EQ(progress[k].frame_index(), k < 2 ? 0 : int(k) - 2);
  }
  const double target = IlluminationParams{}.target_grey;
  EXPECT_GT(std::abs(frames[0].mean_grey() - target), std::abs(frames[2].mean_grey() - target) - 1.0);
  EXPECT_NEAR(frames[2].mean_grey(), target, 12.0);

  // The default scan range of the tilted plane (skew5), as a user would start it.
  v1::RigStatus rig;
  ASSERT_TRUE(client_->GetRigStatus(&rig).ok());
  const double step = rig.scan_defaults().z_step_um();
  v1::Job full;
  s = client_->Scan(v1::ScanRequest(), nullptr, &full);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(full.state(), v1::JOB_STATE_SUCCEEDED) << full.error_message();
  const std::filesystem::path out = UniqueTempDir("default_depth");
  std::vector<std::filesystem::path> written;
  ASSERT_TRUE(client_->DownloadResults(full, out, false, &written).ok());
  auto depth = ReadDepthTiff(out / "depth.tiff");
  auto truth = ReadDepthTiff(out / "ground_truth_depth.tiff");
  ASSERT_TRUE(depth.ok() && truth.ok());
  const DepthErrorStats e = CompareDepth(*depth, *truth, 2.0 * step, /*border_px=*/9);
  std::printf("skew5, default mode (%s): sigma %.3f um, bias %+.3f um, RMSE %.3f um, valid %.1f %%, %d frames\n",
              full.result().depth().illumination_decision().c_str(), e.stddev_error_um, e.mean_error_um, e.rmse_um,
              e.valid_percent, full.result().depth().frame_count());
  EXPECT_EQ(full.result().depth().illumination(), "STD");
  EXPECT_EQ(full.result().depth().illumination_decision().rfind(
                "AUTO -> STD: no saturation and no texture models in the calibration (probe: ", 0),
            0u)
      << full.result().depth().illumination_decision();
  EXPECT_GT(e.valid_percent, 95.0);
  EXPECT_LE(std::abs(e.mean_error_um), std::max(0.1, 0.02 * step));
  EXPECT_LT(e.rmse_um, 0.1 * step);
  std::filesystem::remove_all(out);

  v1::ScanRequest tex;
  tex.set_illumination(v1::ILLUMINATION_MODE_TEXTURE);
  s = client_->Scan(tex, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("psf"), std::string::npos) << s.error_message();
}

}  // namespace
}  // namespace inspection::testing
