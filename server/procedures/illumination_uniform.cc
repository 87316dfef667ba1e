// STD (thesis 6.2, Table 6.3): the projector shows one uniform grey (ScanPlan::uniform_grey) for
// the whole scan and every z gets one capture at the plan's exposure.
#include <string>

#include "server/procedures/illumination_families.h"

namespace inspection {
namespace {

class UniformIllumination : public IlluminationStrategy {
 public:
  UniformIllumination(const ScanPlan& plan, const IlluminationSetup& setup)
      : plan_(plan), setup_(setup), pattern_name_("uniform:" + std::to_string(plan.uniform_grey)) {}

  int stack_bit_depth() const override { return setup_.camera_bit_depth; }

  Status Prepare(ScanCaptureContext& rig) override {
    return rig.ShowPattern(cv::Mat(setup_.projector_size, CV_8UC1, cv::Scalar(plan_.uniform_grey)));
  }

  StatusOr<CapturedStackFrame> CaptureStackFrame(int i, ScanCaptureContext& rig) override {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, rig.Capture(i, cv::Mat(), plan_.exposure_us, CaptureRole::kStackFrame, ""));
    return CapturedStackFrame{f, plan_.exposure_us, pattern_name_};
  }

 private:
  const ScanPlan& plan_;
  const IlluminationSetup setup_;
  const std::string pattern_name_;
};

}  // namespace

std::unique_ptr<IlluminationStrategy> MakeUniformIllumination(const ScanPlan& plan, const IlluminationSetup& setup) {
  return std::make_unique<UniformIllumination>(plan, setup);
}

}  // namespace inspection
