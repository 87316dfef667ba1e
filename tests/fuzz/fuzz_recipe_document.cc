// libFuzzer target: recipe documents as `inspectctl recipe create` and an MES send
// them: JSON text in protobuf's JSON mapping, or the binary message; then the server's full
// check (server/results/recipe_mapping.h) against a 320 x 240 px image of 0.74 um pixels, and for a
// valid recipe the mapping to core/ measurement specs. Each step must answer, never crash.
#include <google/protobuf/util/json_util.h>

#include <cstddef>
#include <cstdint>
#include <string>

#include "server/results/recipe_mapping.h"
#include "server/api/request_mapping.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  namespace v1 = inspection::v1;
  const std::string body(reinterpret_cast<const char*>(data + 1), size - 1);
  v1::Recipe recipe;
  bool parsed = false;
  if (data[0] % 2 == 0) {
    google::protobuf::util::JsonParseOptions options;
    options.ignore_unknown_fields = false;
    parsed = google::protobuf::util::JsonStringToMessage(body, &recipe, options).ok();
  } else {
    parsed = recipe.ParseFromString(body);
  }
  if (!parsed) return 0;
  v1::CreateRecipeRequest request;
  *request.mutable_recipe() = recipe;
  if (!inspection::CheckRequestTextLimits(request).ok()) return 0;
  const cv::Size image(320, 240);
  if (inspection::ValidateRecipe(recipe, image, 0.74).ok()) {
    auto plans = inspection::MapRecipeMeasurements(recipe, image, 0.74);
    if (!plans.ok()) __builtin_trap();  // a valid recipe must map
  }
  (void)inspection::ScanRequestOfRecipe(recipe.scan());
  return 0;
}
