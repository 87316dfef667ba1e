// The simulated rig's ground-truth texture (SimulationControl::GroundTruthTexture, ISFF-GT's
// template, thesis 6.4.3): on the plane normal to the axis, a noise-free rig's in-focus capture
// is that texture exactly; on the tilted plane it is sharper than any capture, and the rig's own
// frames and noise are untouched by rendering it.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "devices/sim/simulated_rig.h"

namespace inspection {
namespace {

SimulatedRigOptions Small(const std::string& specimen, bool noise) {
  SimulatedRigOptions o;
  o.specimen = specimen;
  o.camera_size = {256, 192};
  o.projector_size = {72, 92};
  o.stage_repeatability_um = 0.0;
  if (!noise) {
    o.read_noise_dn = 0.0;
    o.shot_noise = false;
  }
  return o;
}

cv::Mat Uniform(Rig& rig, int grey) { return cv::Mat(rig.projector().resolution(), CV_8UC1, cv::Scalar(grey)); }

double GradientEnergy(const cv::Mat& img) {
  cv::Mat gx, gy;
  cv::Sobel(img, gx, CV_32F, 1, 0);
  cv::Sobel(img, gy, CV_32F, 0, 1);
  return cv::mean(gx.mul(gx) + gy.mul(gy))[0];
}

TEST(SimGroundTruthTextureTest, EqualsTheNoiseFreeInFocusFrameOfThePlane) {
  auto rig = CreateSimulatedRig(Small("plane", false));
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  Rig& r = **rig;
  double lo = 0, hi = 0;
  cv::minMaxLoc(r.simulation()->GroundTruthDepthUm(), &lo, &hi);
  ASSERT_DOUBLE_EQ(lo, hi);  // normal to the axis: one height
  ASSERT_TRUE(r.stage().MoveTo(lo).ok());
  auto frame = r.camera().Capture();
  ASSERT_TRUE(frame.ok());
  auto texture = r.simulation()->GroundTruthTexture(Uniform(r, 128), r.camera().exposure_us());
  ASSERT_TRUE(texture.ok()) << texture.status().ToString();
  ASSERT_EQ(texture->type(), frame->type());
  ASSERT_EQ(texture->size(), frame->size());
  EXPECT_EQ(cv::norm(*texture, *frame, cv::NORM_INF), 0.0);
  cv::Scalar mean, sd;
  cv::meanStdDev(*texture, mean, sd);
  EXPECT_GT(sd[0], 5.0);  // textured, not a flat grey

  EXPECT_EQ(r.simulation()->GroundTruthTexture(cv::Mat(3, 3, CV_8UC1), 1000.0).status().code(),
            StatusCode::kInvalidArgument);
}

TEST(SimGroundTruthTextureTest, SharperThanAnyFrameOfTheTiltedPlaneAndLeavesTheRigAlone) {
  auto rig = CreateSimulatedRig(Small("skew5", true));
  auto twin = CreateSimulatedRig(Small("skew5", true));
  ASSERT_TRUE(rig.ok() && twin.ok());
  Rig& r = **rig;
  const ScanDefaults d = r.scan_defaults();
  auto texture = r.simulation()->GroundTruthTexture(Uniform(r, 128), d.exposure_us);
  ASSERT_TRUE(texture.ok()) << texture.status().ToString();
  const double texture_energy = GradientEnergy(*texture);
  for (double z = d.z_start_um; z <= d.z_end_um + 1e-9; z += d.z_step_um) {
    ASSERT_TRUE(r.stage().MoveTo(z).ok());
    ASSERT_TRUE((*twin)->stage().MoveTo(z).ok());
    auto f = r.camera().Capture();
    auto g = (*twin)->camera().Capture();
    ASSERT_TRUE(f.ok() && g.ok());
    // The same frame as a twin rig that never rendered the texture: same noise draws.
    EXPECT_EQ(cv::norm(*f, *g, cv::NORM_INF), 0.0) << "z " << z;
    // A tilted plane is in focus on one line per frame only; noise adds less than the blur takes.
    EXPECT_LT(GradientEnergy(*f), texture_energy) << "z " << z;
  }
}

}  // namespace
}  // namespace inspection
