// Type-1 study figures per recipe measurement, and the capability warnings on verdicts.
#include "server/results/study_result.h"

#include <cmath>
#include <cstdio>

#include "core/metrology/capability.h"

namespace inspection {

Status CheckStudyRecipe(const v1::Recipe& recipe, const google::protobuf::Map<std::string, double>& references) {
  for (int i = 0; i < recipe.measurements_size(); ++i) {
    const v1::RecipeMeasurement& m = recipe.measurements(i);
    const std::string field = "recipe '" + recipe.recipe_id() + "' measurements[" + std::to_string(i) + "] ('" +
                              m.name() + "').tolerance";
    if (!m.has_tolerance()) return Status::InvalidArgument(field + ": a Type-1 study needs a tolerance");
    if (!m.tolerance().has_lower() || !m.tolerance().has_upper()) {
      return Status::InvalidArgument(field + ": a Type-1 study needs both lower and upper (T = USL - LSL)");
    }
    if (!(m.tolerance().upper() - m.tolerance().lower() > 0.0)) {
      return Status::InvalidArgument(field + ": upper - lower must be > 0");
    }
  }
  for (const auto& [name, value] : references) {
    bool known = false;
    for (const auto& m : recipe.measurements()) known = known || m.name() == name;
    if (!known) {
      return Status::InvalidArgument("reference_values['" + name + "']: recipe '" + recipe.recipe_id() +
                                     "' has no measurement of that name");
    }
    if (!std::isfinite(value)) return Status::InvalidArgument("reference_values['" + name + "'] must be finite");
  }
  return Status::Ok();
}

StatusOr<std::vector<v1::MeasurementCapability>> StudyCapabilities(
    const v1::Recipe& recipe, const google::protobuf::Map<std::string, double>& references,
    const std::vector<v1::InspectionResult>& repeats) {
  INSPECT_RETURN_IF_ERROR(CheckStudyRecipe(recipe, references));
  std::vector<v1::MeasurementCapability> out;
  for (int k = 0; k < recipe.measurements_size(); ++k) {
    const v1::RecipeMeasurement& m = recipe.measurements(k);
    v1::MeasurementCapability c;
    c.set_name(m.name());
    c.set_parameter(m.parameter());
    Type1StudyInput in;
    double sum_u = 0.0;
    for (size_t r = 0; r < repeats.size(); ++r) {
      if (repeats[r].measurements_size() != recipe.measurements_size()) {
        return Status::Internal("repeat " + std::to_string(r + 1) + " has " +
                                std::to_string(repeats[r].measurements_size()) + " measurements, the recipe " +
                                std::to_string(recipe.measurements_size()));
      }
      const v1::MeasurementResult& v = repeats[r].measurements(k);
      if (!v.measured() || !std::isfinite(v.value())) {
        return Status::FailedPrecondition("repeat " + std::to_string(r + 1) + ": measurement '" + m.name() +
                                          "' could not be made (" + v.reason() + "); a study needs every value");
      }
      c.set_unit(v.unit());
      c.add_values(v.value());
      c.add_expanded_uncertainties(v.expanded_uncertainty());
      in.values.push_back(v.value());
      sum_u += v.expanded_uncertainty();
    }
    const auto ref = references.find(m.name());
    in.reference = ref != references.end() ? ref->second : m.tolerance().nominal();
    c.set_reference_source(ref != references.end() ? "reference_values" : "nominal (no reference value given)");
    in.tolerance = m.tolerance().upper() - m.tolerance().lower();
    in.expanded_uncertainty = repeats.empty() ? NAN : sum_u / double(repeats.size());
    StatusOr<GaugeCapability> g = ComputeType1Capability(in);
    if (!g.ok()) return g.status().WithContext("measurement '" + m.name() + "'");
    c.set_n(g->n);
    c.set_mean(g->mean);
    c.set_stddev(g->stddev);
    c.set_reference(in.reference);
    c.set_tolerance(in.tolerance);
    c.set_cg(g->cg);
    c.set_cgk(g->cgk);
    c.set_bias(g->bias);
    c.set_t_statistic(g->t_statistic);
    c.set_t_critical(g->t_critical);
    c.set_p_value(g->p_value);
    c.set_bias_significant(g->bias_significant);
    c.set_mean_expanded_uncertainty(in.expanded_uncertainty);
    c.set_u_over_t_percent(g->u_over_t_percent);
    c.set_capable(g->capable);
    c.set_reason(g->reason);
    out.push_back(std::move(c));
  }
  return out;
}

void ApplyCapabilityWarnings(const v1::Study& study, v1::InspectionResult* inspection) {
  if (study.recipe_id() != inspection->recipe_id() || study.recipe_version() != inspection->recipe_version()) return;
  for (v1::MeasurementResult& m : *inspection->mutable_measurements()) {
    for (const v1::MeasurementCapability& c : study.measurements()) {
      if (c.name() != m.name() || c.capable()) continue;
      char text[256];
      std::snprintf(text, sizeof text, "gauge not capable (Type-1 study %s: Cg %.3f, Cgk %.3f; 1.33 needed)",
                    study.study_id().c_str(), c.cg(), c.cgk());
      m.set_capability_warning(text);
    }
  }
}

}  // namespace inspection
