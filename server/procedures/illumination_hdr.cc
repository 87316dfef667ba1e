// HDR-n (thesis 3.5, Table 6.2): under STD's uniform grey, n exposures per z at the relative
// times of Table 6.2, merged with the calibrated camera response to ln E (eq. 3.44) and mapped to
// a 16-bit stack frame. The exposures themselves are kept under raw/.
#include <cmath>
#include <string>
#include <vector>

#include "core/calibration/camera_response.h"
#include "server/procedures/illumination_families.h"

namespace inspection {
namespace {

// Merged radiance -> 16 bit for the engine. The mapping is logarithmic: eq. 3.44 yields ln E,
// and a focus measure on ln E responds to relative contrast, so a glint tens of times the
// surrounding metal and the dark metal beside it both keep their texture. (A linear mapping lets
// the defocused halo of a glint out-gradient the in-focus texture next to it; a sensor that sees
// the scene once cannot do better than the camera's own grey levels.) 0 is the radiance of level
// 1 at the longest exposure, 65535 the radiance that saturates the shortest one.
cv::Mat RadianceTo16(const cv::Mat& radiance, double lo, double hi) {
  cv::Mat log_e;
  cv::log(cv::max(radiance, lo), log_e);
  cv::Mat out;
  const double scale = 65535.0 / (std::log(hi) - std::log(lo));
  log_e.convertTo(out, CV_16UC1, scale, -std::log(lo) * scale);
  return out;
}

class HdrIllumination : public IlluminationStrategy {
 public:
  HdrIllumination(const ScanPlan& plan, const CalibrationBundle& bundle, const IlluminationSetup& setup)
      : plan_(plan), crf_(*bundle.camera_response), setup_(setup) {}

  int stack_bit_depth() const override { return 16; }

  Status Prepare(ScanCaptureContext& rig) override {
    INSPECT_ASSIGN_OR_RETURN(std::vector<double> rel, HdrRelativeExposures(plan_.params.hdr_exposures));
    for (double r : rel) exposures_us_.push_back(r * plan_.exposure_us);
    const int top = (1 << setup_.camera_bit_depth) - 1;
    hi_ = std::exp(crf_.LogExposure(top)) / exposures_us_.front();
    lo_ = std::exp(crf_.LogExposure(1)) / exposures_us_.back();
    pattern_name_ =
        "uniform:" + std::to_string(plan_.uniform_grey) + ":hdr" + std::to_string(plan_.params.hdr_exposures);
    return rig.ShowPattern(cv::Mat(setup_.projector_size, CV_8UC1, cv::Scalar(plan_.uniform_grey)));
  }

  StatusOr<CapturedStackFrame> CaptureStackFrame(int i, ScanCaptureContext& rig) override {
    std::vector<cv::Mat> frames;
    for (size_t k = 0; k < exposures_us_.size(); ++k) {
      INSPECT_ASSIGN_OR_RETURN(
          cv::Mat f, rig.Capture(i, cv::Mat(), exposures_us_[k], CaptureRole::kRawFrame, RawFrameName(i, "e", int(k))));
      frames.push_back(f);
    }
    INSPECT_ASSIGN_OR_RETURN(cv::Mat e, MergeRadiance(frames, exposures_us_, crf_));  // eq. 3.44
    return CapturedStackFrame{RadianceTo16(e, lo_, hi_), 0.0, pattern_name_};
  }

 private:
  const ScanPlan& plan_;
  const CameraResponseFunction& crf_;
  const IlluminationSetup setup_;
  std::vector<double> exposures_us_;  // Table 6.2 times the plan's exposure, shortest first
  double lo_ = 0, hi_ = 0;            // radiance range of RadianceTo16
  std::string pattern_name_;
};

}  // namespace

std::unique_ptr<IlluminationStrategy> MakeHdrIllumination(const ScanPlan& plan, const CalibrationBundle& bundle,
                                                          const IlluminationSetup& setup) {
  return std::make_unique<HdrIllumination>(plan, bundle, setup);
}

}  // namespace inspection
