// Simulated rig: a physically based projector-camera-stage model with ground truth (thesis
// 5.1.1, Fig. 5.2). The default rig of inspectd and of every test.
//
// Image formation per frame (each step its own tested piece in devices/sim/):
//   projector pattern Z_p -> projector response prf (eq. 5.1) -> geometric mapping to the
//   camera -> defocus by |height - z| -> reflectance R and texture (eq. 5.2) -> defocus again
//   -> exposure (eq. 5.3) -> camera response, quantisation, saturation, noise (eq. 5.4).
// Depth convention: a surface point of height h_um is in focus when the stage is at z_um = h_um.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/status.h"
#include "devices/rig.h"
#include "devices/sim/image_formation.h"

namespace inspection {

struct SimulatedRigOptions {
  std::string specimen = "skew5";   // built-in name or "file:/path/to/scene.json"
  uint64_t seed = 1;                // every random draw derives from it: runs are repeatable
  cv::Size camera_size{1024, 768};  // camera pixels
  int camera_bit_depth = 8;         // 8 or 12
  cv::Size projector_size{1280, 720};
  double pixel_size_um = 0.74;      // camera pixel on the specimen (thesis 6: 0.740 µm)
  double stage_repeatability_um = 0.1;  // ±, uniform (thesis 6: ±0.1 µm)
  double read_noise_dn = 0.8;       // camera read noise, in output grey levels (8-bit scale)
  bool shot_noise = true;

  Status Validate() const;
};

// Thread-compatible: the server's job worker is its only user at a time.
// The camera starts at the specimen's default exposure (scan_defaults().exposure_us), the
// projector shows uniform grey 128, the stage is homed at z = 0. Stage travel: 0 .. 25000 um.
// SimulationControl::SetSpecimen also resets the camera exposure to the new default.
StatusOr<std::unique_ptr<Rig>> CreateSimulatedRig(const SimulatedRigOptions& options);

// The renderer settings the simulated rig uses for these options (for serving the same frames
// elsewhere, e.g. over GigE Vision: build an ImageFormation from them and MakeSpecimen).
StatusOr<ImageFormationOptions> ImageFormationOptionsFor(const SimulatedRigOptions& options);

// Scan defaults for a specimen z range: the range with 4 steps of margin each side, 5 um steps.
ScanDefaults ScanDefaultsFor(std::pair<double, double> z_range_um, double exposure_us);

}  // namespace inspection
