// inspectctl recipe create|update|get|list|delete: recipes as JSON documents in protobuf's JSON
// mapping of inspection.v1.Recipe (docs/inspectctl.md "Recipes"). Unknown field names in a document are
// refused here, before anything reaches the server; the server checks the rest.
#include <google/protobuf/util/json_util.h>

#include <fstream>
#include <iostream>
#include <sstream>

#include "client_cli/commands.h"

namespace inspection::client::cli {
namespace {

// A file that cannot be read or parsed is the caller's input: exit 2 with one line.
int LocalInputError(const std::string& message) {
  PrintErrorLine(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, message));
  return kExitUsage;
}

bool ReadRecipeFile(const std::string& path, v1::Recipe* recipe, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = "cannot read recipe file " + path;
    return false;
  }
  std::ostringstream text;
  text << in.rdbuf();
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = false;  // a misspelt field is an error, not a silent default
  const auto status = google::protobuf::util::JsonStringToMessage(text.str(), recipe, options);
  if (!status.ok()) {
    *error = path + ": not a recipe document: " + std::string(status.message());
    return false;
  }
  return true;
}

// "recipe pad-check version 3 (4 measurements) by qa-lead at 2026-11-26T01:02:03Z"
void PrintRecipe(const v1::Recipe& r, const Output& out) {
  if (out.json) {
    PrintJsonLine(ProtoJson(r));
    return;
  }
  std::cout << "recipe " << r.recipe_id() << " version " << r.version() << " (" << r.measurements_size()
            << " measurements) by " << (r.author().empty() ? "-" : r.author()) << " at " << TimeText(r.create_time())
            << '\n';
}

struct RecipeFileFlags {
  std::string file;
  int expected_version = 0;
};

int RunCreateOrUpdate(const RecipeFileFlags& f, bool create, Session& session) {
  v1::Recipe recipe;
  std::string error;
  if (!ReadRecipeFile(f.file, &recipe, &error)) return LocalInputError(error);
  v1::Recipe stored;
  const grpc::Status s = create ? session.client.CreateRecipe(recipe, &stored)
                                : session.client.UpdateRecipe(recipe, f.expected_version, &stored);
  if (!s.ok()) return ReportError(s);
  PrintRecipe(stored, session.out);
  return kExitOk;
}

struct RecipeGetFlags {
  std::string id;
  int version = 0;
  std::string out;
};

int RunGet(const RecipeGetFlags& f, Session& session) {
  v1::Recipe recipe;
  if (grpc::Status s = session.client.GetRecipe(f.id, f.version, &recipe); !s.ok()) return ReportError(s);
  if (f.out.empty()) {
    // The document itself, ready to edit and send back with `recipe update`.
    std::cout << ProtoJson(recipe).dump(2) << '\n';
    return kExitOk;
  }
  std::ofstream file(f.out, std::ios::binary | std::ios::trunc);
  file << ProtoJson(recipe).dump(2) << '\n';
  if (!file.flush()) return LocalInputError("cannot write " + f.out);
  PrintRecipe(recipe, session.out);
  return kExitOk;
}

int RunList(Session& session) {
  v1::ListRecipesResponse list;
  if (grpc::Status s = session.client.ListRecipes(&list); !s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(list));
    return kExitOk;
  }
  for (const v1::Recipe& r : list.recipes()) PrintRecipe(r, session.out);
  return kExitOk;
}

int RunDeleteRecipe(const std::string& id, Session& session) {
  v1::DeleteResponse deleted;
  if (grpc::Status s = session.client.DeleteRecipe(id, &deleted); !s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(deleted));
  } else {
    std::cout << "deleted recipe " << deleted.id() << '\n';
  }
  return kExitOk;
}

}  // namespace

void RegisterRecipeCommands(CLI::App& app, CliContext& context) {
  auto* recipe = app.add_subcommand("recipe", "Recipes: what to scan and what to measure (versioned)");
  recipe->require_subcommand(1);

  auto* create_cmd = recipe->add_subcommand("create", "Store a new recipe from a JSON file (engineer)");
  auto create = std::make_shared<RecipeFileFlags>();
  create_cmd->add_option("file", create->file, "Recipe document (JSON)")->required();
  context.AddCommand(create_cmd, [create](Session& session) { return RunCreateOrUpdate(*create, true, session); });

  auto* update_cmd = recipe->add_subcommand("update", "Store a new version of a recipe (engineer)");
  auto update = std::make_shared<RecipeFileFlags>();
  update_cmd->add_option("file", update->file, "Recipe document (JSON); recipe_id names the recipe")->required();
  update_cmd
      ->add_option("--expected-version", update->expected_version,
                   "Refuse (ABORTED) unless this is the current version")
      ->check(CLI::Range(1, 1 << 30));
  context.AddCommand(update_cmd, [update](Session& session) { return RunCreateOrUpdate(*update, false, session); });

  auto* get_cmd = recipe->add_subcommand("get", "Print a recipe document (or write it with --out)");
  auto get = std::make_shared<RecipeGetFlags>();
  get_cmd->add_option("recipe_id", get->id, "Recipe id")->required();
  get_cmd->add_option("--version", get->version, "Version (default: the current one)")->check(CLI::Range(1, 1 << 30));
  get_cmd->add_option("--out", get->out, "Write the document to this file");
  context.AddCommand(get_cmd, [get](Session& session) { return RunGet(*get, session); });

  auto* list_cmd = recipe->add_subcommand("list", "The current version of every recipe");
  context.AddCommand(list_cmd, [](Session& session) { return RunList(session); });

  auto* delete_cmd = recipe->add_subcommand("delete", "Delete a recipe, every version (engineer)");
  auto id = std::make_shared<std::string>();
  delete_cmd->add_option("recipe_id", *id, "Recipe id")->required();
  context.AddCommand(delete_cmd, [id](Session& session) { return RunDeleteRecipe(*id, session); });
}

}  // namespace inspection::client::cli
