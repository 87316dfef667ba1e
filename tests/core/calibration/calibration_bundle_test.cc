// Calibration bundle folder: every model survives Save/Load bit-exactly (floats via TIFF and
// the CSC file), a bundle is never overwritten, newer versions and damaged files are refused.
#include "core/calibration/calibration_bundle.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

namespace inspection {
namespace {
namespace fs = std::filesystem;

class CalibrationBundleTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("bundle_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  static CalibrationBundle MakeBundle() {
    CalibrationBundle b;
    b.id = "cal-0001";
    b.created_utc = "2026-11-22T00:30:00Z";
    b.rig = "synthetic";
    b.camera_size = {8, 6};
    b.projector_size = {4, 3};
    CameraResponseFunction crf;
    for (int z = 0; z < 256; ++z) crf.log_exposure.push_back(0.01 * (z - 128) + 1e-3 * std::sin(z));
    for (int z = 1; z < 256; ++z) crf.log_exposure[z] = std::max(crf.log_exposure[z], crf.log_exposure[z - 1]);
    crf.fit_rms_residual = 0.0123;
    b.camera_response = crf;
    ProjectorResponseFunction prf;
    for (int i = 0; i < 256; ++i) prf.relative_irradiance.push_back(std::pow(i / 255.0, 2.2));
    prf.measured_levels = {0, 128, 255};
    b.projector_response = prf;
    GeometricCalibration g;
    g.projector_size = b.projector_size;
    g.camera_size = b.camera_size;
    g.projector_to_camera = cv::Mat(3, 4, CV_32FC2);
    for (int v = 0; v < 3; ++v)
      for (int u = 0; u < 4; ++u)
        g.projector_to_camera.at<cv::Vec2f>(v, u) = cv::Vec2f(1.5f + 2.01f * u, 1.25f + 1.99f * v);
    g.projector_to_camera.at<cv::Vec2f>(0, 0) = cv::Vec2f(NAN, NAN);
    EXPECT_TRUE(FinishGeometricCalibration(g).ok());
    b.geometry = g;
    PsfCalibration psf;
    for (double dz : {0.0, 10.0}) {
      PsfAtDefocus s;
      s.defocus_um = dz;
      s.psf = cv::Mat(5, 5, CV_32FC1, cv::Scalar(0.04f));
      s.sigma_px = 1.0 + dz / 10;
      psf.steps.push_back(s);
    }
    psf.influence_radius_px = 4.2;
    b.psf = psf;
    ScatterMatrix s;
    s.camera_size = b.camera_size;
    s.projector_size = b.projector_size;
    s.a.resize(48, 12);
    s.a.insert(9, 1) = 0.5f;
    s.a.insert(10, 1) = 0.25f;
    s.a.insert(40, 11) = 3.0f;
    s.a.makeCompressed();
    s.black_radiance = cv::Mat(6, 8, CV_32FC1, cv::Scalar(0.125f));
    s.patch_radius_px = 3;
    b.scatter = s;
    IntegralPsf ipsf;
    ipsf.kernel = cv::Mat::zeros(3, 3, CV_32FC1);
    ipsf.kernel.at<float>(1, 1) = 1.25f;
    ipsf.regularisation = IpsfRegularisation::kTotalVariation;
    b.integral_psf = ipsf;
    CalibrationStepReport rep;
    rep.step = CalibrationStep::kGeometry;
    rep.duration_s = 1.5;
    rep.frames_captured = 100;
    rep.figures["lut_vs_homography_mean_px"] = 0.266;
    rep.figures["lut_error_vs_truth_max_px"] = NAN;
    b.SetReport(rep);
    return b;
  }

