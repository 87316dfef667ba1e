// High-frequency texture projection (thesis 5.2-5.3): TEXTURE shows the checkerboard of eq. 5.16
// at the period of eq. 5.15 for the whole scan; the combinations with compensation use the same
// period: HF+ADAPT adds the modified checkerboard to the adapted pattern (eq. 5.17-5.18),
// ADAPTED-HF compensates towards a checkerboard camera image (5.3.2).
#include <string>

#include "core/illumination/texture_pattern.h"
#include "server/procedures/illumination_families.h"

namespace inspection {
namespace {

// Eq. 5.15: the checkerboard period from sigma_p, the projector-to-camera ratio and the window.
StatusOr<TexturePeriod> PlanTexturePeriod(const ScanPlan& plan, const CalibrationBundle& bundle) {
  auto p = ChooseTexturePeriod(bundle.psf->influence_radius_px, bundle.geometry->camera_px_per_projector_px,
                               plan.sff.window_px);
  if (!p.ok()) return p.status().WithContext("sff window_px " + std::to_string(plan.sff.window_px));
  return *p;
}

// 8-bit grey units -> the camera's grey levels.
double LevelScale(const IlluminationSetup& setup) { return double(1 << setup.camera_bit_depth) / 256.0; }

class TextureIllumination : public IlluminationStrategy {
 public:
  TextureIllumination(const ScanPlan& plan, const CalibrationBundle& bundle, const IlluminationSetup& setup)
      : plan_(plan), bundle_(bundle), setup_(setup) {}

  int stack_bit_depth() const override { return setup_.camera_bit_depth; }

  Status Prepare(ScanCaptureContext& rig) override {
    INSPECT_ASSIGN_OR_RETURN(TexturePeriod period, PlanTexturePeriod(plan_, bundle_));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat pattern,
                             MakeHfPattern(setup_.projector_size, period.cell_projector_px, plan_.params.gamma));
    pattern_name_ =
        "checkerboard:" + std::to_string(period.cell_projector_px) + ":gamma=" + std::to_string(plan_.params.gamma);
    // Same mean projector irradiance as STD's uniform pattern: the exposure is scaled by
    // prf(uniform) / mean prf(checkerboard), so the mean grey stays near STD's.
    const ProjectorResponseFunction& pr = *bundle_.projector_response;
    exposure_us_ = plan_.exposure_us * (pr.Irradiance(plan_.uniform_grey) / cv::mean(pr.IrradianceImage(pattern))[0]);
    return rig.ShowPattern(pattern);
  }

  StatusOr<CapturedStackFrame> CaptureStackFrame(int i, ScanCaptureContext& rig) override {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, rig.Capture(i, cv::Mat(), exposure_us_, CaptureRole::kStackFrame, ""));
    return CapturedStackFrame{f, exposure_us_, pattern_name_};
  }

 private:
  const ScanPlan& plan_;
  const CalibrationBundle& bundle_;
  const IlluminationSetup setup_;
  double exposure_us_ = 0.0;
  std::string pattern_name_;
};

}  // namespace

std::unique_ptr<IlluminationStrategy> MakeTextureIllumination(const ScanPlan& plan, const CalibrationBundle& bundle,
                                                              const IlluminationSetup& setup) {
  return std::make_unique<TextureIllumination>(plan, bundle, setup);
}

CompensationTargetFactory HfAdaptTarget(const ScanPlan& plan, const CalibrationBundle& bundle,
                                        const IlluminationSetup& setup) {
  return [&plan, &bundle, setup]() -> StatusOr<CompensationTarget> {
    INSPECT_ASSIGN_OR_RETURN(TexturePeriod period, PlanTexturePeriod(plan, bundle));
    CompensationTarget t;
    t.options = plan.params.compensation;
    // The reflectance estimate averages over one checkerboard period (core/illumination/compensation.h).
    t.options.texture_period_camera_px = 2.0 * period.half_period_camera_px;
    t.desired_grey = cv::Mat(setup.camera_size, CV_32FC1, cv::Scalar(plan.params.target_grey * LevelScale(setup)));
    t.added_checkerboard = CheckerboardMask(setup.projector_size, period.cell_projector_px);
    t.psi = plan.params.psi;
    return t;
  };
}

CompensationTargetFactory AdaptedHfTarget(const ScanPlan& plan, const CalibrationBundle& bundle,
                                          const IlluminationSetup& setup) {
  return [&plan, &bundle, setup]() -> StatusOr<CompensationTarget> {
    INSPECT_ASSIGN_OR_RETURN(TexturePeriod period, PlanTexturePeriod(plan, bundle));
    CompensationTarget t;
    // The desired image holds the checkerboard itself, so the solve runs at full resolution
    // (no low-pass grid, no camera bins).
    t.options = plan.params.compensation;
    t.options.pattern_cell_px = 1;
    t.options.camera_bin_px = 1;
    t.options.texture_period_camera_px = 2.0 * period.half_period_camera_px;
    const double level_scale = LevelScale(setup);
    // Thesis: 25 % / 75 % of full scale, 60 and 190 for 8 bit.
    t.desired_grey =
        CameraCheckerboard(setup.camera_size, period.half_period_camera_px, 60.0 * level_scale, 190.0 * level_scale);
    return t;
  };
}

}  // namespace inspection
