// Request mapping without a server: requests become the work and options the engine and the
// procedures get, every bad field is INVALID_ARGUMENT naming it, and the default illumination
// is AUTO when the active calibration allows TEXTURE or ADAPT, else STD (thesis 5.3, 6.2.3,
// eq. 5.15).
#include "server/api/request_mapping.h"

#include <gtest/gtest.h>

#include <string>

namespace inspection {
namespace {

// Travel 0..400 um; never moves (mapping only reads the limits).
class TravelOnlyStage final : public Stage {
 public:
  DeviceInfo info() const override { return {"stage", "test", "", "", true, ""}; }
  double min_z_um() const override { return 0.0; }
  double max_z_um() const override { return 400.0; }
  Status Home() override { return Status::Ok(); }
  Status MoveTo(double) override { return Status::Ok(); }
  StatusOr<double> position_um() override { return 0.0; }
};

void ExpectInvalidNaming(const Status& s, const std::string& field) {
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << field << ": " << s.ToString();
  EXPECT_NE(s.message().find(field), std::string::npos) << field << ": " << s.message();
}

// A bundle holding the models of `steps` (placeholders: the mapping only asks which models are
// present), with sigma_p 3 px and 2 camera px per projector px: the checkerboard of eq. 5.15
// then needs t/2 = 8 px, which fits window 7 (8 < 7 + 2) but not window 5.
CalibrationBundle BundleWith(std::initializer_list<CalibrationStep> steps) {
  CalibrationBundle b;
  for (CalibrationStep s : steps) {
    switch (s) {
      case CalibrationStep::kCameraResponse:
        b.camera_response.emplace();
        break;
      case CalibrationStep::kProjectorResponse:
        b.projector_response.emplace();
        break;
      case CalibrationStep::kGeometry:
        b.geometry.emplace();
        b.geometry->camera_px_per_projector_px = 2.0;
        break;
      case CalibrationStep::kPsf:
        b.psf.emplace();
        b.psf->influence_radius_px = 3.0;
        break;
      case CalibrationStep::kScatterMatrix:
        b.scatter.emplace();
        break;
      case CalibrationStep::kIntegralPsf:
        b.integral_psf.emplace();
        break;
      case CalibrationStep::kZLinearity:
        b.z_linearity = ZLinearity::Uncharacterised();
        break;
      case CalibrationStep::kFocusBreathing:
        b.focus_breathing.emplace();
        break;
    }
  }
  return b;
}

const std::initializer_list<CalibrationStep> kAdaptSteps = {
    CalibrationStep::kCameraResponse, CalibrationStep::kProjectorResponse, CalibrationStep::kScatterMatrix};
const std::initializer_list<CalibrationStep> kHfAdaptSteps = {
    CalibrationStep::kCameraResponse, CalibrationStep::kProjectorResponse, CalibrationStep::kScatterMatrix,
    CalibrationStep::kGeometry, CalibrationStep::kPsf};

class ScanMappingTest : public ::testing::Test {
 protected:
  ScanContext Context(const CalibrationBundle* calibration = nullptr) {
    ScanContext c;
    c.defaults.z_start_um = 100.0;
    c.defaults.z_end_um = 200.0;
    c.defaults.z_step_um = 10.0;
    c.defaults.exposure_us = 5000.0;
    c.stage = &stage_;
    c.calibration = calibration;
    return c;
  }
  TravelOnlyStage stage_;
};

TEST_F(ScanMappingTest, EmptyRequestTakesTheRigDefaults) {
  auto work = MapScanRequest(v1::ScanRequest(), Context());
  ASSERT_TRUE(work.ok()) << work.status().ToString();
  const ScanPlan& plan = work->plan;
  ASSERT_EQ(plan.z_um.size(), 11u);  // 100, 110, ..., 200
  EXPECT_DOUBLE_EQ(plan.z_um.front(), 100.0);
  EXPECT_DOUBLE_EQ(plan.z_um.back(), 200.0);
  EXPECT_DOUBLE_EQ(plan.exposure_us, 5000.0);
  EXPECT_EQ(plan.mode, IlluminationMode::kStd);  // uncalibrated default
  EXPECT_EQ(plan.sff.focus_measure, FocusMeasure::kTenengrad);
  EXPECT_EQ(plan.sff.interpolation, DepthInterpolation::kDefocusParabola);
  EXPECT_EQ(plan.sff.window_px, SffOptions().window_px);
  EXPECT_TRUE(work->extra_exports.empty());
  EXPECT_TRUE(plan.calibration_id.empty());  // filled in when the scan starts
}

TEST_F(ScanMappingTest, RequestFieldsReachThePlan) {
  v1::ScanRequest r;
  r.set_z_start_um(300.0);
  r.set_z_end_um(280.0);
  r.set_z_step_um(5.0);
  r.set_exposure_us(1234.0);
  r.set_illumination(v1::ILLUMINATION_MODE_HDR);
  r.mutable_illumination_parameters()->set_hdr_exposures(4);
  r.mutable_reconstruction()->set_focus_measure(v1::FOCUS_MEASURE_SUM_MODIFIED_LAPLACIAN);
  r.mutable_reconstruction()->set_window_px(9);
  r.mutable_reconstruction()->set_interpolation(v1::DEPTH_INTERPOLATION_LINE_FIT);
  r.mutable_reconstruction()->set_min_confidence(0.3);
  r.mutable_reconstruction()->add_extra_exports(v1::ARTIFACT_KIND_DEPTH_X3P);
  r.mutable_reconstruction()->add_extra_exports(v1::ARTIFACT_KIND_DEPTH_PLY);
  const CalibrationBundle camera_only = BundleWith({CalibrationStep::kCameraResponse});
  auto work = MapScanRequest(r, Context(&camera_only));
  ASSERT_TRUE(work.ok()) << work.status().ToString();
  EXPECT_EQ(work->plan.z_um, (std::vector<double>{300.0, 295.0, 290.0, 285.0, 280.0}));
  EXPECT_DOUBLE_EQ(work->plan.exposure_us, 1234.0);
  EXPECT_EQ(work->plan.mode, IlluminationMode::kHdr);
  EXPECT_EQ(work->plan.params.hdr_exposures, 4);
  EXPECT_EQ(work->plan.sff.focus_measure, FocusMeasure::kSumModifiedLaplacian);
  EXPECT_EQ(work->plan.sff.window_px, 9);
  EXPECT_EQ(work->plan.sff.interpolation, DepthInterpolation::kLineFit);
  EXPECT_DOUBLE_EQ(work->plan.sff.min_confidence, 0.3);
  EXPECT_EQ(work->extra_exports,
            (std::vector<DepthExportKind>{DepthExportKind::kDepthX3p, DepthExportKind::kDepthPly}));
}

TEST_F(ScanMappingTest, BadFieldsAreNamed) {
  struct Case {
    void (*mutate)(v1::ScanRequest&);
    const char* field;
  };
  const Case cases[] = {
      {[](v1::ScanRequest& r) { r.set_illumination(static_cast<v1::IlluminationMode>(42)); }, "illumination"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_lambda(2.5); },
       "illumination_parameters.lambda"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_target_grey(0); },
       "illumination_parameters.target_grey"},
      {[](v1::ScanRequest& r) { r.set_exposure_us(-1); }, "exposure_us"},
      {[](v1::ScanRequest& r) { r.set_z_step_um(-2); }, "z_step_um"},
      {[](v1::ScanRequest& r) {
         r.set_z_start_um(-50);
         r.set_z_end_um(100);
       },
       "z_start_um"},
      {[](v1::ScanRequest& r) {
         r.set_z_start_um(100);
         r.set_z_end_um(500);
       },
       "z_end_um"},
      {[](v1::ScanRequest& r) { r.mutable_reconstruction()->set_window_px(4); }, "reconstruction: window_px"},
      {[](v1::ScanRequest& r) { r.mutable_reconstruction()->set_focus_measure(static_cast<v1::FocusMeasure>(99)); },
       "reconstruction: focus_measure"},
      {[](v1::ScanRequest& r) {
         r.mutable_reconstruction()->set_interpolation(static_cast<v1::DepthInterpolation>(9));
       },
       "reconstruction.interpolation"},
      {[](v1::ScanRequest& r) { r.mutable_reconstruction()->set_min_confidence(1.5); },
       "reconstruction: min_confidence"},
      {[](v1::ScanRequest& r) {
         r.mutable_reconstruction()->add_extra_exports(v1::ARTIFACT_KIND_DEPTH_PLY);
         r.mutable_reconstruction()->add_extra_exports(v1::ARTIFACT_KIND_STACK_ZIP);
       },
       "reconstruction.extra_exports[1]"},
  };
  for (const Case& c : cases) {
    v1::ScanRequest r;
    c.mutate(r);
    auto work = MapScanRequest(r, Context());
    ASSERT_FALSE(work.ok()) << c.field;
    ExpectInvalidNaming(work.status(), c.field);
  }
}

