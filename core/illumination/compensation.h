// Radiometric compensation by adaptive illumination (thesis 5.1): reflectance estimate
// R = E_c / E_s (eq. 5.5, as a ratio of local means, see below), desired scene irradiance
// E_c^ / R (eq. 5.6) and the projector
// pattern through the scatter matrix's pseudo-inverse (eq. 5.11), solved iteratively
// (Eigen LeastSquaresConjugateGradient on the sparse system, never a dense inverse), with the
// low-pass of 5.1.2, plus the prediction of eq. 5.12 used by the predictive ADAPT mode.
//
// Low-pass (5.1.2): the projector irradiance is solved on a coarse grid of nodes every
// pattern_cell_px projector pixels and bilinearly interpolated to the projector, e_p = U c, so
// the system is A U c = e_s. The camera side is binned alike (sums over camera_bin_px^2 blocks,
// B), so the solved system is B A U c = B e_s, formed once at construction: it keeps the pattern
// free of high frequencies that would disturb the focus measure and makes one solve ~bin^2
// cheaper than one on A (tests/bench/compensation_bench.cc).
//
// Corrections shown at the next z (ShownAt::kNextZ): the scatter matrix A is the in-focus light
// transport, but during a scan most of the frame is defocused, so E_c is a blurred version of
// what A e_p predicts. Per pixel, R = E_c / (A e_p) then carries the shown pattern's own structure
// inverted (blur(P) / P), the next pattern re-imprints it, and how strongly depends on how far
// each point is from focus; texture peaks that saturate only near focus add jumps. A correction
// computed at z_i and shown at z_i+1 thus changes the illumination of a point while it passes
// through focus, one frame late: its focus curve is modulated asymmetrically and its peak moves
// against or with the scan direction (the predictive ADAPT family's depth bias, docs/illumination.md
// "Illumination modes"). For such corrections eq. 5.5 is taken as a ratio of local means over one
// period of the finest structure a shown pattern has (two grid cells, or the period of an added
// checkerboard), which is the same sharp or blurred, and saturated pixels get no extra factor. A
// correction shown at the same z (ShownAt::kSameZ: initialisation frames, ADAPT-IT's iterations)
// keeps the thesis's per-pixel estimate: it lights the focus state it was estimated from.
#pragma once

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCore>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "core/calibration/camera_response.h"
#include "core/calibration/projector_response.h"
#include "core/calibration/scatter_matrix.h"
#include "core/util/status.h"

namespace inspection {

struct CompensationOptions {
  // Coarse-grid spacing of the low-pass, projector px (1..32). 2 (~7 camera px at 3.4 camera px
  // per projector px) dims glints of a few camera pixels; 4 flattens less texture on specimens
  // that never saturate but leaves the glints' halos (docs/illumination.md).
  int pattern_cell_px = 2;
  int camera_bin_px = 4;           // camera rows summed in bin x bin blocks (1..16)
  int solver_iterations = 12;      // LSCG iterations per solve (warm-started), 1..1000
  double solver_tolerance = 1e-3;  // relative residual at which LSCG stops early
  // Pixels whose predicted scene radiance is below this share of the maximum are not lit by
  // the projector: they do not enter the reflectance estimate.
  double min_lit_fraction = 0.02;
  // A saturated pixel's radiance is only a lower bound of the truth: for a correction shown at
  // the same z, its reflectance estimate is multiplied by this factor (>= 1) so the next pattern
  // dims it faster. Corrections shown at the next z use 1 (see the file comment).
  double saturated_reflectance_factor = 4.0;
  // Corrections shown at the next z: side (camera px, odd, <= 63) of the window over which
  // eq. 5.5 takes the ratio of local means, sum E_c / sum A e_p. 0 = automatic: the odd number
  // nearest to one period of the finest structure shown patterns have, 2 pattern cells in camera
  // pixels (camera px per projector px estimated from the scatter matrix) or
  // texture_period_camera_px when larger. 1 = per pixel, as in the thesis.
  int reflectance_window_px = 0;
  // Period (camera px) of a texture that shown patterns carry besides the compensation
  // (HF+ADAPT's added checkerboard, ADAPTED-HF's checkerboard target); 0 = none.
  double texture_period_camera_px = 0.0;
  Status Validate() const;
};

// The outcome of one compensation step.
struct CompensationStep {
  cv::Mat projector_irradiance;    // CV_32FC1 projector size, relative irradiance (prf units)
  cv::Mat pattern;                 // CV_8UC1 projector size: prf^-1 of projector_irradiance
  cv::Mat reflectance;             // CV_32FC1 camera size, eq. 5.5 (per pixel or windowed; NaN = not lit)
  double mean_abs_error_grey = 0;  // |Z_c - Z_c^| over lit pixels of the frame given, camera levels
  int solver_iterations = 0;
  double solver_error = 0;  // LSCG relative residual
};

// Where a correction's pattern will be shown (see the file comment).
enum class ShownAt {
  kSameZ,  // at the z of the frame it was computed from: per-pixel eq. 5.5 (thesis)
  kNextZ,  // at the next z of a scan: eq. 5.5 over the reflectance window
};

// Holds pointers to the models: they must outlive the compensator. Not thread-safe (one solver).
class Compensator {
 public:
  static StatusOr<std::unique_ptr<Compensator>> Create(const CameraResponseFunction& crf,
                                                       const ProjectorResponseFunction& prf,
                                                       const ScatterMatrix& scatter,
                                                       const CompensationOptions& options);

