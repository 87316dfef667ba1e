// Inspect: recipe measurements on a depth map, with uncertainty and verdicts (issue 13).
#include "server/inspection_result.h"

#include "core/measurement.h"
#include "core/verdict.h"

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
      m->set_coverage_percent(v.coverage_percent);
      verdict = Judge(v.value, v.uncertainty.standard_uncertainty, v.coverage_percent, plan.tolerance);
      m->set_expanded_uncertainty(verdict.expanded_uncertainty);
    } else {
      verdict = NotMeasured(values[i].status().message());
    }
    m->set_verdict(ToProtoVerdict(verdict.verdict));
    m->set_reason(verdict.reason);
    verdicts.push_back(verdict.verdict);
  }
  out.set_verdict(ToProtoVerdict(OverallVerdict(verdicts)));
  return out;
}

}  // namespace inspection