  fs::path dir_;
};

TEST_F(CalibrationBundleTest, RoundTripKeepsEveryModel) {
  const CalibrationBundle b = MakeBundle();
  ASSERT_TRUE(b.Save(dir_).ok());
  auto l = CalibrationBundle::Load(dir_);
  ASSERT_TRUE(l.ok()) << l.status().ToString();
  EXPECT_EQ(l->id, "cal-0001");
  EXPECT_EQ(l->version, kCalibrationBundleVersion);
  EXPECT_EQ(l->camera_response->log_exposure, b.camera_response->log_exposure);
  EXPECT_EQ(l->projector_response->relative_irradiance, b.projector_response->relative_irradiance);
  EXPECT_EQ(cv::norm(l->geometry->camera_to_projector, b.geometry->camera_to_projector, cv::NORM_INF), 0.0);
  EXPECT_TRUE(std::isnan(l->geometry->projector_to_camera.at<cv::Vec2f>(0, 0)[0]));
  EXPECT_EQ(l->geometry->projector_to_camera.at<cv::Vec2f>(2, 3), b.geometry->projector_to_camera.at<cv::Vec2f>(2, 3));
  EXPECT_EQ(l->geometry->homography, b.geometry->homography);
  EXPECT_EQ(l->psf->steps.size(), 2u);
  EXPECT_DOUBLE_EQ(l->psf->influence_radius_px, 4.2);
  EXPECT_EQ(l->scatter->a.nonZeros(), 3);
  EXPECT_FLOAT_EQ(l->scatter->a.coeff(40, 11), 3.0f);
  EXPECT_FLOAT_EQ(l->scatter->black_radiance.at<float>(5, 7), 0.125f);
  EXPECT_FLOAT_EQ(l->integral_psf->kernel.at<float>(1, 1), 1.25f);
  EXPECT_EQ(l->integral_psf->regularisation, IpsfRegularisation::kTotalVariation);
  const auto* rep = l->Report(CalibrationStep::kGeometry);
  ASSERT_NE(rep, nullptr);
  EXPECT_DOUBLE_EQ(rep->figures.at("lut_vs_homography_mean_px"), 0.266);
  EXPECT_TRUE(std::isnan(rep->figures.at("lut_error_vs_truth_max_px")));
  EXPECT_NE(l->Summary().find("lut_vs_homography_mean_px = 0.266"), std::string::npos);
}

TEST_F(CalibrationBundleTest, NeverOverwritesAndPartialBundlesLoad) {
  ASSERT_TRUE(MakeBundle().Save(dir_).ok());
  EXPECT_EQ(MakeBundle().Save(dir_).code(), StatusCode::kAlreadyExists);
  CalibrationBundle only_crf;
  only_crf.camera_size = {8, 6};
  only_crf.projector_size = {4, 3};
  only_crf.camera_response = MakeBundle().camera_response;
  const fs::path d2 = dir_ / "partial";
  ASSERT_TRUE(only_crf.Save(d2).ok());
  auto l = CalibrationBundle::Load(d2);
  ASSERT_TRUE(l.ok()) << l.status().ToString();
  EXPECT_TRUE(l->HasModel(CalibrationStep::kCameraResponse));
  EXPECT_FALSE(l->HasModel(CalibrationStep::kScatterMatrix));
}

TEST_F(CalibrationBundleTest, RefusesNewerVersionMissingFilesAndBadCurves) {
  EXPECT_EQ(CalibrationBundle::Load(dir_).status().code(), StatusCode::kNotFound);
  ASSERT_TRUE(MakeBundle().Save(dir_).ok());
  const fs::path manifest = dir_ / kCalibrationBundleManifest;
  nlohmann::json j;
  {
    std::ifstream in(manifest);
    j = nlohmann::json::parse(in);
  }
  auto write = [&](const nlohmann::json& x) {
    std::ofstream out(manifest, std::ios::trunc);
    out << x.dump();
  };

  nlohmann::json newer = j;
  newer["version"] = kCalibrationBundleVersion + 1;
  write(newer);
  EXPECT_EQ(CalibrationBundle::Load(dir_).status().code(), StatusCode::kFailedPrecondition);

  nlohmann::json bad_curve = j;
  bad_curve["camera_response"]["log_exposure"][100] = 50.0;  // non-monotonic
  write(bad_curve);
  auto l = CalibrationBundle::Load(dir_);
  EXPECT_EQ(l.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(l.status().message().find("log_exposure"), std::string::npos);
  EXPECT_EQ(l.status().message().rfind(manifest.string() + ": ", 0), 0u) << l.status().message();
  EXPECT_EQ(l.status().message().find(": :"), std::string::npos) << l.status().message();

  write(j);
  fs::remove(dir_ / "scatter_matrix.bin");
  EXPECT_EQ(CalibrationBundle::Load(dir_).status().code(), StatusCode::kNotFound);
  fs::remove(dir_ / "geometry_camera_to_projector_y.tiff");
  l = CalibrationBundle::Load(dir_);
  EXPECT_EQ(l.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(l.status().message().find("geometry_camera_to_projector_y.tiff"), std::string::npos);
}

TEST_F(CalibrationBundleTest, ZLinearityRoundTripsThroughBundleJson) {
  CalibrationBundle b = MakeBundle();
  ZLinearity z;
  z.bias_of_step = {0.0, 0.031, -0.0125, -0.018};
  z.characterised_step_um = 5.0;
  z.source = "calibration step z_linearity on skew10";
  b.z_linearity = z;
  ASSERT_TRUE(b.Save(dir_).ok());
  auto l = CalibrationBundle::Load(dir_);
  ASSERT_TRUE(l.ok()) << l.status().ToString();
  ASSERT_TRUE(l->z_linearity.has_value());
  EXPECT_EQ(l->z_linearity->bias_of_step, z.bias_of_step);
  EXPECT_DOUBLE_EQ(l->z_linearity->characterised_step_um, 5.0);
  EXPECT_EQ(l->z_linearity->source, z.source);
  EXPECT_TRUE(l->HasModel(CalibrationStep::kZLinearity));
  EXPECT_FALSE(MakeBundle().HasModel(CalibrationStep::kZLinearity));
  b.z_linearity->characterised_step_um = 0.0;  // a table must say at which step it holds
  EXPECT_EQ(b.Validate().code(), StatusCode::kInvalidArgument);
}

TEST(CalibrationStepTest, NamesRoundTrip) {
  for (CalibrationStep s : AllCalibrationSteps()) {
    auto p = ParseCalibrationStep(CalibrationStepName(s));
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(*p, s);
  }
  EXPECT_EQ(ParseCalibrationStep("lut").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
