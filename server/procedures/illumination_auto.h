// Automatic illumination (ILLUMINATION_MODE_AUTO): one probe capture under STD's uniform
// pattern in the middle of the scan range decides between STD, TEXTURE, ADAPT and HF+ADAPT from
// the measured saturation and texture contrast and from which calibration models exist. The
// rule and its evidence: docs/automatic-scans.md "Automatic illumination".
#pragma once

#include <string>

#include "core/calibration/calibration_bundle.h"
#include "core/io/frame_statistics.h"
#include "core/util/status.h"
#include "server/procedures/illumination_strategy.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {

// Which modes the active calibration (and the focus window, for the checkerboard period of
// eq. 5.15) allows.
struct IlluminationAvailability {
  bool texture = false;   // projector response, geometry, PSF and a period that fits the window
  bool adapt = false;     // camera and projector response, scatter matrix
  bool hf_adapt = false;  // both of the above
};
IlluminationAvailability AvailableIlluminationModes(const CalibrationBundle* bundle, int window_px);

struct IlluminationChoice {
  IlluminationMode mode = IlluminationMode::kStd;
  FrameStatistics probe;  // the probe capture's statistics
  std::string reasons;    // one line for the job result and stack.json
};

// Saturation above which a part needs compensation: 1 % of the pixels at the sensor maximum.
// Textured parts clip their brightest texture peaks (0.04-0.46 % of the probe on the simulated
// plane, skew, step and wedge specimens, which STD measures completely); shiny parts clip their
// glints and lands (cutter 20 %, coin 33 %), which costs STD a quarter of the depth map. The limit
// sits in that gap with a factor >= 2 to either side (docs/automatic-scans.md "Automatic illumination").
inline constexpr double kAutoSaturatedPercent = 1.0;

// The rule (no device I/O):
//   saturated > kAutoSaturatedPercent -> HF+ADAPT (compensation plus texture), else ADAPT,
//                                       else STD (no compensation models);
//   otherwise                         -> TEXTURE (the projected checkerboard adds texture at no
//                                       cost in frames; it measured better than STD on every
//                                       non-saturating specimen), else STD.
IlluminationChoice DecideIllumination(const FrameStatistics& probe, const IlluminationAvailability& available);

// Captures the probe (raw/frame_<mid>_probe0.png: the plan's middle z, STD's uniform grey at
// the plan's exposure) and decides. The caller shows the chosen mode's patterns afterwards.
StatusOr<IlluminationChoice> ProbeAndChooseIllumination(ScanCaptureContext& rig, const ScanPlan& plan,
                                                        const CalibrationBundle* bundle,
                                                        const IlluminationSetup& setup);

}  // namespace inspection
