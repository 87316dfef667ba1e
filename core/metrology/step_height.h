// Step height between two regions of a depth map, in the style of ISO 5436-1 type A (and the
// areal step evaluation of ISO 25178-70): least-squares planes on a reference region (e.g. the
// land beside a groove, ISO 5436-1's A and B) and a measured region (the groove bottom, C),
// height at the step. Linear in the depths, so its uncertainty is propagated exactly
// (core/metrology/measurement_uncertainty.h).
#pragma once

#include <opencv2/core.hpp>

#include "core/metrology/depth_noise_model.h"
#include "core/metrology/measurement_uncertainty.h"
#include "core/util/status.h"

namespace inspection {

enum class StepHeightFit {
  // One plane slope for both regions and two offsets: z = z_ref + h [p in measured] + sx x + sy y.
  // For parallel surfaces (the usual artefact) the most precise; h is the same everywhere.
  kCommonSlope,
  // A plane per region; h = (measured plane - reference plane) at the midpoint of the two
  // regions' centroids (the step). For surfaces that are not parallel.
  kSeparatePlanes,
};

const char* StepHeightFitName(StepHeightFit fit);  // "common_slope", "separate_planes"
StatusOr<StepHeightFit> ParseStepHeightFit(const std::string& name);

struct StepHeightOptions {
  StepHeightFit fit = StepHeightFit::kCommonSlope;
};

struct StepHeightResult {
  // Measured region above the reference (negative for a groove), perpendicular to the
  // (reference) plane: the vertical offset times cos(tilt), so it does not depend on how the
  // specimen was tilted.
  double height_um = 0.0;
  double vertical_offset_um = 0.0;  // the same along z
  double slope_x = 0.0;             // of the common (or reference) plane, um/um
  double slope_y = 0.0;
  double evaluation_x_um = 0.0;  // where the height is taken (image coordinates, core/metrology/surface_roi.h)
  double evaluation_y_um = 0.0;
  size_t reference_pixels = 0;
  size_t measured_pixels = 0;
  double residual_rms_um = 0.0;   // of the fit(s) over both regions
  UncertaintyBudget uncertainty;  // of height_um; NaN without a noise model
};

// reference_mask, measured_mask: CV_8UC1 of depth_um's size (e.g. RoiMask::measured of two
// ROIs); they must not overlap. noise: the map's error model (EstimateDepthNoise over both
// regions), or null for no uncertainty. INVALID_ARGUMENT for bad inputs (overlap named);
// FAILED_PRECONDITION when a region has too few pixels to fit (< 3, or collinear).
StatusOr<StepHeightResult> MeasureStepHeight(const cv::Mat& depth_um, const cv::Mat& reference_mask,
                                             const cv::Mat& measured_mask, double pixel_size_um,
                                             const StepHeightOptions& options, const DepthNoiseModel* noise);

}  // namespace inspection
