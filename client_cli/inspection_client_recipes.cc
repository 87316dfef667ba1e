// InspectionClient: the recipe and result RPCs (unary ones with the client's deadline; the result
// feed without one) and credentials.
#include "client_cli/inspection_client.h"

namespace inspection::client {

grpc::Status InspectionClient::CreateRecipe(const v1::Recipe& recipe, v1::Recipe* stored) {
  v1::CreateRecipeRequest request;
  *request.mutable_recipe() = recipe;
  return Unary(&v1::InspectionService::Stub::CreateRecipe, request, stored);
}

grpc::Status InspectionClient::UpdateRecipe(const v1::Recipe& recipe, int expected_version, v1::Recipe* stored) {
  v1::UpdateRecipeRequest request;
  *request.mutable_recipe() = recipe;
  request.set_expected_version(expected_version);
  return Unary(&v1::InspectionService::Stub::UpdateRecipe, request, stored);
}

grpc::Status InspectionClient::GetRecipe(const std::string& recipe_id, int version, v1::Recipe* recipe) {
  v1::GetRecipeRequest request;
  request.set_recipe_id(recipe_id);
  request.set_version(version);
  return Unary(&v1::InspectionService::Stub::GetRecipe, request, recipe);
}

grpc::Status InspectionClient::ListRecipes(v1::ListRecipesResponse* response) {
  return Unary(&v1::InspectionService::Stub::ListRecipes, v1::ListRecipesRequest(), response);
}

grpc::Status InspectionClient::DeleteRecipe(const std::string& recipe_id, v1::DeleteResponse* response) {
  v1::DeleteRecipeRequest request;
  request.set_recipe_id(recipe_id);
  return Unary(&v1::InspectionService::Stub::DeleteRecipe, request, response);
}

grpc::Status InspectionClient::ListResults(const v1::ListResultsRequest& request, v1::ListResultsResponse* response) {
  return Unary(&v1::InspectionService::Stub::ListResults, request, response);
}

grpc::Status InspectionClient::WatchResults(int64_t after_sequence,
                                            const std::function<bool(const v1::InspectionResult&)>& on_result) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  Prepare(&ctx);  // no deadline: a feed stays open
  v1::WatchResultsRequest request;
  request.set_after_sequence(after_sequence);
  auto reader = stub_->WatchResults(&ctx, request);
  v1::InspectionResult result;
  bool stopped = false;
  while (reader->Read(&result)) {
    if (!on_result(result)) {
      stopped = true;
      ctx.TryCancel();
      break;
    }
  }
  grpc::Status status = reader->Finish();
  return stopped ? grpc::Status::OK : status;
}

}  // namespace inspection::client
