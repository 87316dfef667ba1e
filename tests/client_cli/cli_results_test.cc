// inspectctl results as an MES script or an operator runs it: the built binary against the real
// server. `list` filters and prints one line per result (all pages), `watch --count` follows the
// feed and resumes with --after; a bad time exits 2 with one line.
#include <fstream>
#include <sstream>

#include "tests/client_cli/cli_fixture.h"

namespace inspection::testing {
namespace {

constexpr const char* kRecipe = R"({
  "recipe_id": "tilt-check", "scan": {"z_step_um": 5},
  "measurements": [{"name": "tilt", "parameter": "tilt",
                    "tolerance": {"nominal": 5.0, "lower": -0.5, "upper": 0.5}}]})";

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

TEST_F(CliTest, ResultsListAndWatch) {
  StartServer();
  const fs::path file = work_ / "tilt.json";
  std::ofstream(file) << kRecipe;
  ASSERT_EQ(Run({"recipe", "create", file.string()}).exit_code, 0);
  for (const char* part : {"A-1", "A-2", "B-1"}) {
    const CliResult r = Run({"scan", "--recipe", "tilt-check", "--part-id", part, "--out", (work_ / part).string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }

  CliResult r = Run({"results", "list"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::vector<std::string> lines = Lines(r.out);
  ASSERT_EQ(lines.size(), 3u) << r.out;
  EXPECT_EQ(lines[0].rfind("3 ", 0), 0u) << lines[0];  // newest first, by sequence
  EXPECT_NE(lines[0].find(" part B-1 recipe tilt-check v1: OK (job scan-"), std::string::npos) << lines[0];
  EXPECT_EQ(lines[2].rfind("1 ", 0), 0u) << lines[2];

  r = Run({"results", "list", "--part-id", "A-2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_EQ(Lines(r.out).size(), 1u);
  EXPECT_NE(r.out.find(" part A-2 "), std::string::npos);
  EXPECT_EQ(Run({"results", "list", "--verdict", "not-ok"}).out, "");
  EXPECT_EQ(Lines(Run({"results", "list", "--limit", "2"}).out).size(), 2u);

  // The feed from the start, stopped after two; then resumed after the second.
  r = Run({"results", "watch", "--count", "2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  lines = Lines(r.out);
  ASSERT_EQ(lines.size(), 2u) << r.out;
  EXPECT_NE(lines[0].find(" part A-1 "), std::string::npos);
  EXPECT_NE(lines[1].find(" part A-2 "), std::string::npos);
  r = Run({"results", "watch", "--after", "2", "--count", "1", "--details"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("3 ", 0), 0u) << r.out;
  EXPECT_NE(r.out.find("  tilt             tilt         "), std::string::npos) << r.out;

  r = Run({"results", "list", "--since", "yesterday"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err,
            "inspectctl: INVALID_ARGUMENT: --since 'yesterday' is not an RFC 3339 time (e.g. "
            "2026-11-26T05:00:00Z)\n");
}

}  // namespace
}  // namespace inspection::testing
