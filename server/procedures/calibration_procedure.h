// Calibration procedure: drives a Rig through the calibration steps of thesis 4.3 and 5.4.1
// (camera response, projector response, geometric LUTs, PSF + sigma_p, scatter matrix,
// integral PSF) and the focus-breathing model, calls the core estimators and returns a CalibrationBundle
// with the figures that verify each step. No gRPC here: the server's Calibrate job wraps RunCalibration.
//
// What it needs from the rig: a planar, diffuse target normal to the optical axis under the
// objective (thesis 4.3.1). On the simulated rig the procedure switches the specimen to
// `simulated_target` itself and restores the previous specimen afterwards.
// Not thread-safe with respect to the rig: the caller guarantees nothing else drives it
// (the server refuses Calibrate while a scan runs and vice versa).
#pragma once

#include <atomic>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "core/calibration/calibration_bundle.h"
#include "core/calibration/integral_psf.h"
#include "core/util/status.h"
#include "devices/rig.h"

namespace inspection {

struct CalibrationProgress {
  std::string step;    // CalibrationStepName, or "focus" while focusing on the target
  int step_index = 0;  // 0-based among the steps of this run
  int step_count = 0;
  int item = 0;  // frames (or sub-tasks) done in this step
  int item_count = 0;
  std::string message;  // human-readable, e.g. "dot grid 12/64"
};

struct CalibrationOptions {
  // Steps to run, in any order (they are run in CalibrationStep order); empty = the seven of
  // DefaultCalibrationSteps() (focus_breathing only when named).
  std::vector<CalibrationStep> steps;

  // Simulated rig only (ignored on real rigs; empty = keep the current specimen): the target
  // for the radiometric/PSF/scatter/IPSF steps and the one for geometry (thesis 4.3.2 uses a
  // mirror there so the dots are not modulated by texture).
  std::string simulated_target = "plane";
  std::string simulated_geometry_target = "mirror";

  // Stage z at which the target is in focus; NaN = autofocus (checkerboard pattern, Laplacian
  // energy, parabolic peak) over the rig's scan_defaults() range.
  double focus_z_um = std::numeric_limits<double>::quiet_NaN();

  // Camera response (thesis 4.3.1): exposure series under uniform grey, log-spaced around the
  // exposure giving a median of mid-grey, spanning crf_exposure_span (max/min ratio).
  int crf_exposure_count = 24;
  double crf_exposure_span = 1000.0;
  int crf_projector_grey = 128;
  double crf_smoothness_lambda = 10.0;
  int crf_sample_pixels = 200;

  // Projector response (eq. 4.8-4.9): every prf_level_step-th grey level plus 255; exposures
  // log-spaced over prf_exposure_span by eq. 4.8, halved while saturated.
  int prf_level_step = 5;
  double prf_exposure_span = 100.0;

  // Geometry (4.3.2): Gray code down to this stripe width, then spacing^2 dot grids.
  int gray_code_finest_stripe_px = 4;
  int geometry_grid_spacing_px = 8;

  // PSF (4.3.3): one sparse dot grid per defocus step (stage offsets from focus).
  std::vector<double> psf_defocus_um = {-20.0, -10.0, -5.0, 0.0, 5.0, 10.0, 20.0};
  int psf_grid_spacing_px = 16;

  // Scatter matrix (4.3.4): spacing^2 dot grids; patch radius 0 = 2 sigma_p + 2 (or
  // 1.5 x projector-to-camera scale + 2 without a PSF calibration); a random test pattern
  // (random grey per prediction_block_px block) measures the prediction error.
  int scatter_grid_spacing_px = 8;
  int scatter_patch_radius_px = 0;
  double scatter_relative_threshold = 0.005;
  int scatter_test_block_px = 2;
  uint64_t scatter_test_seed = 1;

  // Integral PSF (5.4.1): a stack from focus - half range to focus + half range.
  double ipsf_half_range_um = 40.0;
  double ipsf_step_um = 5.0;
  int ipsf_radius_px = 8;
  IpsfRegularisation ipsf_regularisation = IpsfRegularisation::kGradientL2;
  double ipsf_regularisation_weight = 1e-4;
  // The IPSF is one kernel for the whole field (thesis 5.4.1): it is estimated on the central
  // region of at most this many pixels per side, which bounds the solve time on big cameras.
  int ipsf_region_px = 512;

  // Focus breathing: the target from focus - half range to focus + half range (frames
  // beyond the stage travel are skipped), registered neighbour to neighbour.
  double breathing_half_range_um = 40.0;
  double breathing_step_um = 5.0;

  // z linearity: a smooth, textured flat tilted so its heights span several z steps
  // (an optical flat on a wedge on a real rig; SKEW10, tilted 10 deg, on the simulated rig),
  // scanned over the rig's default range at this step (0 = the rig's default step: the table
  // applies only to scans at that step).
  std::string simulated_linearity_target = "skew10";
  double z_linearity_step_um = 0.0;

  Status Validate() const;
};

// Runs the requested steps. Steps not run are carried over from `previous` (may be null), with
// their reports. A step whose inputs are neither run now nor in `previous` fails the request
// with FAILED_PRECONDITION naming the missing model, before any frame is captured:
//   projector_response <- camera_response; psf <- camera_response, geometry;
//   scatter_matrix <- camera_response, projector_response, geometry.
// `previous` must have the rig's camera and projector size (FAILED_PRECONDITION otherwise).
// Returns CANCELLED as soon as `cancel` is seen between frames; device errors pass through.
// The returned bundle has no id (the server assigns it) and created_utc set to now.
// The projector is left at uniform grey 128 and the camera at its previous exposure.
StatusOr<CalibrationBundle> RunCalibration(Rig& rig, const CalibrationOptions& options,
                                           const CalibrationBundle* previous,
                                           const std::function<void(const CalibrationProgress&)>& on_progress,
                                           const std::atomic<bool>& cancel);

}  // namespace inspection
