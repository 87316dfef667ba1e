// An inspection: a recipe's measurements made on one part's depth map and judged against their
// tolerances (core/metrology/measurement.h measures, core/metrology/verdict.h decides per ISO 14253-1).
// The result names the recipe version, part and station, so an MES can act on it alone.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/metrology/depth_noise_model.h"
#include "core/sff/sff_engine.h"
#include "inspection/v1/inspection.pb.h"
#include "server/results/recipe_mapping.h"

namespace inspection {

// A stored recipe as a scan runs it: the document (id and resolved version) and its
// measurements mapped for the rig's image (checked when the scan was submitted).
struct RecipeRun {
  v1::Recipe recipe;
  std::vector<RecipeMeasurementPlan> plans;
  std::vector<RecipeProfilePlan> profiles;
};

// Measures every measurement of `run` on `depth` (pixels of pixel_size_um) with the error model
// `noise` (the stack's z positions, the focus window, the stage's repeatability) and judges it:
// a measurement that cannot be made is NOT_DECIDABLE with the reason. The overall verdict is
// NOT_OK if any is NOT_OK, else NOT_DECIDABLE if any is, else OK. The recipe's line profiles
// come back as data (a profile the map cannot give has no samples and coverage 0).
v1::InspectionResult Inspect(const RecipeRun& run, const DepthResult& depth, double pixel_size_um,
                             const DepthNoiseOptions& noise, const std::string& part_id, const std::string& station);

v1::Verdict ToProtoVerdict(Verdict verdict);

}  // namespace inspection
