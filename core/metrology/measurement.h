// One entry point for recipe measurements on a depth map: a measurement names what
// to compute (ISO 25178-2 height parameter, step height, flatness, tilt, volume, form radius),
// on which region(s) of interest, with which options; the result is the value, its unit, its
// standard uncertainty (core/metrology/measurement_uncertainty.h) and the region's coverage. The verdict
// against a tolerance is core/metrology/verdict.h's Judge. No gRPC here: server/ maps recipes to
// MeasurementSpec and MeasuredValue to the proto.
//
//   MeasurementContext ctx{depth.depth_um, pixel_size_um};
//   ctx.noise.window_px = sff.window_px;  ctx.noise.z_positions_um = manifest z positions;
//   ctx.noise.linearity = the rig's characterised ZLinearity (else the uncharacterised bound);
//   MeasurementSpec sa;  sa.kind = MeasurementKind::kSa;  sa.roi = RegionOfInterest::Rectangle(...);
//   INSPECT_RETURN_IF_ERROR(sa.Validate(depth.size(), pixel_size_um, "measurements[0]"));
//   StatusOr<MeasuredValue> v = Measure(sa, ctx);
//   VerdictResult verdict = v.ok() ? Judge(v->value, v->uncertainty.standard_uncertainty,
//                                          v->coverage_percent, tolerance)
//                                  : NotMeasured(v.status().message());
//
// Everything here is a pure function of its inputs (no global state), so several maps may be
// measured on several threads at once; the Monte Carlo seed is fixed, so a map and a spec always
// give the same value and uncertainty.
#pragma once

#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/metrology/areal_parameters.h"
#include "core/metrology/depth_noise_model.h"
#include "core/metrology/form_removal.h"
#include "core/metrology/measurement_uncertainty.h"
#include "core/metrology/plane_measures.h"
#include "core/util/status.h"
#include "core/metrology/step_height.h"
#include "core/metrology/surface_roi.h"

namespace inspection {

enum class MeasurementKind {
  kSa,
  kSq,
  kSp,
  kSv,
  kSz,
  kSsk,
  kSku,          // ISO 25178-2 height parameters of `roi` (options: areal)
  kStepHeight,   // `roi` (measured region) above `reference_roi`, um (options: step)
  kFlatness,     // FLTt of `roi` against its least-squares plane, um
  kTilt,         // tilt of `roi`'s least-squares plane, degrees
  kVolumeAbove,  // material above the reference over `roi` (options: volume, volume_unit)
  kVolumeBelow,  // space below the reference over `roi`
  kRadius,       // sphere or cylinder radius fitted to `roi`, um (options: form, model sphere/cylinder)
};

// Recipe names: "Sa" "Sq" "Sp" "Sv" "Sz" "Ssk" "Sku" "step_height" "flatness" "tilt"
// "volume_above" "volume_below" "radius".
const char* MeasurementKindName(MeasurementKind kind);
// INVALID_ARGUMENT "unknown measurement parameter 'X' (Sa, Sq, ...)" for other names.
StatusOr<MeasurementKind> ParseMeasurementKind(const std::string& name);
std::vector<MeasurementKind> AllMeasurementKinds();

enum class VolumeUnit { kCubicMicrometre, kCubicMillimetre };  // "um3", "mm3"

struct MeasurementSpec {
  MeasurementKind kind = MeasurementKind::kSa;
  RegionOfInterest roi;
  std::optional<RegionOfInterest> reference_roi;  // step height: required; volume: plane region (optional)
  ArealOptions areal;                             // Sa..Sku: form removal and S-/L-filter cut-offs
  FormOptions form{FormModel::kSphere};           // radius: kSphere or kCylinder
  StepHeightOptions step;
  VolumeOptions volume;
  VolumeUnit volume_unit = VolumeUnit::kCubicMicrometre;

  // INVALID_ARGUMENT naming `field` + ".roi", ".reference_roi", ".areal.l_filter_cutoff_um", ...
  Status Validate(cv::Size image_size, double pixel_size_um, const std::string& field) const;
  std::string unit() const;  // "um", "" (Ssk, Sku), "deg", "um3", "mm3"
};

// The depth map and how to model its errors; shared by all measurements of one inspection.
struct MeasurementContext {
  cv::Mat depth_um;  // CV_32FC1, NaN = no depth (DepthResult::depth_um)
  double pixel_size_um = 0.0;
  DepthNoiseOptions noise;  // window, the stack's z positions, z linearity, stage repeatability
  MonteCarloOptions monte_carlo;
  bool with_uncertainty = true;  // false: values only (budgets stay NaN), e.g. on a ground truth
};

struct MeasuredValue {
  MeasurementKind kind = MeasurementKind::kSa;
  double value = 0.0;
  std::string unit;
  UncertaintyBudget uncertainty;  // standard uncertainty (k = 1) and its parts
  double coverage_percent = 0.0;  // measured share of the region (the smaller of two regions)
  size_t region_pixels = 0;       // of `roi`
  size_t measured_pixels = 0;     // of `roi`
};

// Validates the spec against the map (errors name `field`), rasterises the regions, estimates
// the error model over them and measures. FAILED_PRECONDITION when the regions hold too little
// data to measure (no pixel, a fit that cannot be made): the caller's verdict is then
// NotMeasured (NOT_DECIDABLE).
StatusOr<MeasuredValue> Measure(const MeasurementSpec& spec, const MeasurementContext& context,
                                const std::string& field = "measurement");

// Several measurements on one map; height parameters that share a region and areal options are
// evaluated (and Monte-Carlo'd) once. One result per spec, in order; field names are
// field_prefix + "[i]".
std::vector<StatusOr<MeasuredValue>> MeasureAll(const std::vector<MeasurementSpec>& specs,
                                                const MeasurementContext& context,
                                                const std::string& field_prefix = "measurements");

}  // namespace inspection
