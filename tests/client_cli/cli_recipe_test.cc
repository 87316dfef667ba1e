// inspectctl recipe as an engineer runs it: the built binary against the real server. A JSON
// document goes in, the stored version comes back; `get` prints a document `update` accepts; a
// misspelt field is refused locally (exit 2, one line) and an unknown id is NOT_FOUND (exit 4).
#include <fstream>

#include "tests/client_cli/cli_fixture.h"

namespace inspection::testing {
namespace {

constexpr const char* kRecipe = R"({
  "recipe_id": "pad-check",
  "scan": {"z_step_um": 5},
  "measurements": [
    {"name": "pad_height", "parameter": "step_height",
     "roi": {"shape": "SHAPE_RECTANGLE", "x": 20, "y": 20, "width": 100, "height": 80},
     "reference_roi": {"shape": "SHAPE_RECTANGLE", "x": 180, "y": 20, "width": 100, "height": 80},
     "tolerance": {"nominal": 12.5, "lower": -0.5, "upper": 0.5}}
  ]})";

TEST_F(CliTest, RecipeCreateGetUpdateListDelete) {
  StartServer();
  const fs::path file = work_ / "pad.json";
  std::ofstream(file) << kRecipe;

  CliResult r = Run({"recipe", "create", file.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("recipe pad-check version 1 (1 measurements) by anonymous at ", 0), 0u) << r.out;

  // `get` prints the stored document; sent back with `update`, it becomes version 2.
  const fs::path got = work_ / "got.json";
  r = Run({"recipe", "get", "pad-check", "--out", got.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json doc = json::parse(ReadAll(got));
  EXPECT_EQ(doc["recipe_id"], "pad-check");
  EXPECT_EQ(doc["version"], 1);
  EXPECT_EQ(doc["measurements"][0]["tolerance"]["nominal"], 12.5);
  r = Run({"recipe", "update", got.string(), "--expected-version", "1"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("recipe pad-check version 2 ", 0), 0u) << r.out;
  r = Run({"recipe", "update", got.string(), "--expected-version", "1"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.err.rfind("inspectctl: ABORTED: ", 0), 0u) << r.err;

  r = Run({"--json", "recipe", "list"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto lines = JsonLines(r.out);
  ASSERT_EQ(lines.size(), 1u);
  ASSERT_EQ(lines[0]["recipes"].size(), 1u);
  EXPECT_EQ(lines[0]["recipes"][0]["version"], 2);

  r = Run({"recipe", "delete", "pad-check"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "deleted recipe pad-check\n");
  r = Run({"recipe", "get", "pad-check"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("inspectctl: NOT_FOUND: recipe_id 'pad-check' not found", 0), 0u) << r.err;
}

TEST_F(CliTest, RecipeDocumentsWithUnknownFieldsOrBadValuesAreRefused) {
  StartServer();
  const fs::path typo = work_ / "typo.json";
  std::string text = kRecipe;
  text.replace(text.find("\"parameter\""), 11, "\"parametr\"");
  std::ofstream(typo) << text;
  CliResult r = Run({"recipe", "create", typo.string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("not a recipe document"), std::string::npos) << r.err;

  const fs::path outside = work_ / "outside.json";
  text = kRecipe;
  text.replace(text.find("\"x\": 180"), 8, "\"x\": 900");
  std::ofstream(outside) << text;
  r = Run({"recipe", "create", outside.string()});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("inspectctl: INVALID_ARGUMENT: recipe.measurements[0].reference_roi", 0), 0u) << r.err;

  r = Run({"recipe", "create", (work_ / "missing.json").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("cannot read recipe file"), std::string::npos) << r.err;
}

TEST_F(CliTest, ScanWithARecipePrintsTheVerdicts) {
  StartServer();  // skew5: a plane tilted by 5 deg
  const fs::path file = work_ / "tilt.json";
  std::ofstream(file) << R"({"recipe_id": "tilt-check", "measurements": [
      {"name": "tilt_in", "parameter": "tilt", "tolerance": {"nominal": 5.0, "lower": -0.5, "upper": 0.5}}]})";
  ASSERT_EQ(Run({"recipe", "create", file.string()}).exit_code, 0);
  CliResult r = Run(
      {"scan", "--recipe", "tilt-check", "--part-id", "4711", "--station", "st-7", "--out", (work_ / "part").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("inspection: recipe tilt-check v1, part 4711, station st-7: OK\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  tilt_in          tilt         "), std::string::npos) << r.out;
  r = Run({"scan", "--recipe", "tilt-check", "--z-step", "2", "--out", (work_ / "bad").string()});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.err, "inspectctl: INVALID_ARGUMENT: z_start_um is fixed by recipe 'tilt-check'; leave it unset\n");
}

}  // namespace
}  // namespace inspection::testing
