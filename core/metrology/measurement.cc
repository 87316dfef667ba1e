// Recipe measurements: spec validation, region rasterisation, error model per region set,
// dispatch to the measures and their uncertainty methods.
#include "core/metrology/measurement.h"

#include <array>
#include <functional>
#include <map>
#include <sstream>

namespace inspection {
namespace {

constexpr int kPeriodicErrorBins = 20;  // ZLinearityOptions{}.bins

bool IsHeightParameter(MeasurementKind k) { return int(k) <= int(MeasurementKind::kSku); }

HeightParameter ToHeightParameter(MeasurementKind k) { return HeightParameter(int(k)); }

// All seven height parameters of one region with their budgets.
struct ArealGroupResult {
  ArealHeightParameters values;
  std::array<UncertaintyBudget, 7> budgets;
};

StatusOr<ArealGroupResult> EvaluateArealGroup(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                              const ArealOptions& options, const DepthNoiseModel* noise,
                                              const MonteCarloOptions& monte_carlo) {
  ArealGroupResult r;
  INSPECT_ASSIGN_OR_RETURN(ArealEvaluator evaluator, ArealEvaluator::Create(depth_um, mask, pixel_size_um, options));
  INSPECT_ASSIGN_OR_RETURN(ArealEvaluation e, evaluator.Evaluate(depth_um));
  r.values = e.parameters;
  if (noise == nullptr) return r;
  // Mean-type parameters by Monte Carlo; extremes by the bound (core/metrology/measurement_uncertainty.h).
  static constexpr HeightParameter kMoment[4] = {HeightParameter::kSa, HeightParameter::kSq, HeightParameter::kSsk,
                                              HeightParameter::kSku};
  auto pick = [](const ArealHeightParameters& p) { return std::vector<double>{p.Sa_um, p.Sq_um, p.Ssk, p.Sku}; };
  const std::vector<double> measured = pick(r.values);
  auto measure = [&](const cv::Mat& z) -> StatusOr<std::vector<double>> {
    INSPECT_ASSIGN_OR_RETURN(ArealEvaluation p, evaluator.Evaluate(z));
    return pick(p.parameters);
  };
  INSPECT_ASSIGN_OR_RETURN(std::vector<MonteCarloEstimate> mc,
                           MonteCarloUncertainty(depth_um, measured, measure, *noise, monte_carlo));
  // Reported as measured (ISO 25178), the noise bias in u. Corrected by the Monte Carlo's bias
  // estimate (GUM 3.2.4) Sa and Sq of flats were sharp (a flat at 5 um steps: +0.050 +- 0.001 um
  // left -0.002 +- 0.001), but the estimate follows the model's sigma, which structure at 1-3
  // windows inflates: on a random rough surface (Sq ~1 um, 16-60 px wavelengths) it put the bias
  // at +0.08 um where the deviation was -0.05, and the corrected Sa fell out of U in every scan
  // (tests/server/procedures/uncertainty_sharpness_test.cc). Not corrected, then.
  for (int i = 0; i < 4; ++i) r.budgets[int(kMoment[i])] = MonteCarloBudget(mc[i]);
  const double range = LinearityRangeUm(depth_um, mask, *noise);
  // The focus window's flattening of curvature, estimated from the map (WindowAveragingError):
  // an uncorrected systematic error of every moment parameter (Sa, Sq of a 2 um cosine at a
  // 64 px period: -0.03 um), which the Monte Carlo's error model does not contain.
  const cv::Mat flattening = WindowAveragingError(depth_um, noise->correlation_px);
  INSPECT_ASSIGN_OR_RETURN(std::vector<double> unflattened, measure(depth_um - flattening));
  for (size_t i = 0; i < measured.size(); ++i) {
    AddEstimatedSystematic(r.budgets[int(kMoment[i])],
                           std::isfinite(unflattened[i]) ? unflattened[i] - measured[i] : 0.0);
  }
  // Shape parameters: the worst case of the z-linearity's height-dependent error, whose shape on
  // a curved surface is not the characterised table's (core/metrology/measurement_uncertainty.h),
  // among errors periodic in the z grid (PeriodicWorstCaseSign): the unconstrained worst case,
  // g = +-delta sign(d Ssk / d z), made Ssk and Sku U 3-6x their deviations (median |dev| / U
  // 0.08-0.17 for Sku on the held-out scenes). The bins are those of a characterisation
  // (ZLinearityOptions::bins): the finest shape a table resolves.
  // A table characterised at this step is known in shape to ~20 % (core/metrology/z_linearity.h:
  // SKEW5 / SKEW10 / the ground-metal wedge agree within that) and the Monte Carlo draws it at
  // every phase: only the shape's deviation is a worst case. Transferred from another step or a
  // bound, the shape is not known: the whole half-range.
  constexpr double kTableShapeTolerance = 0.2;
  const double delta_um = 0.5 * range * (noise->linearity_shape_known ? kTableShapeTolerance : 1.0);
  for (const HeightParameter shape : {HeightParameter::kSsk, HeightParameter::kSku}) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat sign,
                             PeriodicWorstCaseSign(depth_um, e.surface_um, shape, *noise, kPeriodicErrorBins));
    const size_t out = shape == HeightParameter::kSsk ? 2 : 3;
    double bound = 0.0;
    for (const double direction : {1.0, -1.0}) {
      cv::Mat shifted = depth_um + sign * (direction * delta_um);
      StatusOr<std::vector<double>> v = measure(shifted);
      if (v.ok() && std::isfinite((*v)[out])) bound = std::max(bound, std::abs((*v)[out] - measured[out]));
    }
    AddHeightDependentBound(r.budgets[int(shape)], bound);
  }
  // Extremes: the errors that can reach the peak and the valley (ExtremeErrorUm), not the
  // largest anywhere in the region.
  const double peak_um = ExtremeErrorUm(e.surface_um, *noise, true);
  const double valley_um = ExtremeErrorUm(e.surface_um, *noise, false);
  r.budgets[int(HeightParameter::kSp)] = ExtremeValueBudgetUm(peak_um, range);
  r.budgets[int(HeightParameter::kSv)] = ExtremeValueBudgetUm(valley_um, range);
  r.budgets[int(HeightParameter::kSz)] = ExtremeValueBudgetUm(peak_um + valley_um, range);
  return r;
}

