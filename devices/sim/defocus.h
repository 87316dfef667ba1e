// Defocus of the simulated rig (thesis 3.1.1, 4.3.3, Fig. 4.16-4.18): a point at height h seen
// with the stage at z is blurred by a PSF whose width grows with |h - z|. Near focus the PSF is
// close to a Gaussian; far from focus it tends to the pillbox (geometric blur circle).
// SpatiallyVaryingBlur applies a per-pixel PSF width fast enough for whole scans: the image is
// blurred at a ladder of PSF widths (large ones on 2x/4x/... reduced images) and each pixel
// interpolates between the two rungs bracketing its own width.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/util/status.h"

namespace inspection {

struct DefocusModel {
  // Gaussian sigma of the in-focus PSF (diffraction of a 10x/0.3 objective: ~0.21 lambda/NA).
  double in_focus_sigma_px = 0.55;
  // Radius of the geometric blur circle per micrometre of defocus, in camera pixels:
  // tan(asin(NA)) / pixel size = 0.314 / 0.74 for the thesis rig (10x, NA 0.3, 0.74 um px).
  double blur_radius_px_per_um = 0.425;
  // PSF shape: pure Gaussian up to this sigma, blending linearly in sigma into a pillbox of the
  // same second moment (radius 2 sigma) that is reached at pillbox_from_sigma_px.
  double gaussian_until_sigma_px = 1.5;
  double pillbox_from_sigma_px = 8.0;
  // How the image pass spreads a surface whose defocus varies across the frame. false: each
  // camera pixel takes the PSF of its own defocus (the thesis' fast blur, a gather); where the
  // defocus varies (a tilted or stepped surface) that moves defocused content by about
  // d(sigma^2)/dx per frame, a lateral motion the specimen does not make. true: each surface
  // point spreads by its own defocus, as a telecentric thin lens images it (ApplyScatter).
  bool point_spread_imaging = false;

  Status Validate() const;
  // PSF width (sigma, camera px) for a defocus |h - z| in micrometres:
  // sqrt(in_focus^2 + (radius / 2)^2), a pillbox of radius r having sigma r / 2.
  double SigmaPx(double defocus_um) const;
  // 0 = Gaussian, 1 = pillbox.
  double PillboxWeight(double sigma_px) const;
  // The PSF at this sigma as a normalised 2D kernel (CV_32FC1, odd size): Gaussian (cut at
  // truncation_sigmas) and anti-aliased pillbox of equal sigma mixed by
  // PillboxWeight(shape_sigma_px).
  cv::Mat Kernel(double sigma_px, double shape_sigma_px, double truncation_sigmas = 3.0) const;
  cv::Mat Kernel(double sigma_px) const { return Kernel(sigma_px, sigma_px); }
};

// Which two ladder rungs each pixel mixes, and how: computed once per sigma map and shared by
// both defocus passes of a frame.
struct BlurPlan {
  int first_rung = 0, last_rung = 0;  // rungs used by this map
  cv::Mat rung;                       // CV_8UC1: lower rung, relative to first_rung
  cv::Mat weight;                     // CV_32FC1: weight of the upper rung (0..1)
};

// Not thread-safe (keeps scratch buffers between calls); one per renderer. Type and size
// mismatches of its inputs are programming errors (CV_Assert), not user errors: the renderer
// builds every input itself.
class SpatiallyVaryingBlur {
 public:
  explicit SpatiallyVaryingBlur(const DefocusModel& model);

  // Per pixel PSF sigma (camera px, CV_32FC1), clamped to [in_focus_sigma_px, max_sigma_px()].
  // Mixing two rungs with weights keeps the pixel's PSF variance exact.
  BlurPlan Plan(const cv::Mat& sigma_px) const;
  // dst(p) = (src * PSF(sigma(p)))(p) for the plan's sigma map. src CV_32FC1 of the plan's size.
  // Border: reflected.
  void Apply(const cv::Mat& src, const BlurPlan& plan, cv::Mat* dst);
  // Each source pixel spread by the PSF of its own sigma (plan's rungs read at the source): the
  // source split between its two rungs, each part blurred by its rung, the parts summed.
  void ApplyScatter(const cv::Mat& src, const BlurPlan& plan, cv::Mat* dst);
  void Apply(const cv::Mat& src, const cv::Mat& sigma_px, cv::Mat* dst) { Apply(src, Plan(sigma_px), dst); }

  const std::vector<double>& ladder_sigma_px() const { return ladder_; }
  double max_sigma_px() const { return ladder_.back(); }

 private:
  // Blurs the padded source at ladder rung i into layers_[i] (reduced by layer_factor_[i]).
  void ComputeLayer(int i);

  DefocusModel model_;
  std::vector<double> ladder_;    // PSF sigma of each rung, geometric
  std::vector<int> factor_;       // reduction factor (1, 2, 4, ...) of each rung
  cv::Mat padded_;                // source with a reflected border, size a multiple of kMaxFactor
  std::vector<cv::Mat> reduced_;  // padded_ reduced by 2^k (index k)
  std::vector<cv::Mat> layers_;   // rung images, reduced by layer_factor_
  std::vector<int> layer_factor_;
  int border_ = 0;
};

}  // namespace inspection
