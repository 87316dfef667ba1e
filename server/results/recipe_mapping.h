// Recipes (OPC 40100 style): the checks a recipe document passes before it is stored
// and its translation into core/ measurement specs and tolerances. Field names in errors are
// the document's ("recipe.measurements[2].roi.width"), so an engineer can fix the JSON they
// wrote. No storage here (server/storage/data_store.h) and no gRPC service (inspection_service.cc).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/metrology/line_profile.h"
#include "core/metrology/measurement.h"
#include "core/util/status.h"
#include "core/metrology/verdict.h"
#include "inspection/v1/inspection.pb.h"

namespace inspection {

inline constexpr size_t kMaxRecipeBytes = 256 * 1024;  // serialised; a recipe is a small document
inline constexpr int kMaxRecipeMeasurements = 64;
inline constexpr int kMaxRecipeProfiles = 16;

// [A-Za-z0-9_.-], 1..64 characters: ids and measurement names appear in file names, URLs and
// MES tags. INVALID_ARGUMENT naming `field`.
Status CheckRecipeName(const std::string& name, const std::string& field);

// One recipe measurement as core/ measures it, and its tolerance.
struct RecipeMeasurementPlan {
  std::string name;
  MeasurementSpec spec;
  Tolerance tolerance;
};

// Everything that can be checked without a depth map: ids and names, sizes, parameter names,
// options, tolerances (lower <= upper, at least one limit), and the regions against the image
// the rig delivers (image_size pixels of pixel_size_um: a region outside it is refused now, not
// when the part is on the stage). The scan section is checked by the caller (MapScanRequest).
// INVALID_ARGUMENT naming the field with the prefix "recipe.".
Status ValidateRecipe(const v1::Recipe& recipe, cv::Size image_size, double pixel_size_um);

// The measurements of a valid recipe, in order.
StatusOr<std::vector<RecipeMeasurementPlan>> MapRecipeMeasurements(const v1::Recipe& recipe, cv::Size image_size,
                                                                   double pixel_size_um);

// A recipe's line profile, mapped for the rig's image.
struct RecipeProfilePlan {
  std::string name;
  LineProfileOptions options;
};

// The profiles of a recipe (0..16), in order; INVALID_ARGUMENT naming "recipe.profiles[i]...".
StatusOr<std::vector<RecipeProfilePlan>> MapRecipeProfiles(const v1::Recipe& recipe, cv::Size image_size,
                                                           double pixel_size_um);

// The ScanRequest a recipe's scan section stands for (the MES adds part and station).
v1::ScanRequest ScanRequestOfRecipe(const v1::RecipeScan& scan);

}  // namespace inspection