std::string RoiKey(const RegionOfInterest& roi) {
  std::ostringstream s;
  s.precision(17);
  s << int(roi.shape) << ' ' << int(roi.unit) << ' ' << roi.x << ' ' << roi.y << ' ' << roi.width << ' ' << roi.height;
  for (const RoiPoint& p : roi.polygon) s << ' ' << p.x << ',' << p.y;
  return s.str();
}

std::string ArealKey(const MeasurementSpec& spec) {
  std::ostringstream s;
  s.precision(17);
  s << RoiKey(spec.roi) << '|' << int(spec.areal.form.model) << ' ' << spec.areal.form.polynomial_order << ' '
    << spec.areal.form.max_iterations << ' ' << spec.areal.s_filter_cutoff_um << ' ' << spec.areal.l_filter_cutoff_um;
  return s.str();
}

// Rasterised regions of a spec and the error model over them.
struct Regions {
  RoiMask roi;
  std::optional<RoiMask> reference;
  std::optional<DepthNoiseModel> noise;
  double coverage_percent() const {
    double c = roi.coverage_percent();
    if (reference) c = std::min(c, reference->coverage_percent());
    return c;
  }
};

StatusOr<Regions> PrepareRegions(const MeasurementSpec& spec, const MeasurementContext& ctx, const std::string& field) {
  INSPECT_RETURN_IF_ERROR(spec.Validate(ctx.depth_um.size(), ctx.pixel_size_um, field));
  Regions r;
  INSPECT_ASSIGN_OR_RETURN(r.roi, RasteriseRoi(spec.roi, ctx.depth_um, ctx.pixel_size_um, field + ".roi"));
  if (spec.reference_roi) {
    INSPECT_ASSIGN_OR_RETURN(
        r.reference, RasteriseRoi(*spec.reference_roi, ctx.depth_um, ctx.pixel_size_um, field + ".reference_roi"));
  }
  if (r.roi.measured_pixels == 0) return Status::FailedPrecondition(field + ".roi: no pixel of the region has depth");
  if (r.reference && r.reference->measured_pixels == 0) {
    return Status::FailedPrecondition(field + ".reference_roi: no pixel of the region has depth");
  }
  if (ctx.with_uncertainty) {
    const cv::Mat mask = r.reference ? (r.roi.measured | r.reference->measured) : r.roi.measured;
    StatusOr<DepthNoiseModel> m = EstimateDepthNoise(ctx.depth_um, mask, ctx.noise);
    if (!m.ok()) return m.status().WithContext(field);
    r.noise = std::move(m).value();
  }
  return r;
}

