// Material measures of the simulated rig (devices/sim/specimen.h SimulatedMaterialMeasures) and the
// injected instrument errors (devices/sim/simulated_rig.h): the certificates match the built
// surfaces, the errors change what the optics show but not the ground truth, and the extra depth
// noise is drawn afresh for every scan.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>

#include "devices/sim/simulated_rig.h"
#include "devices/sim/specimen.h"

namespace inspection {
namespace {

const SpecimenGrid kGrid{{256, 192}, 0.74, 1};

TEST(SimMaterialMeasures, CertificatesMatchTheSurfaces) {
  const auto measures = SimulatedMaterialMeasures();
  ASSERT_EQ(measures.size(), 1u + 4u + 8u + 1u);
  for (const MaterialMeasure& m : measures) {
    auto s = MakeSpecimen(m.specimen, kGrid);
    ASSERT_TRUE(s.ok()) << m.specimen;
    double lo = 0, hi = 0;
    cv::minMaxLoc(s->height_um, &lo, &hi);
    switch (m.type) {
      case MaterialMeasureType::kAfl:
        EXPECT_DOUBLE_EQ(hi - lo, 0.0);
        break;
      case MaterialMeasureType::kPgr:
        EXPECT_NEAR(hi - lo, m.height_um, 1e-4) << m.specimen;
        // The groove is the centre third.
        EXPECT_NEAR(s->height_um.at<float>(96, 128), lo, 1e-4);
        EXPECT_NEAR(s->height_um.at<float>(96, 10), hi, 1e-4);
        break;
      case MaterialMeasureType::kAsg: {
        EXPECT_NEAR(hi - lo, 2.0 * m.height_um, 0.05) << m.specimen;  // sampled peaks
        // One period along x repeats the row.
        const int p = int(std::lround(m.period_um / kGrid.pixel_size_um));
        if (std::abs(p * kGrid.pixel_size_um - m.period_um) < 1e-9) {
          EXPECT_NEAR(s->height_um.at<float>(50, 20), s->height_um.at<float>(50, 20 + p), 1e-4);
        }
        break;
      }
      case MaterialMeasureType::kAcg:
        EXPECT_NEAR(hi - lo, 4.0 * m.height_um, 0.05);
        EXPECT_DOUBLE_EQ(m.period_um, 20.0);
        break;
    }
  }
}

TEST(SimMaterialMeasures, RigOffersThemUnlessSwitchedOff) {
  SimulatedRigOptions o;
  o.camera_size = {64, 48};
  o.specimen = "afl";
  auto rig = CreateSimulatedRig(o);
  ASSERT_TRUE(rig.ok());
  EXPECT_EQ((*rig)->simulation()->material_measures().size(), SimulatedMaterialMeasures().size());
  const auto names = (*rig)->simulation()->specimen_names();
  EXPECT_NE(std::find(names.begin(), names.end(), "acg"), names.end());
  o.material_measures = false;
  auto bare = CreateSimulatedRig(o);
  ASSERT_TRUE(bare.ok());
  EXPECT_TRUE((*bare)->simulation()->material_measures().empty());
  const auto bare_names = (*bare)->simulation()->specimen_names();
  EXPECT_EQ(std::find(bare_names.begin(), bare_names.end(), "acg"), bare_names.end());
}

TEST(SimOpticsErrors, ZScaleAndBowChangeWhatTheOpticsShowNotTheTruth) {
  SimulatedRigOptions o;
  o.camera_size = {64, 48};
  o.specimen = "pgr20";
  auto clean = CreateSimulatedRig(o);
  o.z_scale_error = 0.01;
  o.flatness_bow_um = 0.5;
  auto faulty = CreateSimulatedRig(o);
  ASSERT_TRUE(clean.ok() && faulty.ok());
  const cv::Mat t0 = (*clean)->simulation()->GroundTruthDepthUm(), t1 = (*faulty)->simulation()->GroundTruthDepthUm();
  EXPECT_EQ(cv::norm(t0, t1, cv::NORM_INF), 0.0);
  const auto [lo, hi] = (*faulty)->simulation()->SpecimenZRangeUm();
  // Seen: 1.01 x (200 .. 220), the bow adds up to 0.5 um at the corners (lands are outside).
  EXPECT_NEAR(lo, 202.0, 0.05);
  EXPECT_NEAR(hi, 222.2 + 0.5, 0.05);
}

TEST(SimOpticsErrors, Validated) {
  SimulatedRigOptions o;
  o.z_scale_error = 0.5;
  EXPECT_NE(o.Validate().message().find("z_scale_error"), std::string::npos);
  o = {};
  o.lateral_scale_error_y = -0.3;
  EXPECT_NE(o.Validate().message().find("lateral_scale_error_y"), std::string::npos);
  o = {};
  o.extra_noise_um = -1;
  EXPECT_NE(o.Validate().message().find("extra_noise_um"), std::string::npos);
}

TEST(SimOpticsErrors, ExtraNoiseIsDrawnAfreshForEveryScan) {
  SimulatedRigOptions o;
  o.camera_size = {128, 96};
  o.specimen = "afl";
  o.extra_noise_um = 0.2;
  const cv::Mat a = SimulatedDepthNoiseField(o, 0), b = SimulatedDepthNoiseField(o, 1);
  cv::Scalar mean, sd;
  cv::meanStdDev(a, mean, sd);
  EXPECT_NEAR(sd[0], 0.2, 1e-4);
  EXPECT_NEAR(mean[0], 0.0, 1e-6);
  EXPECT_GT(cv::norm(a, b, cv::NORM_INF), 0.1);
  EXPECT_EQ(cv::norm(a, SimulatedDepthNoiseField(o, 0), cv::NORM_INF), 0.0);  // a pure function of the draw
  auto rig = CreateSimulatedRig(o);
  ASSERT_TRUE(rig.ok());
  Stage& stage = (*rig)->stage();
  EXPECT_EQ(SimulatedNoiseDraw(**rig), 0);
  ASSERT_TRUE(stage.MoveTo(190).ok());  // up: the same scan
  ASSERT_TRUE(stage.MoveTo(200).ok());
  EXPECT_EQ(SimulatedNoiseDraw(**rig), 0);
  ASSERT_TRUE(stage.MoveTo(180).ok());  // down: the next scan starts
  EXPECT_EQ(SimulatedNoiseDraw(**rig), 1);
}

}  // namespace
}  // namespace inspection
