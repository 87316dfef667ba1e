// Automatic illumination: a probe capture and the decision rule of illumination_auto.h.
#include "server/procedures/illumination_auto.h"

#include <cstdio>

#include "core/illumination/texture_pattern.h"

namespace inspection {

IlluminationAvailability AvailableIlluminationModes(const CalibrationBundle* bundle, int window_px) {
  IlluminationAvailability a;
  if (bundle == nullptr) return a;
  a.adapt = CheckCalibrationFor(IlluminationMode::kAdapt, bundle).ok();
  a.texture =
      CheckCalibrationFor(IlluminationMode::kTexture, bundle).ok() &&
      ChooseTexturePeriod(bundle->psf->influence_radius_px, bundle->geometry->camera_px_per_projector_px, window_px)
          .ok();
  a.hf_adapt = a.adapt && a.texture;
  return a;
}

IlluminationChoice DecideIllumination(const FrameStatistics& probe, const IlluminationAvailability& available) {
  IlluminationChoice c;
  c.probe = probe;
  const bool saturating = probe.saturated_percent > kAutoSaturatedPercent;
  const char* why;
  if (saturating) {
    if (available.hf_adapt) {
      c.mode = IlluminationMode::kHfAdapt;
      why = "saturation: compensation with added texture";
    } else if (available.adapt) {
      c.mode = IlluminationMode::kAdapt;
      why = "saturation: compensation (no texture models)";
    } else {
      c.mode = IlluminationMode::kStd;
      why = "saturation, but no compensation models in the calibration";
    }
  } else if (available.texture) {
    c.mode = IlluminationMode::kTexture;
    why = "no saturation: projected texture";
  } else {
    c.mode = IlluminationMode::kStd;
    why = "no saturation and no texture models in the calibration";
  }
  char buf[256];
  std::snprintf(buf, sizeof(buf),
                "AUTO -> %s: %s (probe: %.3f %% saturated, limit %.2f %%; mean grey %.1f, contrast %.3f)",
                IlluminationModeName(c.mode).c_str(), why, probe.saturated_percent, kAutoSaturatedPercent,
                probe.mean_grey, probe.mean_grey > 0 ? probe.stddev_grey / probe.mean_grey : 0.0);
  c.reasons = buf;
  return c;
}

StatusOr<IlluminationChoice> ProbeAndChooseIllumination(ScanCaptureContext& rig, const ScanPlan& plan,
                                                        const CalibrationBundle* bundle,
                                                        const IlluminationSetup& setup) {
  const int mid = int(plan.z_um.size()) / 2;
  INSPECT_RETURN_IF_ERROR(rig.MoveStageTo(mid));
  const cv::Mat uniform(setup.projector_size, CV_8UC1, cv::Scalar(plan.uniform_grey));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, rig.Capture(mid, uniform, plan.exposure_us, CaptureRole::kRawFrame,
                                                      RawFrameName(mid, "probe", 0)));
  return DecideIllumination(ComputeFrameStatistics(frame, setup.camera_bit_depth),
                            AvailableIlluminationModes(bundle, plan.sff.window_px));
}

}  // namespace inspection