MeasuredValue Base(const MeasurementSpec& spec, const Regions& r) {
  MeasuredValue v;
  v.kind = spec.kind;
  v.unit = spec.unit();
  v.coverage_percent = r.coverage_percent();
  v.region_pixels = r.roi.region_pixels;
  v.measured_pixels = r.roi.measured_pixels;
  return v;
}

StatusOr<MeasuredValue> MeasureNonAreal(const MeasurementSpec& spec, const MeasurementContext& ctx, const Regions& r,
                                        const std::string& field) {
  const DepthNoiseModel* noise = r.noise ? &*r.noise : nullptr;
  MeasuredValue v = Base(spec, r);
  switch (spec.kind) {
    case MeasurementKind::kStepHeight: {
      StatusOr<StepHeightResult> s =
          MeasureStepHeight(ctx.depth_um, r.reference->measured, r.roi.measured, ctx.pixel_size_um, spec.step, noise);
      if (!s.ok()) return s.status().WithContext(field);
      v.value = s->height_um;
      v.uncertainty = s->uncertainty;
      return v;
    }
    case MeasurementKind::kFlatness: {
      StatusOr<FlatnessResult> f = MeasureFlatness(ctx.depth_um, r.roi.measured, ctx.pixel_size_um, noise);
      if (!f.ok()) return f.status().WithContext(field);
      v.value = f->flatness_um;
      v.uncertainty = f->uncertainty;
      return v;
    }
    case MeasurementKind::kTilt: {
      StatusOr<TiltResult> t = MeasureTilt(ctx.depth_um, r.roi.measured, ctx.pixel_size_um, noise);
      if (!t.ok()) return t.status().WithContext(field);
      v.value = t->tilt_deg;
      v.uncertainty = t->uncertainty;
      return v;
    }
    case MeasurementKind::kVolumeAbove:
    case MeasurementKind::kVolumeBelow: {
      const cv::Mat reference = r.reference ? r.reference->measured : cv::Mat();
      StatusOr<VolumeResult> vol =
          MeasureVolume(ctx.depth_um, r.roi.region, reference, ctx.pixel_size_um, spec.volume, noise, ctx.monte_carlo);
      if (!vol.ok()) return vol.status().WithContext(field);
      const bool above = spec.kind == MeasurementKind::kVolumeAbove;
      const double scale = spec.volume_unit == VolumeUnit::kCubicMillimetre ? 1e-9 : 1.0;
      v.value = (above ? vol->above_um3 : vol->below_um3) * scale;
      v.uncertainty = above ? vol->above_uncertainty : vol->below_uncertainty;
      for (double* d : {&v.uncertainty.standard_uncertainty, &v.uncertainty.monte_carlo_spread,
                        &v.uncertainty.noise_bias, &v.uncertainty.other}) {
        *d *= scale;
      }
      return v;
    }
    case MeasurementKind::kRadius: {
      StatusOr<FormFit> f = FitForm(ctx.depth_um, r.roi.measured, ctx.pixel_size_um, spec.form);
      if (!f.ok()) return f.status().WithContext(field);
      const int k = f->ParameterIndex("radius_um");
      v.value = f->parameters[k];
      if (noise) {
        StatusOr<FunctionalCovariance> cov =
            FormFitCovariance(*f, ctx.depth_um, r.roi.measured, ctx.pixel_size_um, *noise);
        if (!cov.ok()) return cov.status().WithContext(field);
        Eigen::VectorXd c = Eigen::VectorXd::Zero(f->parameters.size());
        c[k] = 1.0;
        v.uncertainty = AnalyticBudget(*cov, c);
      }
      return v;
    }
    default:
      break;
  }
  return Status::Internal(field + ": unhandled measurement kind");
}

}  // namespace

