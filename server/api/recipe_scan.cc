// MapScanRequestWithRecipe: a ScanRequest with or without a recipe, as ScanWork.
#include "server/api/recipe_scan.h"

namespace inspection {
namespace {

// The scan fields a recipe fixes: the request must leave them unset.
Status CheckNoScanFields(const v1::ScanRequest& r, const std::string& recipe_id) {
  const std::string why = " is fixed by recipe '" + recipe_id + "'; leave it unset";
  if (r.z_start_um() != 0) return Status::InvalidArgument("z_start_um" + why);
  if (r.z_end_um() != 0) return Status::InvalidArgument("z_end_um" + why);
  if (r.z_step_um() != 0) return Status::InvalidArgument("z_step_um" + why);
  if (r.exposure_us() != 0) return Status::InvalidArgument("exposure_us" + why);
  if (r.illumination() != v1::ILLUMINATION_MODE_UNSPECIFIED) return Status::InvalidArgument("illumination" + why);
  // Present but empty messages (clients that always fill them) fix nothing.
  if (r.illumination_parameters().ByteSizeLong() > 0) {
    return Status::InvalidArgument("illumination_parameters" + why);
  }
  if (r.reconstruction().ByteSizeLong() > 0) return Status::InvalidArgument("reconstruction" + why);
  if (r.z_range_search().ByteSizeLong() > 0) return Status::InvalidArgument("z_range_search" + why);
  return Status::Ok();
}

}  // namespace

StatusOr<ScanWork> MapScanRequestWithRecipe(const v1::ScanRequest& request, const ScanContext& context,
                                            DataStore& store, cv::Size image_size, double pixel_size_um) {
  if (request.recipe_id().empty()) {
    if (request.recipe_version() != 0) return Status::InvalidArgument("recipe_version needs recipe_id");
    INSPECT_ASSIGN_OR_RETURN(ScanWork work, MapScanRequest(request, context));
    work.part_id = request.part_id();
    work.station = request.station();
    return work;
  }
  INSPECT_RETURN_IF_ERROR(CheckRecipeName(request.recipe_id(), "recipe_id"));
  if (request.recipe_version() < 0) return Status::InvalidArgument("recipe_version must be >= 0 (0 = the current one)");
  INSPECT_RETURN_IF_ERROR(CheckNoScanFields(request, request.recipe_id()));
  INSPECT_ASSIGN_OR_RETURN(v1::Recipe recipe, store.GetRecipe(request.recipe_id(), request.recipe_version()));
  v1::ScanRequest scan = ScanRequestOfRecipe(recipe.scan());
  auto mapped = MapScanRequest(scan, context);
  if (!mapped.ok()) {
    return Status(mapped.status().code(), "recipe '" + recipe.recipe_id() + "' version " +
                                              std::to_string(recipe.version()) +
                                              ": recipe.scan: " + mapped.status().message());
  }
  ScanWork work = std::move(*mapped);
  work.part_id = request.part_id();
  work.station = request.station();
  auto run = std::make_shared<RecipeRun>();
  // Checked when stored; checked again here because the camera may have changed since.
  INSPECT_ASSIGN_OR_RETURN(run->plans, MapRecipeMeasurements(recipe, image_size, pixel_size_um));
  INSPECT_ASSIGN_OR_RETURN(run->profiles, MapRecipeProfiles(recipe, image_size, pixel_size_um));
  run->recipe = std::move(recipe);
  work.recipe = std::move(run);
  return work;
}

}  // namespace inspection
