// Measures against a least-squares plane of a region: tilt angle, flatness (ISO 12781-1 FLTt with
// the least-squares reference plane: peak-to-valley of the deviations from it), and the volume
// of material above and of space below a reference (plane of a reference region, or a fixed
// height). Each with its standard uncertainty from the depth map's error model
// (core/metrology/measurement_uncertainty.h).
#pragma once

#include <opencv2/core.hpp>

#include "core/metrology/depth_noise_model.h"
#include "core/metrology/form_removal.h"
#include "core/metrology/measurement_uncertainty.h"
#include "core/util/status.h"

namespace inspection {

struct TiltResult {
  double tilt_deg = 0.0;     // angle between the plane's normal and the z axis: atan(|slope|)
  double tilt_x_deg = 0.0;   // atan(slope_x): rotation about the y axis
  double tilt_y_deg = 0.0;   // atan(slope_y)
  double azimuth_deg = 0.0;  // direction of steepest ascent, from +x towards +y, (-180, 180]
  FormFit plane;
  // Of tilt_deg: sqrt(trace) of the slope covariance (radial plus tangential variance), through
  // d atan(m) / dm. Near zero tilt |slope| is Rayleigh-distributed (never negative, biased up),
  // and the radial variance alone would cover it at k = 2 only 86 % of the time; with both
  // components the k = 2 interval holds its 95 % quantile (2.45 sigma < 2 sqrt 2 sigma). For a
  // tilt far above its uncertainty this is conservative by up to sqrt 2.
  UncertaintyBudget uncertainty;
};
// mask: CV_8UC1 region; noise may be null (no uncertainty).
StatusOr<TiltResult> MeasureTilt(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                 const DepthNoiseModel* noise);

struct FlatnessResult {
  double flatness_um = 0.0;  // peak + valley of the deviations, perpendicular to the plane
  double peak_um = 0.0;      // largest deviation above the plane (perpendicular)
  double valley_um = 0.0;    // largest deviation below it, as a positive number
  FormFit plane;
  UncertaintyBudget uncertainty;  // ExtremeValueBudget(2, ...): a peak-to-valley is two extremes
};
StatusOr<FlatnessResult> MeasureFlatness(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                         const DepthNoiseModel* noise);

enum class VolumeReference {
  kRegionPlane,  // least-squares plane of a reference region (or of the measured region itself)
  kHeight,       // the plane z = reference_height_um
};
StatusOr<VolumeReference> ParseVolumeReference(const std::string& name);

struct VolumeOptions {
  VolumeReference reference = VolumeReference::kRegionPlane;
  double reference_height_um = 0.0;  // kHeight only
};

struct VolumeResult {
  // Material above the reference and space below it over the region, um^3 (1 mm^3 = 1e9 um^3):
  // sum over pixels of max(0, +-(z - reference)) times the pixel area. Pixels of the region
  // without depth are filled from the measured pixels around them (Gaussian-weighted mean height
  // above the reference, sigma 4 px); pixels with no measurement within ~10 px count as the
  // region's mean (the sums are scaled to the whole region). Both enter the uncertainty as a
  // rectangular +-100 % of their share (UncertaintyBudget::other).
  double above_um3 = 0.0;
  double below_um3 = 0.0;
  double above_mm3() const { return above_um3 * 1e-9; }
  double below_mm3() const { return below_um3 * 1e-9; }
  size_t region_pixels = 0;
  size_t measured_pixels = 0;
  UncertaintyBudget above_uncertainty;  // Monte Carlo (re-fitting the reference plane per sample)
  UncertaintyBudget below_uncertainty;
};
// region_mask: the region (all its pixels, measured or not, e.g. RoiMask::region);
// reference_mask: kRegionPlane's reference region (empty = the region itself).
StatusOr<VolumeResult> MeasureVolume(const cv::Mat& depth_um, const cv::Mat& region_mask, const cv::Mat& reference_mask,
                                     double pixel_size_um, const VolumeOptions& options, const DepthNoiseModel* noise,
                                     const MonteCarloOptions& monte_carlo = {});

}  // namespace inspection