const char* MeasurementKindName(MeasurementKind kind) {
  if (IsHeightParameter(kind)) return HeightParameterName(ToHeightParameter(kind));
  switch (kind) {
    case MeasurementKind::kStepHeight:
      return "step_height";
    case MeasurementKind::kFlatness:
      return "flatness";
    case MeasurementKind::kTilt:
      return "tilt";
    case MeasurementKind::kVolumeAbove:
      return "volume_above";
    case MeasurementKind::kVolumeBelow:
      return "volume_below";
    case MeasurementKind::kRadius:
      return "radius";
    default:
      break;
  }
  return "unknown";
}

std::vector<MeasurementKind> AllMeasurementKinds() {
  std::vector<MeasurementKind> all;
  for (int k = 0; k <= int(MeasurementKind::kRadius); ++k) all.push_back(MeasurementKind(k));
  return all;
}

StatusOr<MeasurementKind> ParseMeasurementKind(const std::string& name) {
  std::string known;
  for (MeasurementKind k : AllMeasurementKinds()) {
    if (name == MeasurementKindName(k)) return k;
    known += (known.empty() ? "" : ", ") + std::string(MeasurementKindName(k));
  }
  return Status::InvalidArgument("unknown measurement parameter '" + name + "' (" + known + ")");
}

std::string MeasurementSpec::unit() const {
  if (IsHeightParameter(kind)) return HeightParameterUnit(ToHeightParameter(kind));
  switch (kind) {
    case MeasurementKind::kTilt:
      return "deg";
    case MeasurementKind::kVolumeAbove:
    case MeasurementKind::kVolumeBelow:
      return volume_unit == VolumeUnit::kCubicMillimetre ? "mm3" : "um3";
    default:
      return "um";
  }
}

Status MeasurementSpec::Validate(cv::Size image_size, double pixel_size_um, const std::string& field) const {
  if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um)) {
    return Status::InvalidArgument(field + ": the depth map needs a pixel size > 0");
  }
  INSPECT_RETURN_IF_ERROR(ValidateRoi(roi, image_size, pixel_size_um, field + ".roi"));
  const bool wants_reference = kind == MeasurementKind::kStepHeight;
  const bool takes_reference =
      wants_reference || ((kind == MeasurementKind::kVolumeAbove || kind == MeasurementKind::kVolumeBelow) &&
                          volume.reference == VolumeReference::kRegionPlane);
  if (wants_reference && !reference_roi) {
    return Status::InvalidArgument(field + ".reference_roi is required for " + MeasurementKindName(kind));
  }
  if (reference_roi && !takes_reference) {
    return Status::InvalidArgument(field + ".reference_roi is not used by " + std::string(MeasurementKindName(kind)) +
                                   (kind == MeasurementKind::kVolumeAbove || kind == MeasurementKind::kVolumeBelow
                                        ? " with reference height"
                                        : ""));
  }
  if (reference_roi)
    INSPECT_RETURN_IF_ERROR(ValidateRoi(*reference_roi, image_size, pixel_size_um, field + ".reference_roi"));
  if (IsHeightParameter(kind)) {
    const Status s = areal.Validate();
    if (!s.ok()) return s.WithContext(field + ".areal");
  }
  if (kind == MeasurementKind::kRadius) {
    if (form.model != FormModel::kSphere && form.model != FormModel::kCylinder) {
      return Status::InvalidArgument(field + ".form.model must be sphere or cylinder for radius");
    }
    const Status s = form.Validate();
    if (!s.ok()) return s.WithContext(field + ".form");
  }
  if ((kind == MeasurementKind::kVolumeAbove || kind == MeasurementKind::kVolumeBelow) &&
      volume.reference == VolumeReference::kHeight && !std::isfinite(volume.reference_height_um)) {
    return Status::InvalidArgument(field + ".volume.reference_height_um is not a finite number");
  }
  return Status::Ok();
}

