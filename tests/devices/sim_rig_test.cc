// Simulated rig end to end: defaults, exposure, ground truth and a Tenengrad SFF scan of the
// tilted textured plane compared to ground truth (thesis 6.2: SKEW5).
#include <gtest/gtest.h>

#include <cmath>

#include "core/sff/sff_engine.h"
#include "devices/sim/simulated_rig.h"

namespace inspection {
namespace {

// Standard SFF of the thesis (STD): Tenengrad 7x7, three-point Gaussian interpolation.
SffOptions TenengradGaussian() {
  SffOptions o;
  o.focus_measure = FocusMeasure::kTenengrad;
  o.window_px = 7;
  o.interpolation = DepthInterpolation::kGaussian;
  return o;
}

SimulatedRigOptions SmallOptions(const std::string& specimen) {
  SimulatedRigOptions o;
  o.specimen = specimen;
  o.camera_size = {256, 192};
  return o;
}

std::unique_ptr<Rig> MakeRig(const SimulatedRigOptions& o) {
  auto rig = CreateSimulatedRig(o);
  EXPECT_TRUE(rig.ok()) << rig.status().ToString();
  return rig.ok() ? std::move(rig).value() : nullptr;
}

struct ScanResult {
  DepthResult depth;
  std::vector<cv::Mat> frames;
};

ScanResult Scan(Rig& rig, const ScanDefaults& d) {
  auto engine = SffEngine::Create(TenengradGaussian(), rig.camera().frame_size(),
                                  rig.camera().bit_depth() == 8 ? CV_8UC1 : CV_16UC1);
  EXPECT_TRUE(engine.ok());
  ScanResult r;
  for (double z = d.z_start_um; z <= d.z_end_um + 1e-9; z += d.z_step_um) {
    EXPECT_TRUE(rig.stage().MoveTo(z).ok());
    auto frame = rig.camera().Capture();
    EXPECT_TRUE(frame.ok());
    r.frames.push_back(*frame);
    EXPECT_TRUE((*engine)->PushFrame(*frame, z).ok());
  }
  auto depth = (*engine)->Finish();
  EXPECT_TRUE(depth.ok());
  r.depth = *depth;
  return r;
}

// RMSE of finite depths against ground truth, ignoring a border of the focus window's size.
double DepthRmse(const cv::Mat& depth, const cv::Mat& truth, int border, double* valid_fraction) {
  double sum = 0;
  int n = 0, total = 0;
  for (int r = border; r < depth.rows - border; ++r) {
    for (int c = border; c < depth.cols - border; ++c) {
      ++total;
      const float d = depth.at<float>(r, c);
      if (!std::isfinite(d)) continue;
      const double e = d - truth.at<float>(r, c);
      sum += e * e;
      ++n;
    }
  }
  *valid_fraction = static_cast<double>(n) / total;
  return n ? std::sqrt(sum / n) : 1e9;
}

TEST(SimulatedRigTest, Skew5ScanMatchesGroundTruth) {
  auto rig = MakeRig(SmallOptions("skew5"));
  ASSERT_TRUE(rig);
  const ScanDefaults d = rig->scan_defaults();
  ASSERT_TRUE(rig->projector().ShowUniform(128).ok());
  ASSERT_TRUE(rig->camera().SetExposure(d.exposure_us).ok());
  ScanResult r = Scan(*rig, d);
  double valid = 0;
  const double rmse = DepthRmse(r.depth.depth_um, rig->simulation()->GroundTruthDepthUm(), 8, &valid);
  std::printf("skew5 256x192: %zu frames, rmse %.3f um, valid %.3f, exposure %.0f us\n", r.frames.size(), rmse, valid,
              d.exposure_us);
  EXPECT_LT(rmse, 0.25 * d.z_step_um);
  EXPECT_GT(valid, 0.95);
}

TEST(SimulatedRigTest, DefaultExposureGivesMeanGrey128OnTexturedSpecimens) {
  for (const std::string name : {"plane", "skew5", "skew10", "step1um", "wedge", "chamfer"}) {
    auto rig = MakeRig(SmallOptions(name));
    ASSERT_TRUE(rig);
    const ScanDefaults d = rig->scan_defaults();
    const auto range = rig->simulation()->SpecimenZRangeUm();
    ASSERT_TRUE(rig->stage().MoveTo(0.5 * (range.first + range.second)).ok());
    ASSERT_TRUE(rig->projector().ShowUniform(128).ok());
    ASSERT_TRUE(rig->camera().SetExposure(d.exposure_us).ok());
    auto frame = rig->camera().Capture();
    ASSERT_TRUE(frame.ok());
    EXPECT_NEAR(cv::mean(*frame)[0], 128.0, 10.0) << name;
    EXPECT_LE(d.z_start_um, range.first - 3 * d.z_step_um) << name;
    EXPECT_GE(d.z_end_um, range.second + 3 * d.z_step_um) << name;
    EXPECT_DOUBLE_EQ(d.z_step_um, 5.0);
  }
}

}  // namespace
}  // namespace inspection
