// The calibration bundle: every calibrated model of thesis 4.3 and 5.4.1 (camera and projector
// response, geometric LUTs, PSFs and sigma_p, scatter matrix, integral PSF) plus the figures
// that verify each step, stored as one versioned folder. Plain data; Save/Load only.
//
// Folder layout (format "inspection-calibration", version kCalibrationBundleVersion):
//   bundle.json                       everything scalar: ids, sizes, curves, figures, file names
//   geometry_projector_to_camera_{x,y}.tiff   float32, projector size (NaN = not seen)
//   geometry_camera_to_projector_{x,y}.tiff   float32, camera size (NaN = unlit)
//   psf_<k>.tiff                      float32 PSF of defocus step k
//   scatter_matrix.bin                CSC float32 (see core/calibration/scatter_matrix.h)
//   scatter_black_radiance.tiff       float32, camera size
//   integral_psf.tiff                 float32 kernel
// The focus-breathing model (core/registration/stack_alignment.h) and the z-linearity table
// 13, core/metrology/z_linearity.h) are scalar: bundle.json only.
// Models that were not calibrated are absent from bundle.json and have no files.
#pragma once

#include <filesystem>
#include <map>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/calibration/camera_response.h"
#include "core/calibration/geometric_calibration.h"
#include "core/calibration/integral_psf.h"
#include "core/calibration/projector_response.h"
#include "core/calibration/psf_calibration.h"
#include "core/calibration/scatter_matrix.h"
#include "core/registration/stack_alignment.h"
#include "core/util/status.h"
#include "core/metrology/z_linearity.h"

namespace inspection {

inline constexpr int kCalibrationBundleVersion = 1;
inline constexpr const char* kCalibrationBundleManifest = "bundle.json";

// The steps of a calibration, in the order RunCalibration performs them.
enum class CalibrationStep {
  kCameraResponse,     // thesis 4.3.1, eq. 4.4
  kProjectorResponse,  // thesis 4.3.1, eq. 4.8-4.9
  kGeometry,           // thesis 4.3.2, eq. 4.10
  kPsf,                // thesis 4.3.3 and sigma_p of 5.2.1
  kScatterMatrix,      // thesis 4.3.4, eq. 4.11-4.12
  kIntegralPsf,        // thesis 5.4.1, eq. 5.22
  kZLinearity,         // the depth's periodic error between frames, for uncertainties
  kFocusBreathing,     // magnification change and lateral drift through z
};
inline constexpr int kCalibrationStepCount = 8;

// "camera_response", "projector_response", "geometry", "psf", "scatter_matrix", "integral_psf",
// "z_linearity", "focus_breathing".
const char* CalibrationStepName(CalibrationStep step);
StatusOr<CalibrationStep> ParseCalibrationStep(const std::string& name);
std::vector<CalibrationStep> AllCalibrationSteps();
// What a calibration request without steps runs: every step but focus_breathing, which a rig
// with telecentric optics and a straight stage does not need (request it by name).
std::vector<CalibrationStep> DefaultCalibrationSteps();

// What one step measured, for `inspectctl calibration show`. Figure names carry units, e.g.
// "lut_vs_homography_mean_px", "prediction_mae_percent", "fit_rms_residual_ln".
struct CalibrationStepReport {
  CalibrationStep step = CalibrationStep::kCameraResponse;
  double duration_s = 0.0;
  std::string finished_utc;  // ISO 8601, e.g. "2026-11-22T01:02:03Z"
  int frames_captured = 0;
  std::map<std::string, double> figures;
  std::string note;  // free text, e.g. which true-parameter checks were possible
};

struct CalibrationBundle {
  int version = kCalibrationBundleVersion;
  std::string id;           // assigned by the server; empty until then
  std::string created_utc;  // ISO 8601
  std::string rig;          // rig description, e.g. "simulated (seed 1)"
  cv::Size camera_size;
  cv::Size projector_size;
  int camera_bit_depth = 8;

  std::optional<CameraResponseFunction> camera_response;
  std::optional<ProjectorResponseFunction> projector_response;
  std::optional<GeometricCalibration> geometry;
  std::optional<PsfCalibration> psf;
  std::optional<ScatterMatrix> scatter;
  std::optional<IntegralPsf> integral_psf;
  std::optional<FocusBreathingModel> focus_breathing;
  std::optional<ZLinearity> z_linearity;  // characterised at z_linearity->characterised_step_um

  // The latest report of every step in the bundle (one per step; a step carried over from a
  // previous bundle keeps its report).
  std::vector<CalibrationStepReport> reports;

  const CalibrationStepReport* Report(CalibrationStep step) const;
  void SetReport(CalibrationStepReport report);  // replaces the step's report
  bool HasModel(CalibrationStep step) const;

  // Checks every present model (Validate) and that sizes agree with camera/projector size.
  Status Validate() const;

  // Writes the folder (created if missing). ALREADY_EXISTS if dir already holds a bundle:
  // a bundle, once written, is never overwritten (scans refer to it by id). bundle.json is
  // written last, atomically, so a folder without it is an incomplete save.
  Status Save(const std::filesystem::path& dir) const;
  // Reads and validates a folder. NOT_FOUND without bundle.json; FAILED_PRECONDITION for a
  // newer version; DATA_LOSS / INVALID_ARGUMENT naming the file or field that is wrong.
  static StatusOr<CalibrationBundle> Load(const std::filesystem::path& dir);

  // Human-readable summary of models and figures (what `inspectctl calibration show` prints).
  std::string Summary() const;
};

}  // namespace inspection
