// ImageFormation: the simulated rig's renderer, a pure function of (projector pattern, stage z,
// exposure, gain, noise seed) for one specimen (thesis 5.1.1, Fig. 5.2):
//   Z_p -> prf (eq. 5.1) -> projector-to-camera mapping (4.3.2) -> defocus by |h - z|
//   -> E_s = R * texture * E~_p (eq. 5.2) -> defocus again -> X_c = E_c dt (eq. 5.3)
//   -> shot/read noise, crf, black level, saturation, quantisation (eq. 5.4).
// No device or transport state lives here, so the same frames can be served by the simulated
// Camera and by a GigE Vision fake camera.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>

#include "core/registration/stack_alignment.h"
#include "core/util/status.h"
#include "devices/sim/defocus.h"
#include "devices/sim/projector_camera_geometry.h"
#include "devices/sim/radiometry.h"
#include "devices/sim/specimen.h"

namespace inspection {

// Lateral optics through focus: a non-telecentric objective's magnification changes
// with the stage z ("focus breathing") and the stage drifts laterally. The camera grid at z is
// the specimen grid (the grid of the specimen maps and of the ground truth) transformed by
// FocusBreathingModel::At(z) (core/registration/stack_alignment.h: scale about the image centre, then shift);
// at reference_z_um it is the specimen grid. All zero = frames registered pixel for pixel.
struct LateralOptics {
  double breathing_percent_per_100um = 0.0;  // magnification change, % per 100 um of z
  double drift_x_px_per_100um = 0.0;         // lateral drift, camera px per 100 um of z
  double drift_y_px_per_100um = 0.0;
  double reference_z_um = 0.0;
  bool active() const {
    return breathing_percent_per_100um != 0.0 || drift_x_px_per_100um != 0.0 || drift_y_px_per_100um != 0.0;
  }
  // The exact model the frames follow, for a camera of frame_size.
  FocusBreathingModel Model(cv::Size frame_size) const;
  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

struct ImageFormationOptions {
  cv::Size camera_size{1024, 768};
  cv::Size projector_size{1280, 720};
  ProjectorResponse projector;
  ProjectorCameraGeometryOptions geometry;
  DefocusModel defocus;
  CameraResponse camera;
  LateralOptics lateral;

  Status Validate() const;
};

// Not thread-safe (scratch buffers); use one per thread. Render results are deterministic.
class ImageFormation {
 public:
  // specimen maps must have options.camera_size.
  static StatusOr<std::unique_ptr<ImageFormation>> Create(const ImageFormationOptions& options, Specimen specimen);

  Status SetSpecimen(Specimen specimen);
  const Specimen& specimen() const { return specimen_; }
  const ImageFormationOptions& options() const { return options_; }
  const ProjectorCameraGeometry& geometry() const { return geometry_; }

  // The whole chain. pattern: CV_8UC1 of the projector size. Output: CV_8UC1 (8 bit) or
  // CV_16UC1 (12 bit). INVALID_ARGUMENT naming the parameter on bad input.
  StatusOr<cv::Mat> Render(const cv::Mat& pattern, double z_um, double exposure_us, double gain_db,
                           uint64_t noise_seed);

  // Stages of the chain, for tests and for noise-free analysis (all CV_32FC1, camera size;
  // INVALID_ARGUMENT for a pattern that is not CV_8UC1 of the projector size):
  // E_p on the camera grid (prf + mapping), no defocus.
  StatusOr<cv::Mat> ProjectorIrradianceOnCamera(const cv::Mat& pattern) const;
  // Specimen-grid pixels -> camera pixels with the stage at z_um (identity without lateral optics).
  cv::Matx23d CameraFromSpecimen(double z_um) const;
  // E_c: irradiance reaching the sensor (both defocus passes, then the lateral optics), relative
  // units.
  StatusOr<cv::Mat> CameraIrradiance(const cv::Mat& pattern, double z_um);

  // Exposure (us) for which the noise-free, in-focus image under a uniform projector grey has
  // mean grey level target_grey (8-bit scale), with gain 0 dB.
  double ExposureForMeanGrey(int projector_grey, double target_grey) const;

 private:
  ImageFormation(const ImageFormationOptions& options);
  Status ValidatePattern(const cv::Mat& pattern) const;
  void ProjectorIrradianceInto(const cv::Mat& pattern, cv::Mat* on_camera) const;
  void DefocusSigmaInto(double z_um, cv::Mat* sigma) const;
  const cv::Mat& CameraIrradianceScratch(const cv::Mat& pattern, double z_um);

  ImageFormationOptions options_;
  ProjectorCameraGeometry geometry_;
  std::array<float, 256> prf_table_;
  cv::Rect projector_roi_;                 // projector pixels the camera sees
  cv::Mat map_x_, map_y_;                  // camera -> projector_roi_ coordinates (released once converted)
  cv::Mat fixed_map_xy_, fixed_map_frac_;  // the same as fixed-point remap maps
  Specimen specimen_;
  cv::Mat surface_;  // reflectance * texture
  SpatiallyVaryingBlur blur_;
  cv::Mat scratch_sigma_, scratch_ep_, scratch_ep_blurred_, scratch_es_, scratch_ec_, scratch_lateral_;
};

}  // namespace inspection
