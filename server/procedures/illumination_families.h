// Internal to the illumination strategies (illumination_*.cc): one constructor per mode family,
// and the compensation state the ADAPT family shares (thesis 5.1: eq. 5.5-5.6, 5.11, 5.12;
// 5.3: the checkerboard added to, or used as the target of, the adapted pattern).
#pragma once

#include <functional>
#include <memory>
#include <opencv2/core.hpp>

#include "core/illumination/compensation.h"
#include "server/procedures/illumination_strategy.h"

namespace inspection {

std::unique_ptr<IlluminationStrategy> MakeUniformIllumination(const ScanPlan& plan,
                                                              const IlluminationSetup& setup);  // STD
std::unique_ptr<IlluminationStrategy> MakeHdrIllumination(const ScanPlan& plan, const CalibrationBundle& bundle,
                                                          const IlluminationSetup& setup);  // HDR-n
std::unique_ptr<IlluminationStrategy> MakeTextureIllumination(const ScanPlan& plan, const CalibrationBundle& bundle,
                                                              const IlluminationSetup& setup);  // TEXTURE

// What an ADAPT-family mode compensates towards and how it shows the solved irradiance.
struct CompensationTarget {
  CompensationOptions options;  // solver options (ADAPTED-HF: full resolution)
  cv::Mat desired_grey;         // CV_32FC1 camera size, camera grey levels
  // HF+ADAPT: the checkerboard of eq. 5.17 (CheckerboardMask) added to every shown pattern with
  // weight psi (eq. 5.18) around the adapted irradiance (AddHfPatternToIrradiance); else empty.
  cv::Mat added_checkerboard;
  double psi = 0.0;
};
// Built in Prepare, so the scan reports errors in the order the models are needed.
using CompensationTargetFactory = std::function<StatusOr<CompensationTarget>()>;

// ADAPT, ADAPT-IT: a uniform camera image at plan.params.target_grey.
CompensationTargetFactory UniformGreyTarget(const ScanPlan& plan, const IlluminationSetup& setup);
// HF+ADAPT (eq. 5.17-5.18) and ADAPTED-HF (5.3.2), in illumination_texture.cc.
CompensationTargetFactory HfAdaptTarget(const ScanPlan& plan, const CalibrationBundle& bundle,
                                        const IlluminationSetup& setup);
CompensationTargetFactory AdaptedHfTarget(const ScanPlan& plan, const CalibrationBundle& bundle,
                                          const IlluminationSetup& setup);

// Predictive ADAPT (5.1.3) and iterative ADAPT-IT (5.1.2) towards a target.
std::unique_ptr<IlluminationStrategy> MakePredictiveAdaptIllumination(const ScanPlan& plan,
                                                                      const CalibrationBundle& bundle,
                                                                      const IlluminationSetup& setup,
                                                                      CompensationTargetFactory target);
std::unique_ptr<IlluminationStrategy> MakeIterativeAdaptIllumination(const ScanPlan& plan,
                                                                     const CalibrationBundle& bundle,
                                                                     const IlluminationSetup& setup,
                                                                     CompensationTargetFactory target);

// The compensation loop both ADAPT strategies run: one Compensator for the scan, the target,
// and the projector response that turns shown patterns back into irradiance.
class AdaptiveCompensation {
 public:
  Status Init(const CalibrationBundle& bundle, const CompensationTargetFactory& target);
  // The pattern shown for an adapted projector irradiance (HF+ADAPT adds the checkerboard).
  StatusOr<cv::Mat> Shown(const cv::Mat& irradiance) const;
  // Eq. 5.5, 5.6, 5.11 on `frame`, captured while `pattern` was shown at exposure_us; the solve
  // starts from warm_start (the adapted irradiance without any added checkerboard). shown_at:
  // where the correction will be shown (core/illumination/compensation.h).
  StatusOr<CompensationStep> Correct(const cv::Mat& pattern, const cv::Mat& frame, double exposure_us,
                                     const cv::Mat& warm_start, ShownAt shown_at) const;
  const ProjectorResponseFunction& prf() const { return *prf_; }

 private:
  std::unique_ptr<Compensator> compensator_;
  CompensationTarget target_;
  const ProjectorResponseFunction* prf_ = nullptr;
};

}  // namespace inspection
