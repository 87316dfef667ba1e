// Simulated rig: a physically based projector-camera-stage model with ground truth (thesis
// 5.1.1, Fig. 5.2). The default rig of inspectd and of every test.
//
// Image formation per frame (each step its own tested piece in devices/sim/):
//   projector pattern Z_p -> projector response prf (eq. 5.1) -> geometric mapping to the
//   camera -> defocus by |height - z| -> reflectance R and texture (eq. 5.2) -> defocus again
//   -> exposure (eq. 5.3) -> camera response, quantisation, saturation, noise (eq. 5.4).
// Depth convention: a surface point of height h_um is in focus when the stage is at z_um = h_um.
// Specimens (devices/sim/specimen.h): plane, skew5, skew10, step1um, wedge, chamfer, cutter,
// lens, mirror, coin, or a user scene "file:/path/scene.json". Overview: devices/sim/README.md.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "core/util/status.h"
#include "devices/rig.h"
#include "devices/sim/image_formation.h"

namespace inspection {

struct SimulatedRigOptions {
  std::string specimen = "skew5";   // built-in name or "file:/path/to/scene.json"
  uint64_t seed = 1;                // every random draw derives from it: runs are repeatable
  cv::Size camera_size{1024, 768};  // camera pixels
  int camera_bit_depth = 8;         // 8 or 12
  cv::Size projector_size{1280, 720};
  double pixel_size_um = 0.74;          // camera pixel on the specimen (thesis 6: 0.740 µm)
  double numerical_aperture = 0.3;      // objective NA (10x): sets the defocus blur per µm
  // The image pass's defocus as each surface point's own PSF (DefocusModel::point_spread_imaging).
  bool point_spread_imaging = false;
  double stage_repeatability_um = 0.1;  // ±, uniform (thesis 6: ±0.1 µm)
  double read_noise_dn = 0.8;           // camera read noise, in output grey levels (8-bit scale)
  bool shot_noise = true;
  // Lateral optics (devices/sim/image_formation.h, LateralOptics): magnification change in % per
  // 100 um of stage z relative to breathing_reference_z_um, and lateral drift in camera px per
  // 100 um. 0 = none (the default): frames registered pixel for pixel.
  double focus_breathing_percent_per_100um = 0.0;
  double lateral_drift_x_px_per_100um = 0.0;
  double lateral_drift_y_px_per_100um = 0.0;
  double breathing_reference_z_um = 0.0;
  // Instrument errors (ISO 25178-600 characteristics) the optics really apply: every specimen
  // map is shown to the renderer as an instrument with these errors would see it, so depth maps
  // come out wrong the way a real rig's would. Ground truth (GroundTruthDepthUm) stays the
  // specimen's true surface. 0 = a perfect instrument (the default). See SimulatedOpticsErrors.
  double z_scale_error = 0.0;          // heights about z = 0 come out (1 + e) x true: alpha_z = 1 + e
  double lateral_scale_error_x = 0.0;  // lengths along x come out (1 + e) x true: alpha_x = 1 + e
  double lateral_scale_error_y = 0.0;
  double flatness_bow_um = 0.0;  // field curvature: + bow * (r / r_corner)^2, r from the centre
  // Extra depth noise: a random height field of this standard deviation (Gaussian, correlated
  // over extra_noise_correlation_px), drawn afresh for every scan (a move down of the stage
  // starts one: scans sweep upward) from (seed, draw number): SimulatedDepthNoiseField.
  double extra_noise_um = 0.0;
  double extra_noise_correlation_px = 3.0;
  bool material_measures = true;  // false: a rig without the ISO 25178-70 measures (none offered)

