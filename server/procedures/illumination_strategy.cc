// Picks the illumination strategy of a scan's mode (thesis 5, 6.2); see illumination_strategy.h.
#include "server/procedures/illumination_strategy.h"

#include <cstdio>

#include "server/procedures/illumination_families.h"

namespace inspection {

std::unique_ptr<IlluminationStrategy> CreateIlluminationStrategy(const ScanPlan& plan, const CalibrationBundle* bundle,
                                                                 const IlluminationSetup& setup) {
  switch (plan.mode) {
    case IlluminationMode::kStd:
    case IlluminationMode::kAuto:  // resolved to a concrete mode before (illumination_auto.h)
      break;
    case IlluminationMode::kHdr:
      return MakeHdrIllumination(plan, *bundle, setup);
    case IlluminationMode::kAdaptIterative:
      return MakeIterativeAdaptIllumination(plan, *bundle, setup, UniformGreyTarget(plan, setup));
    case IlluminationMode::kAdapt:
      return MakePredictiveAdaptIllumination(plan, *bundle, setup, UniformGreyTarget(plan, setup));
    case IlluminationMode::kTexture:
      return MakeTextureIllumination(plan, *bundle, setup);
    case IlluminationMode::kHfAdapt:
      return MakePredictiveAdaptIllumination(plan, *bundle, setup, HfAdaptTarget(plan, *bundle, setup));
    case IlluminationMode::kAdaptedHf:
      return MakePredictiveAdaptIllumination(plan, *bundle, setup, AdaptedHfTarget(plan, *bundle, setup));
  }
  return MakeUniformIllumination(plan, setup);
}

std::string RawFrameName(int i, const char* what, int k) {
  char name[48];
  std::snprintf(name, sizeof(name), "frame_%04d_%s%d.png", i, what, k);
  return std::string(name);
}

}  // namespace inspection