namespace {

// A verified amplification's uncertainty (VerifiedCharacteristics) on height-scale values.
void AddAmplification(MeasuredValue& v, const DepthNoiseModel& noise) {
  if (!(noise.relative_amplification_u > 0.0)) return;
  switch (v.kind) {
    case MeasurementKind::kSsk:
    case MeasurementKind::kSku:
    case MeasurementKind::kTilt:
    case MeasurementKind::kRadius:
      return;  // shape ratios; tilt and radius mix the height scale with the lateral one (not verified here)
    default:
      break;
  }
  const double u = noise.relative_amplification_u * std::abs(v.value);
  v.uncertainty.amplification = u;
  const double before = std::isfinite(v.uncertainty.standard_uncertainty) ? v.uncertainty.standard_uncertainty : 0.0;
  v.uncertainty.standard_uncertainty = std::hypot(before, u);
}

std::vector<StatusOr<MeasuredValue>> MeasureSpecs(const std::vector<const MeasurementSpec*>& specs,
                                                  const MeasurementContext& context,
                                                  const std::function<std::string(size_t)>& field_of) {
  std::vector<StatusOr<MeasuredValue>> out;
  std::map<std::string, StatusOr<ArealGroupResult>> areal_cache;
  std::map<std::string, Regions> region_cache;
  for (size_t i = 0; i < specs.size(); ++i) {
    const MeasurementSpec& spec = *specs[i];
    const std::string field = field_of(i);
    if (context.depth_um.empty() || context.depth_um.type() != CV_32FC1) {
      out.push_back(Status::InvalidArgument(field + ": the depth map must be a non-empty CV_32FC1 image"));
      continue;
    }
    // Specs on the same region(s) share the rasterisation and the error model.
    const std::string regions_key = RoiKey(spec.roi) + "|" + (spec.reference_roi ? RoiKey(*spec.reference_roi) : "-");
    auto cached = region_cache.find(regions_key);
    StatusOr<Regions> regions = Status::Internal("unset");
    if (cached != region_cache.end()) {
      const Status valid = spec.Validate(context.depth_um.size(), context.pixel_size_um, field);
      regions = valid.ok() ? StatusOr<Regions>(cached->second) : StatusOr<Regions>(valid);
    } else {
      regions = PrepareRegions(spec, context, field);
      if (regions.ok()) region_cache.emplace(regions_key, *regions);
    }
    if (!regions.ok()) {
      out.push_back(regions.status());
      continue;
    }
    if (!IsHeightParameter(spec.kind)) {
      StatusOr<MeasuredValue> v = MeasureNonAreal(spec, context, *regions, field);
      if (v.ok() && regions->noise) AddAmplification(*v, *regions->noise);
      out.push_back(std::move(v));
      continue;
    }
    const std::string key = ArealKey(spec);
    auto it = areal_cache.find(key);
    if (it == areal_cache.end()) {
      it = areal_cache
               .emplace(key,
                        EvaluateArealGroup(context.depth_um, regions->roi.measured, context.pixel_size_um, spec.areal,
                                           regions->noise ? &*regions->noise : nullptr, context.monte_carlo))
               .first;
    }
    if (!it->second.ok()) {
      out.push_back(it->second.status().WithContext(field));
      continue;
    }
    MeasuredValue v = Base(spec, *regions);
    v.value = HeightParameterValue(it->second->values, ToHeightParameter(spec.kind));
    v.uncertainty = it->second->budgets[int(ToHeightParameter(spec.kind))];
    if (regions->noise) AddAmplification(v, *regions->noise);
    out.push_back(std::move(v));
  }
  return out;
}

}  // namespace

StatusOr<MeasuredValue> Measure(const MeasurementSpec& spec, const MeasurementContext& context,
                                const std::string& field) {
  return std::move(MeasureSpecs({&spec}, context, [&](size_t) { return field; }).front());
}

std::vector<StatusOr<MeasuredValue>> MeasureAll(const std::vector<MeasurementSpec>& specs,
                                                const MeasurementContext& context, const std::string& field_prefix) {
  std::vector<const MeasurementSpec*> ptrs;
  for (const MeasurementSpec& s : specs) ptrs.push_back(&s);
  return MeasureSpecs(ptrs, context, [&](size_t i) { return field_prefix + "[" + std::to_string(i) + "]"; });
}

}  // namespace inspection
