// ADAPT, predictive adaptive illumination (thesis 5.1.3): two initialisation frames at the first
// z, then per z one capture under the predicted pattern (eq. 5.12) and one correction (eq. 5.5,
// 5.6, 5.11). Also the compensation loop the ADAPT family shares, and the uniform target.
#include "core/calibration/projector_response.h"
#include "core/illumination/texture_pattern.h"
#include "server/procedures/illumination_families.h"

namespace inspection {

Status AdaptiveCompensation::Init(const CalibrationBundle& bundle, const CompensationTargetFactory& target) {
  INSPECT_ASSIGN_OR_RETURN(target_, target());
  INSPECT_ASSIGN_OR_RETURN(compensator_, Compensator::Create(*bundle.camera_response, *bundle.projector_response,
                                                             *bundle.scatter, target_.options));
  prf_ = &*bundle.projector_response;
  return Status::Ok();
}

StatusOr<cv::Mat> AdaptiveCompensation::Shown(const cv::Mat& irradiance) const {
  if (!target_.added_checkerboard.empty()) {
    // Eq. 5.17-5.18 around the adapted irradiance, so the checkerboard adds texture, not light.
    return AddHfPatternToIrradiance(irradiance, target_.added_checkerboard, target_.psi, *prf_);
  }
  return compensator_->PatternFor(irradiance);
}

StatusOr<CompensationStep> AdaptiveCompensation::Correct(const cv::Mat& pattern, const cv::Mat& frame,
                                                         double exposure_us, const cv::Mat& warm_start,
                                                         ShownAt shown_at) const {
  return compensator_->Step(prf_->IrradianceImage(pattern), frame, exposure_us, target_.desired_grey, warm_start,
                            shown_at);
}

CompensationTargetFactory UniformGreyTarget(const ScanPlan& plan, const IlluminationSetup& setup) {
  return [&plan, setup]() -> StatusOr<CompensationTarget> {
    CompensationTarget t;
    t.options = plan.params.compensation;
    const double level_scale = double(1 << setup.camera_bit_depth) / 256.0;
    t.desired_grey = cv::Mat(setup.camera_size, CV_32FC1, cv::Scalar(plan.params.target_grey * level_scale));
    return t;
  };
}

namespace {

class PredictiveAdaptIllumination : public IlluminationStrategy {
 public:
  PredictiveAdaptIllumination(const ScanPlan& plan, const CalibrationBundle& bundle, const IlluminationSetup& setup,
                              CompensationTargetFactory target)
      : plan_(plan), bundle_(bundle), setup_(setup), target_(std::move(target)) {}

  int stack_bit_depth() const override { return setup_.camera_bit_depth; }

  Status Prepare(ScanCaptureContext& rig) override {
    INSPECT_RETURN_IF_ERROR(comp_.Init(bundle_, target_));
    INSPECT_RETURN_IF_ERROR(rig.MoveStageTo(0));
    const cv::Mat uniform(setup_.projector_size, CV_8UC1, cv::Scalar(plan_.uniform_grey));
    irr_next_ = comp_.prf().IrradianceImage(uniform);
    // Two initialisation frames at the first z (thesis 5.1.3): uniform, then once corrected.
    // Their corrections light the first z again (the second one its stack frame).
    for (int k = 0; k < 2; ++k) {
      INSPECT_ASSIGN_OR_RETURN(cv::Mat p, k == 0 ? StatusOr<cv::Mat>(uniform) : comp_.Shown(irr_next_));
      INSPECT_ASSIGN_OR_RETURN(
          cv::Mat f, rig.Capture(0, p, plan_.exposure_us, CaptureRole::kRawFrame, RawFrameName(0, "init", k)));
      INSPECT_ASSIGN_OR_RETURN(CompensationStep st, comp_.Correct(p, f, plan_.exposure_us, irr_next_, ShownAt::kSameZ));
      irr_next_ = st.projector_irradiance;
    }
    return Status::Ok();
  }

  // Shows the prediction, captures the stack frame, corrects once and predicts the next z. The
  // correction lights the next z, so it must not depend on how focused this frame is.
  StatusOr<CapturedStackFrame> CaptureStackFrame(int i, ScanCaptureContext& rig) override {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat pattern, comp_.Shown(irr_next_));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, rig.Capture(i, pattern, plan_.exposure_us, CaptureRole::kStackFrame, ""));
    INSPECT_ASSIGN_OR_RETURN(CompensationStep st,
                             comp_.Correct(pattern, frame, plan_.exposure_us, irr_next_, ShownAt::kNextZ));
    irr_prev_ = irr_cur_.empty() ? st.projector_irradiance : irr_cur_;
    irr_cur_ = st.projector_irradiance;
    INSPECT_ASSIGN_OR_RETURN(irr_next_, PredictIrradiance(irr_cur_, irr_prev_, plan_.params.lambda,
                                                          comp_.prf().relative_irradiance[0]));  // eq. 5.12
    return CapturedStackFrame{frame, plan_.exposure_us, "adapted"};
  }

 private:
  const ScanPlan& plan_;
  const CalibrationBundle& bundle_;
  const IlluminationSetup setup_;
  const CompensationTargetFactory target_;
  AdaptiveCompensation comp_;
  // Corrected projector irradiances of z_i and z_i-1, and the prediction for the next capture.
  cv::Mat irr_cur_, irr_prev_, irr_next_;
};

}  // namespace

std::unique_ptr<IlluminationStrategy> MakePredictiveAdaptIllumination(const ScanPlan& plan,
                                                                      const CalibrationBundle& bundle,
                                                                      const IlluminationSetup& setup,
                                                                      CompensationTargetFactory target) {
  return std::make_unique<PredictiveAdaptIllumination>(plan, bundle, setup, std::move(target));
}

}  // namespace inspection