  // One iteration of eq. 5.5, 5.6, 5.11: `irradiance` is the projector irradiance that lit
  // `frame` (CV_32FC1, projector size; e.g. prf.IrradianceImage(pattern)), frame the camera
  // image (CV_8UC1/CV_16UC1) captured at exposure_us; desired_grey the desired camera image
  // (CV_32FC1 camera size, camera grey levels). The solve is warm-started from warm_start
  // (CV_32FC1 projector size), or from `irradiance` when empty (HF+ADAPT passes the adapted
  // part without the added checkerboard). shown_at: where the corrected pattern will be shown.
  StatusOr<CompensationStep> Step(const cv::Mat& irradiance, const cv::Mat& frame, double exposure_us,
                                  const cv::Mat& desired_grey, const cv::Mat& warm_start = cv::Mat(),
                                  ShownAt shown_at = ShownAt::kSameZ) const;

  // Eq. 5.11 alone: the projector irradiance whose predicted scene radiance is closest to
  // scene_radiance (CV_32FC1 camera size; NaN entries are unconstrained -> keep warm start),
  // low-passed and clamped to [prf(0), 1]. warm_start: CV_32FC1 projector size.
  StatusOr<cv::Mat> SolveIrradiance(const cv::Mat& scene_radiance, const cv::Mat& warm_start, int* iterations = nullptr,
                                    double* error = nullptr) const;

  // Irradiance -> 8-bit projector pattern through the inverse prf.
  cv::Mat PatternFor(const cv::Mat& irradiance) const;

  const CompensationOptions& options() const { return options_; }
  cv::Size coarse_size() const { return coarse_size_; }
  // The reflectance window of ShownAt::kNextZ (options().reflectance_window_px, or automatic).
  int reflectance_window_px() const { return reflectance_window_px_; }

 private:
  Compensator() = default;
  cv::Mat Upsample(const Eigen::VectorXf& c) const;
  Eigen::VectorXf Downsample(const cv::Mat& irradiance) const;

  const CameraResponseFunction* crf_ = nullptr;
  const ProjectorResponseFunction* prf_ = nullptr;
  const ScatterMatrix* scatter_ = nullptr;
  CompensationOptions options_;
  cv::Size coarse_size_;
  int reflectance_window_px_ = 1;
  using Sparse = Eigen::SparseMatrix<float, Eigen::ColMajor, int>;
  cv::Size bin_size_;
  Sparse au_;  // B A U
  std::unique_ptr<Eigen::LeastSquaresConjugateGradient<Sparse>> solver_;
  std::vector<float> exposure_table_;  // exp(crf(g)) at g = k / 16
  uint8_t inverse_prf_[4097] = {};     // grey for irradiance k / 4096
};

// Camera pixels per projector pixel of a scatter matrix: sqrt(lit camera pixels / projector
// pixels that light any), i.e. the linear scale of the overlap of the two fields. 0 when empty.
double CameraPxPerProjectorPx(const ScatterMatrix& scatter);

// Eq. 5.12: E_p,i+1 = E_p,i + lambda (E_p,i - E_p,i-1), clamped to [floor, 1]. CV_32FC1.
StatusOr<cv::Mat> PredictIrradiance(const cv::Mat& current, const cv::Mat& previous, double lambda, double floor);

}  // namespace inspection
