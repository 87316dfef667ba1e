// A Type-1 gauge study's figures from its repeats' inspection results (core/metrology/capability.h
// computes), and what a finished study means for later verdicts: a measurement the newest study
// of its recipe version found not capable carries a warning on every verdict.
#pragma once

#include <google/protobuf/map.h>

#include <string>
#include <vector>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"

namespace inspection {

// A recipe a study can judge: every measurement has a two-sided tolerance (T = USL - LSL > 0);
// every name in `references` is a measurement of the recipe and its value finite.
// INVALID_ARGUMENT naming the field (recipe.measurements[i].tolerance, reference_values[name]).
Status CheckStudyRecipe(const v1::Recipe& recipe, const google::protobuf::Map<std::string, double>& references);

// Per measurement of `recipe`, in order: the repeats' values and U, Cg, Cgk, the bias t-test,
// U/T. FAILED_PRECONDITION naming the repeat and measurement when one repeat could not measure it
// (a study needs every value).
StatusOr<std::vector<v1::MeasurementCapability>> StudyCapabilities(
    const v1::Recipe& recipe, const google::protobuf::Map<std::string, double>& references,
    const std::vector<v1::InspectionResult>& repeats);

// Sets MeasurementResult.capability_warning on every measurement of `inspection` that `study`
// (of the same recipe version) found not capable.
void ApplyCapabilityWarnings(const v1::Study& study, v1::InspectionResult* inspection);

}  // namespace inspection