TEST_F(ScanMappingTest, RequestedModeWithoutItsModelsNamesTheMissingStep) {
  const CalibrationBundle adapt_only = BundleWith(kAdaptSteps);
  v1::ScanRequest r;
  r.set_illumination(v1::ILLUMINATION_MODE_TEXTURE);
  auto work = MapScanRequest(r, Context(&adapt_only));
  ASSERT_FALSE(work.ok());
  EXPECT_EQ(work.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(work.status().message().find("geometry, psf"), std::string::npos) << work.status().message();

  // Calibrated, but the focus window is too small for the checkerboard (eq. 5.15).
  const CalibrationBundle full = BundleWith(kHfAdaptSteps);
  r.set_illumination(v1::ILLUMINATION_MODE_HF_ADAPT);
  r.mutable_reconstruction()->set_window_px(5);
  work = MapScanRequest(r, Context(&full));
  ASSERT_FALSE(work.ok());
  EXPECT_EQ(work.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(work.status().message().rfind("reconstruction.window_px 5: ", 0), 0u) << work.status().message();
}

TEST_F(ScanMappingTest, DefaultIlluminationFallsBackByCalibrationContents) {
  const CalibrationBundle none;
  const CalibrationBundle camera_only = BundleWith({CalibrationStep::kCameraResponse});
  const CalibrationBundle adapt = BundleWith(kAdaptSteps);
  const CalibrationBundle full = BundleWith(kHfAdaptSteps);
  struct Case {
    const CalibrationBundle* calibration;
    int window_px;
    IlluminationMode expected;
  };
  const Case cases[] = {
      {nullptr, 7, IlluminationMode::kStd},      {&none, 7, IlluminationMode::kStd},
      {&camera_only, 7, IlluminationMode::kStd}, {&adapt, 7, IlluminationMode::kAuto},
      {&full, 7, IlluminationMode::kAuto},       {&full, 5, IlluminationMode::kAuto},  // AUTO: ADAPT or STD
  };
  for (const Case& c : cases) {
    EXPECT_EQ(DefaultIlluminationMode(c.calibration, c.window_px), c.expected)
        << "window " << c.window_px << ", expected " << IlluminationModeName(c.expected);
    // The scan request with no mode gets the same, and never an error for the fallback.
    v1::ScanRequest r;
    r.mutable_reconstruction()->set_window_px(c.window_px);
    auto work = MapScanRequest(r, Context(c.calibration));
    ASSERT_TRUE(work.ok()) << work.status().ToString();
    EXPECT_EQ(work->plan.mode, c.expected);
  }
}

// Integral SFF (thesis 5.4, 6.4): the method and threshold reach the plan; the integral methods
// scan under STD even where the calibration would pick HF+ADAPT, and name what they lack.
TEST_F(ScanMappingTest, IntegralMethodsReachThePlanAndNameWhatTheyLack) {
  const CalibrationBundle everything = BundleWith(
      {CalibrationStep::kCameraResponse, CalibrationStep::kProjectorResponse, CalibrationStep::kScatterMatrix,
       CalibrationStep::kGeometry, CalibrationStep::kPsf, CalibrationStep::kIntegralPsf});
  v1::ScanRequest r;
  auto sff = MapScanRequest(r, Context(&everything));
  ASSERT_TRUE(sff.ok()) << sff.status().ToString();
  EXPECT_EQ(sff->plan.reconstruction.method, ReconstructionMethod::kSff);
  EXPECT_EQ(sff->plan.mode, IlluminationMode::kAuto);

  r.mutable_reconstruction()->set_method(v1::RECONSTRUCTION_METHOD_ISFF_FAST);
  auto fast = MapScanRequest(r, Context(&everything));
  ASSERT_TRUE(fast.ok()) << fast.status().ToString();
  EXPECT_EQ(fast->plan.reconstruction.method, ReconstructionMethod::kIsffFast);
  EXPECT_DOUBLE_EQ(fast->plan.reconstruction.isff_fast_threshold, 0.9);
  EXPECT_EQ(fast->plan.mode, IlluminationMode::kStd);
  const IsffOptions o = IsffOptionsFor(fast->plan.reconstruction, fast->plan.sff);
  EXPECT_TRUE(o.ncc.stop_at_first_maximum);
  EXPECT_EQ(o.ncc.correlation_window_px, 7);
  EXPECT_EQ(o.ncc.summation_window_px, 7);

  r.mutable_reconstruction()->set_isff_fast_threshold(0.75);
  r.mutable_reconstruction()->set_window_px(9);
  fast = MapScanRequest(r, Context(&everything));
  ASSERT_TRUE(fast.ok()) << fast.status().ToString();
  EXPECT_DOUBLE_EQ(fast->plan.reconstruction.isff_fast_threshold, 0.75);
  EXPECT_DOUBLE_EQ(IsffOptionsFor(fast->plan.reconstruction, fast->plan.sff).ncc.stop_threshold, 0.75);
  EXPECT_EQ(IsffOptionsFor(fast->plan.reconstruction, fast->plan.sff).ncc.correlation_window_px, 9);

  for (double bad : {0.0, 1.5, -1.0}) {
    r.mutable_reconstruction()->set_isff_fast_threshold(bad);
    ExpectInvalidNaming(MapScanRequest(r, Context(&everything)).status(), "reconstruction.isff_fast_threshold");
  }
  r.mutable_reconstruction()->set_method(v1::RECONSTRUCTION_METHOD_ISFF);
  r.mutable_reconstruction()->set_isff_fast_threshold(0.9);  // not ISFF-FAST
  ExpectInvalidNaming(MapScanRequest(r, Context(&everything)).status(), "reconstruction.isff_fast_threshold");
  r.mutable_reconstruction()->clear_isff_fast_threshold();
  r.mutable_reconstruction()->set_focus_measure(v1::FOCUS_MEASURE_SUM_MODIFIED_LAPLACIAN);
  ExpectInvalidNaming(MapScanRequest(r, Context(&everything)).status(), "reconstruction.focus_measure");
  r.mutable_reconstruction()->clear_focus_measure();
  r.set_illumination(v1::ILLUMINATION_MODE_HDR);
  ExpectInvalidNaming(MapScanRequest(r, Context(&everything)).status(), "illumination");
  r.set_illumination(v1::ILLUMINATION_MODE_STD);
  EXPECT_TRUE(MapScanRequest(r, Context(&everything)).ok());

  // No IPSF: FAILED_PRECONDITION naming the step; ISFF-GT needs no calibration.
  const CalibrationBundle adapt = BundleWith(kAdaptSteps);
  for (const CalibrationBundle* c : {static_cast<const CalibrationBundle*>(nullptr), &adapt}) {
    const Status st = MapScanRequest(r, Context(c)).status();
    EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition) << st.ToString();
    EXPECT_NE(st.message().find("integral_psf"), std::string::npos) << st.message();
  }
  r.mutable_reconstruction()->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
  auto gt = MapScanRequest(r, Context(nullptr));
  ASSERT_TRUE(gt.ok()) << gt.status().ToString();
  EXPECT_EQ(gt->plan.reconstruction.method, ReconstructionMethod::kIsffGroundTruth);
}

TEST(CalibrateMappingTest, StepsMapInOrderAndBadOnesAreNamed) {
  v1::CalibrateRequest r;
  auto all = MapCalibrateRequest(r);
  ASSERT_TRUE(all.ok());
  EXPECT_TRUE(all->options.steps.empty());  // empty = all six (RunCalibration)

  r.add_steps(v1::CALIBRATION_STEP_SCATTER_MATRIX);
  r.add_steps(v1::CALIBRATION_STEP_CAMERA_RESPONSE);
  auto two = MapCalibrateRequest(r);
  ASSERT_TRUE(two.ok());
  EXPECT_EQ(two->options.steps,
            (std::vector<CalibrationStep>{CalibrationStep::kScatterMatrix, CalibrationStep::kCameraResponse}));

  r.add_steps(v1::CALIBRATION_STEP_UNSPECIFIED);
  ExpectInvalidNaming(MapCalibrateRequest(r).status(), "steps[2]");
  r.set_steps(2, static_cast<v1::CalibrationStep>(77));
  ExpectInvalidNaming(MapCalibrateRequest(r).status(), "steps[2]");
}

TEST(ReconstructMappingTest, SourceIsAStoredScanOrAnAnnouncedUpload) {
  v1::ReconstructStart s;
  ExpectInvalidNaming(MapReconstructSource(s, 1000).status(), "start.source");
  s.set_scan_id("scan-0123abcd");
  auto scan = MapReconstructSource(s, 1000);
  ASSERT_TRUE(scan.ok());
  EXPECT_EQ(scan->scan_id, "scan-0123abcd");
  EXPECT_FALSE(scan->upload);
  for (const char* bad : {"../scans/x", "a/b", "", "scan id"}) {
    s.set_scan_id(bad);
    ExpectInvalidNaming(MapReconstructSource(s, 1000).status(), "start.scan_id");
  }

  s.mutable_upload()->set_file_count(3);
  s.mutable_upload()->set_total_bytes(1000);
  auto upload = MapReconstructSource(s, 1000);
  ASSERT_TRUE(upload.ok());
  EXPECT_TRUE(upload->upload);
  EXPECT_EQ(upload->upload_total_bytes, 1000);
  EXPECT_EQ(upload->upload_file_count, 3);
  s.mutable_upload()->set_total_bytes(1001);
  ExpectInvalidNaming(MapReconstructSource(s, 1000).status(), "start.upload.total_bytes");
  s.mutable_upload()->set_total_bytes(10);
  s.mutable_upload()->set_file_count(-1);
  ExpectInvalidNaming(MapReconstructSource(s, 1000).status(), "start.upload.file_count");
}

TEST(ReconstructMappingTest, UploadChunksStayInsideTheStackFolder) {
  v1::StackFileChunk c;
  c.set_path("frames/frame_0001.png");
  c.set_data(std::string(kMaxChunkBytes, 'x'));
  EXPECT_TRUE(CheckUploadChunk(c).ok());
  c.set_data(std::string(kMaxChunkBytes + 1, 'x'));
  ExpectInvalidNaming(CheckUploadChunk(c), "file_chunk.data");
  c.clear_data();
  for (const char* bad : {"", "/etc/passwd", "../x.png", "frames/../../x.png", "./stack.json"}) {
    c.set_path(bad);
    ExpectInvalidNaming(CheckUploadChunk(c), "file_chunk.path");
  }
}

TEST(ReconstructMappingTest, OptionsAreNamedUnderOptions) {
  v1::ReconstructStart s;
  s.set_scan_id("scan-1");
  s.mutable_options()->set_window_px(11);
  s.mutable_options()->add_extra_exports(v1::ARTIFACT_KIND_DEPTH_PNG16);
  auto work = MapReconstructStart(s, "/data/scans/scan-1", nullptr);
  ASSERT_TRUE(work.ok());
  EXPECT_EQ(work->stack_dir, "/data/scans/scan-1");
  EXPECT_EQ(work->source_scan_id, "scan-1");
  EXPECT_EQ(work->sff.window_px, 11);
  EXPECT_EQ(work->extra_exports, std::vector<DepthExportKind>{DepthExportKind::kDepthPng16});
  s.mutable_options()->add_extra_exports(v1::ARTIFACT_KIND_DEPTH_TIFF);  // always written, not an extra
  ExpectInvalidNaming(MapReconstructStart(s, "/data/scans/scan-1", nullptr).status(), "options.extra_exports[1]");
}

TEST(ReconstructMappingTest, IntegralMethodsAreCheckedBeforeTheStackArrives) {
  v1::ReconstructStart s;
  s.set_scan_id("scan-1");
  s.mutable_options()->set_method(v1::RECONSTRUCTION_METHOD_ISFF_FAST);
  s.mutable_options()->set_isff_fast_threshold(0.0);
  ExpectInvalidNaming(MapReconstructSource(s, 1000).status(), "options.isff_fast_threshold");
  s.mutable_options()->set_isff_fast_threshold(0.95);
  ASSERT_TRUE(MapReconstructSource(s, 1000).ok());
  auto work = MapReconstructStart(s, "/data/scans/scan-1", nullptr);
  ASSERT_TRUE(work.ok()) << work.status().ToString();
  EXPECT_EQ(work->method.method, ReconstructionMethod::kIsffFast);
  EXPECT_DOUBLE_EQ(work->method.isff_fast_threshold, 0.95);
  // A stored or uploaded stack has no ground-truth texture.
  s.mutable_options()->clear_isff_fast_threshold();
  s.mutable_options()->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
  const Status gt = MapReconstructSource(s, 1000).status();
  EXPECT_EQ(gt.code(), StatusCode::kFailedPrecondition) << gt.ToString();
  EXPECT_NE(gt.message().find("simulated rig"), std::string::npos) << gt.message();
}

TEST(OtherRequestsTest, ListJobsPagesAndDownloadRanges) {
  v1::ListJobsRequest l;
  auto q = MapListJobsRequest(l);
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->limit, 50);
  EXPECT_EQ(q->before_create_ns, 0);
  l.set_page_size(10000);
  l.set_kind(v1::JOB_KIND_SCAN);
  google::protobuf::Timestamp t;
  t.set_seconds(1700000000);
  t.set_nanos(42);
  l.set_page_token(NextPageToken(t));
  q = MapListJobsRequest(l);
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->limit, 500);
  EXPECT_EQ(q->kind, v1::JOB_KIND_SCAN);
  EXPECT_EQ(q->before_create_ns, 1700000000LL * 1000000000LL + 42);
  l.set_page_token("yesterday");
  ExpectInvalidNaming(MapListJobsRequest(l).status(), "page_token");
  l.set_page_size(-1);
  ExpectInvalidNaming(MapListJobsRequest(l).status(), "page_size");

  v1::DownloadArtifactRequest d;
  ExpectInvalidNaming(MapDownloadRequest(d).status(), "artifact_id");
  d.set_artifact_id("art-1");
  d.set_offset(-1);
  ExpectInvalidNaming(MapDownloadRequest(d).status(), "offset");
  d.set_offset(5);
  d.set_limit(-1);
  ExpectInvalidNaming(MapDownloadRequest(d).status(), "limit");
  d.set_limit(7);
  auto range = MapDownloadRequest(d);
  ASSERT_TRUE(range.ok());
  EXPECT_EQ(range->offset, 5);
  EXPECT_EQ(range->limit, 7);

  ExpectInvalidNaming(CheckJobId(""), "job_id");
  EXPECT_TRUE(CheckJobId("scan-1").ok());
  ExpectInvalidNaming(CheckSpecimenName(""), "specimen");
}

}  // namespace
}  // namespace inspection
