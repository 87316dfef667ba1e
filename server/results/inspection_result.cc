// Inspect: recipe measurements on a depth map, with uncertainty and verdicts.
#include "server/results/inspection_result.h"

#include <algorithm>

#include "core/metrology/line_profile.h"
#include "core/metrology/measurement.h"
#include "core/metrology/surface_roi.h"
#include "core/metrology/verdict.h"

namespace inspection {

v1::Verdict ToProtoVerdict(Verdict verdict) {
  switch (verdict) {
    case Verdict::kOk:
      return v1::VERDICT_OK;
    case Verdict::kNotOk:
      return v1::VERDICT_NOT_OK;
    case Verdict::kNotDecidable:
      return v1::VERDICT_NOT_DECIDABLE;
  }
  return v1::VERDICT_UNSPECIFIED;
}

namespace {

void AddProfiles(const RecipeRun& run, const DepthResult& depth, double pixel_size_um,
                 const DepthNoiseOptions& noise_options, v1::InspectionResult* out) {
  if (run.profiles.empty()) return;
  // One error model of the whole map serves every profile (a profile crosses regions).
  StatusOr<DepthNoiseModel> noise = EstimateDepthNoise(depth.depth_um, cv::Mat(), noise_options);
  for (size_t i = 0; i < run.profiles.size(); ++i) {
    const RecipeProfilePlan& plan = run.profiles[i];
    v1::ProfileResult* p = out->add_profiles();
    p->set_name(plan.name);
    p->set_width_um(plan.options.width_px * pixel_size_um);
    StatusOr<LineProfile> profile =
        ExtractLineProfile(depth.depth_um, pixel_size_um, plan.options, noise.ok() ? &*noise : nullptr,
                           "recipe.profiles[" + std::to_string(i) + "]");
    if (!profile.ok()) continue;  // checked against the image when submitted; nothing to plot
    for (size_t k = 0; k < profile->position_um.size(); ++k) {
      p->add_position_um(profile->position_um[k]);
      p->add_height_um(profile->height_um[k]);
      p->add_standard_uncertainty_um(profile->uncertainty_um[k]);
    }
    p->set_coverage_percent(profile->coverage_percent());
  }
}

// Measured share of the measurement's region(s), the smaller of two; 0 when it cannot be formed.
double RegionCoverage(const MeasurementSpec& spec, const cv::Mat& depth_um, double pixel_size_um) {
  StatusOr<RoiMask> roi = RasteriseRoi(spec.roi, depth_um, pixel_size_um);
  if (!roi.ok()) return 0.0;
  double coverage = roi->coverage_percent();
  if (spec.reference_roi) {
    StatusOr<RoiMask> ref = RasteriseRoi(*spec.reference_roi, depth_um, pixel_size_um);
    coverage = ref.ok() ? std::min(coverage, ref->coverage_percent()) : 0.0;
  }
  return coverage;
}

}  // namespace

v1::InspectionResult Inspect(const RecipeRun& run, const DepthResult& depth, double pixel_size_um,
                             const DepthNoiseOptions& noise, const std::string& part_id, const std::string& station) {
  v1::InspectionResult out;
  out.set_recipe_id(run.recipe.recipe_id());
  out.set_recipe_version(run.recipe.version());
  out.set_part_id(part_id);
  out.set_station(station);
  MeasurementContext context;
  context.depth_um = depth.depth_um;
  context.pixel_size_um = pixel_size_um;
  context.noise = noise;
  std::vector<MeasurementSpec> specs;
  for (const RecipeMeasurementPlan& p : run.plans) specs.push_back(p.spec);
  const std::vector<StatusOr<MeasuredValue>> values = MeasureAll(specs, context, "recipe.measurements");
  std::vector<Verdict> verdicts;
  for (size_t i = 0; i < run.plans.size(); ++i) {
    const RecipeMeasurementPlan& plan = run.plans[i];
    v1::MeasurementResult* m = out.add_measurements();
    m->set_name(plan.name);
    m->set_parameter(MeasurementKindName(plan.spec.kind));
    m->set_unit(plan.spec.unit());
    if (int(i) < run.recipe.measurements_size()) *m->mutable_tolerance() = run.recipe.measurements(int(i)).tolerance();
    VerdictResult verdict;
    if (values[i].ok()) {
      const MeasuredValue& v = *values[i];
      m->set_measured(true);
      m->set_value(v.value);
      m->set_standard_uncertainty(v.uncertainty.standard_uncertainty);
      if (std::isfinite(v.uncertainty.amplification)) m->set_amplification_uncertainty(v.uncertainty.amplification);
      m->set_coverage_percent(v.coverage_percent);
      verdict = Judge(v.value, v.uncertainty.standard_uncertainty, v.coverage_percent, plan.tolerance);
      m->set_expanded_uncertainty(verdict.expanded_uncertainty);
    } else {
      // The region's coverage still tells the MES why (e.g. a textureless part: 3 % measured).
      m->set_coverage_percent(RegionCoverage(plan.spec, depth.depth_um, pixel_size_um));
      verdict = NotMeasured(values[i].status().message());
    }
    m->set_verdict(ToProtoVerdict(verdict.verdict));
    m->set_reason(verdict.reason);
    verdicts.push_back(verdict.verdict);
  }
  out.set_verdict(ToProtoVerdict(OverallVerdict(verdicts)));
  AddProfiles(run, depth, pixel_size_um, noise, &out);
  return out;
}

}  // namespace inspection
