// InspectionClient: the recipe RPCs (unary, with the client's deadline and credentials).
#include "client_cli/inspection_client.h"

namespace inspection::client {

grpc::Status InspectionClient::CreateRecipe(const v1::Recipe& recipe, v1::Recipe* stored) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  PrepareUnary(&ctx);
  v1::CreateRecipeRequest request;
  *request.mutable_recipe() = recipe;
  return stub_->CreateRecipe(&ctx, request, stored);
}

grpc::Status InspectionClient::UpdateRecipe(const v1::Recipe& recipe, int expected_version, v1::Recipe* stored) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  PrepareUnary(&ctx);
  v1::UpdateRecipeRequest request;
  *request.mutable_recipe() = recipe;
  request.set_expected_version(expected_version);
  return stub_->UpdateRecipe(&ctx, request, stored);
}

grpc::Status InspectionClient::GetRecipe(const std::string& recipe_id, int version, v1::Recipe* recipe) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  PrepareUnary(&ctx);
  v1::GetRecipeRequest request;
  request.set_recipe_id(recipe_id);
  request.set_version(version);
  return stub_->GetRecipe(&ctx, request, recipe);
}

grpc::Status InspectionClient::ListRecipes(v1::ListRecipesResponse* response) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  PrepareUnary(&ctx);
  return stub_->ListRecipes(&ctx, v1::ListRecipesRequest(), response);
}

grpc::Status InspectionClient::DeleteRecipe(const std::string& recipe_id, v1::DeleteResponse* response) {
  if (!init_status_.ok()) return init_status_;
  grpc::ClientContext ctx;
  PrepareUnary(&ctx);
  v1::DeleteRecipeRequest request;
  request.set_recipe_id(recipe_id);
  return stub_->DeleteRecipe(&ctx, request, response);
}

}  // namespace inspection::client