  Status Validate() const;
};

// The server's job worker is meant to be its only user at a time; still, every device and
// SimulationControl call takes one internal mutex, so e.g. SetSpecimen from an RPC thread never
// tears a frame being rendered (it waits for it).
// The camera starts at the specimen's default exposure (scan_defaults().exposure_us), the
// projector shows uniform grey 128, the stage is homed at z = 0. Stage travel: 0 .. 25000 um.
// SimulationControl::SetSpecimen also resets the camera exposure to the new default.
StatusOr<std::unique_ptr<Rig>> CreateSimulatedRig(const SimulatedRigOptions& options);

// Simulation-only fault injection, for tests of error handling (thesis rig failures: a camera
// unplugged, a frame lost, a stage stuck). Faults hold until replaced by another call
// (SetSimulatedFaults(rig, {}) = everything plugged back in).
struct SimulatedFaults {
  bool camera_unplugged = false;     // camera calls -> UNAVAILABLE, info().connected = false
  bool projector_unplugged = false;  // Show -> UNAVAILABLE
  bool stage_unplugged = false;      // MoveTo/Home/position_um -> UNAVAILABLE
  int camera_frame_timeouts = 0;     // the next N captures -> DEADLINE_EXCEEDED
  int stage_move_timeouts = 0;       // the next N moves -> DEADLINE_EXCEEDED (stage stays put)
};
// INVALID_ARGUMENT when rig is not a simulated rig.
Status SetSimulatedFaults(Rig& rig, const SimulatedFaults& faults);

// Where the part lies relative to where it was loaded: a lateral shift (um on the specimen, x
// right and y down in the camera image) and a height offset on top of SetSpecimenZOffsetUm's.
// Models a part taken off the stage and put back between repeated measurements (a Type-1
// gauge study). Kept across SetSpecimen; {} = as loaded (the default).
struct SimulatedPlacement {
  double dx_um = 0.0;
  double dy_um = 0.0;
  double dz_um = 0.0;
};
// INVALID_ARGUMENT when rig is neither a simulated rig nor one forwarding simulation() to one,
// when a value is not finite, or when the height offset leaves the stage travel (the placement
// is then unchanged).
Status SetSimulatedPlacement(Rig& rig, const SimulatedPlacement& placement);
// Draw number `draw` of a random placement: each component normal with standard deviation
// sigma_xy_um (dx, dy) or sigma_z_um (dz), a pure function of (seed, draw).
SimulatedPlacement RandomSimulatedPlacement(uint64_t seed, uint64_t draw, double sigma_xy_um, double sigma_z_um);

// SimulationControl::GroundTruthInCameraGridUm of a rig (devices/rig.h); empty when the rig is
// not simulated.
cv::Mat GroundTruthInCameraGrid(Rig& rig, double z_um);

// Draw `draw` (0 = the first scan's) of the extra depth noise field of options: camera size,
// zero mean, standard deviation options.extra_noise_um (um); empty when that is 0.
cv::Mat SimulatedDepthNoiseField(const SimulatedRigOptions& options, uint64_t draw);
// The rig's current extra-noise draw number (scans started so far with noise, 0-based); -1 for a
// rig that is not simulated.
int64_t SimulatedNoiseDraw(Rig& rig);

// The renderer settings the simulated rig uses for these options (for serving the same frames
// elsewhere, e.g. over GigE Vision: build an ImageFormation from them and MakeSpecimen).
StatusOr<ImageFormationOptions> ImageFormationOptionsFor(const SimulatedRigOptions& options);

// The simulated rig's renderer on its own, with the same options, specimen and seed as
// CreateSimulatedRig(options): Render(pattern, z, exposure, gain, SimulatedFrameNoiseSeed(seed,
// n)) returns exactly the rig's n-th captured frame (n from 1), without any device state.
StatusOr<std::unique_ptr<ImageFormation>> CreateSimulatedRenderer(const SimulatedRigOptions& options);
uint64_t SimulatedFrameNoiseSeed(uint64_t seed, uint64_t frame_number);

// Scan defaults for a specimen z range: the range with 4 steps of margin each side, 5 um steps,
// z_end_um = z_start_um + k * z_step_um (at least 3 frames).
ScanDefaults ScanDefaultsFor(std::pair<double, double> z_range_um, double exposure_us);

}  // namespace inspection
