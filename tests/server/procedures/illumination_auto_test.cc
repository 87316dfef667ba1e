// The decision rule of ILLUMINATION_MODE_AUTO (server/procedures/illumination_auto.h) on probe
// statistics, for every combination of available calibration models.
#include "server/procedures/illumination_auto.h"

#include <gtest/gtest.h>

namespace inspection {
namespace {

FrameStatistics Probe(double saturated_percent) {
  FrameStatistics s;
  s.mean_grey = 120.0;
  s.stddev_grey = 30.0;
  s.saturated_percent = saturated_percent;
  return s;
}

TEST(IlluminationAutoTest, SaturationChoosesCompensationAsFarAsTheCalibrationAllows) {
  const IlluminationAvailability all{true, true, true}, adapt_only{false, true, false},
      texture_only{true, false, false}, none{};
  const FrameStatistics glints = Probe(2.5);
  EXPECT_EQ(DecideIllumination(glints, all).mode, IlluminationMode::kHfAdapt);
  EXPECT_EQ(DecideIllumination(glints, adapt_only).mode, IlluminationMode::kAdapt);
  EXPECT_EQ(DecideIllumination(glints, texture_only).mode, IlluminationMode::kStd);
  EXPECT_EQ(DecideIllumination(glints, none).mode, IlluminationMode::kStd);
}

TEST(IlluminationAutoTest, NoSaturationChoosesTheProjectedTexture) {
  const IlluminationAvailability all{true, true, true}, adapt_only{false, true, false};
  EXPECT_EQ(DecideIllumination(Probe(0.0), all).mode, IlluminationMode::kTexture);
  EXPECT_EQ(DecideIllumination(Probe(0.0), adapt_only).mode, IlluminationMode::kStd);
  // The limit itself is not saturation; just above it is.
  EXPECT_EQ(DecideIllumination(Probe(kAutoSaturatedPercent), all).mode, IlluminationMode::kTexture);
  EXPECT_EQ(DecideIllumination(Probe(kAutoSaturatedPercent * 1.01), all).mode, IlluminationMode::kHfAdapt);
}

TEST(IlluminationAutoTest, ReasonsNameTheModeAndTheMeasuredFigures) {
  const IlluminationChoice c = DecideIllumination(Probe(2.5), {true, true, true});
  EXPECT_EQ(c.reasons,
            "AUTO -> HF+ADAPT: saturation: compensation with added texture (probe: 2.500 % saturated, limit 1.00 %; "
            "mean grey 120.0, contrast 0.250)");
  EXPECT_EQ(c.probe.saturated_percent, 2.5);
  EXPECT_EQ(IlluminationModeName(IlluminationMode::kAuto), "AUTO");
}

}  // namespace
}  // namespace inspection
