// A scan request as the job queue takes it, with or without a recipe: a request that
// names a recipe runs the recipe's scan section, and its measurements are made when the depth
// map is ready. The recipe document is resolved (id, version) and copied into the job at
// submission, so editing or deleting the recipe later never changes a queued scan.
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"
#include "server/storage/data_store.h"
#include "server/jobs/job_work.h"
#include "server/api/request_mapping.h"

namespace inspection {

// Without recipe_id: MapScanRequest, plus part_id and station. With one: NOT_FOUND for an unknown
// recipe or version; INVALID_ARGUMENT naming a scan field the request sets although the recipe
// fixes it; the recipe's scan section checked as MapScanRequest checks a request (errors prefixed
// "recipe.scan: "); the measurements mapped for the rig's image (image_size px of pixel_size_um).
StatusOr<ScanWork> MapScanRequestWithRecipe(const v1::ScanRequest& request, const ScanContext& context,
                                            DataStore& store, cv::Size image_size, double pixel_size_um);

}  // namespace inspection
