// ADAPT-IT, iterative adaptive illumination (thesis 5.1.2, 6.1.2): at every z, eq. 5.5-5.6 and
// 5.11 are repeated, starting from the previous z's pattern, until the camera image is within
// tolerance of the target, stops improving, or max_iterations captures were taken. The last
// capture is the stack frame; every iteration is kept under raw/.
#include <limits>

#include "core/calibration/projector_response.h"
#include "server/procedures/illumination_families.h"

namespace inspection {
namespace {

class IterativeAdaptIllumination : public IlluminationStrategy {
 public:
  IterativeAdaptIllumination(const ScanPlan& plan, const CalibrationBundle& bundle, const IlluminationSetup& setup,
                             CompensationTargetFactory target)
      : plan_(plan), bundle_(bundle), setup_(setup), target_(std::move(target)) {}

  int stack_bit_depth() const override { return setup_.camera_bit_depth; }

  Status Prepare(ScanCaptureContext& rig) override {
    INSPECT_RETURN_IF_ERROR(comp_.Init(bundle_, target_));
    INSPECT_RETURN_IF_ERROR(rig.MoveStageTo(0));
    irr_next_ = comp_.prf().IrradianceImage(cv::Mat(setup_.projector_size, CV_8UC1, cv::Scalar(plan_.uniform_grey)));
    return Status::Ok();
  }

  StatusOr<CapturedStackFrame> CaptureStackFrame(int i, ScanCaptureContext& rig) override {
    const IlluminationParams& prm = plan_.params;
    const double level_scale = double(1 << setup_.camera_bit_depth) / 256.0;
    cv::Mat irr = irr_next_, frame, pattern;
    double last_err = std::numeric_limits<double>::infinity();
    for (int k = 0;; ++k) {
      INSPECT_ASSIGN_OR_RETURN(pattern, comp_.Shown(irr));
      INSPECT_ASSIGN_OR_RETURN(
          frame, rig.Capture(i, pattern, plan_.exposure_us, CaptureRole::kUndecided, RawFrameName(i, "it", k)));
      // Each iteration's correction lights this z again: the thesis's per-pixel estimate.
      INSPECT_ASSIGN_OR_RETURN(CompensationStep st,
                               comp_.Correct(pattern, frame, plan_.exposure_us, irr, ShownAt::kSameZ));
      const double err = st.mean_abs_error_grey / level_scale;
      const bool done =
          k + 1 >= prm.max_iterations || err < prm.tolerance_grey || err > last_err * (1.0 - prm.min_improvement);
      last_err = err;
      rig.DecideLastCapture(done);
      if (done) break;
      irr = st.projector_irradiance;
    }
    // The next z starts from the pattern that made this z's stack frame.
    irr_next_ = irr;
    return CapturedStackFrame{frame, plan_.exposure_us, "adapted"};
  }

 private:
  const ScanPlan& plan_;
  const CalibrationBundle& bundle_;
  const IlluminationSetup setup_;
  const CompensationTargetFactory target_;
  AdaptiveCompensation comp_;
  cv::Mat irr_next_;  // adapted projector irradiance the next z starts from
};

}  // namespace

std::unique_ptr<IlluminationStrategy> MakeIterativeAdaptIllumination(const ScanPlan& plan,
                                                                     const CalibrationBundle& bundle,
                                                                     const IlluminationSetup& setup,
                                                                     CompensationTargetFactory target) {
  return std::make_unique<IterativeAdaptIllumination>(plan, bundle, setup, std::move(target));
}

}  // namespace inspection
