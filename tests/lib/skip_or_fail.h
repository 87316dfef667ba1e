// A test that cannot run here (no root, a tool not installed, not under umockdev-run) skips on a
// developer's machine but fails in CI: a skipped check in CI is a check nobody ran. CI mode is
// INSPECT_REQUIRE_ALL_TESTS=1 in the environment (ctest sets it when the build was configured
// with -DINSPECT_REQUIRE_ALL_TESTS=ON, which deploy/dev.sh test does under CI=true).
//   INSPECT_SKIP_OR_FAIL() << "gwyddion-thumbnailer not installed";
// Like GTEST_SKIP() it returns from the current function (a TEST body or a fixture's SetUp).
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>

namespace inspection::testing_support {

inline bool RequireAllTests() {
  const char* v = std::getenv("INSPECT_REQUIRE_ALL_TESTS");
  return v != nullptr && std::strcmp(v, "1") == 0;
}

}  // namespace inspection::testing_support

// GTEST_SKIP() and FAIL() are both `return GTEST_MESSAGE_(text, result_type)`; choosing the result
// type at run time keeps the caller's `<< reason` attached in both modes.
#define INSPECT_SKIP_OR_FAIL()                                                                          \
  return ::testing::internal::AssertHelper(                                                            \
             ::inspection::testing_support::RequireAllTests() ? ::testing::TestPartResult::kFatalFailure \
                                                              : ::testing::TestPartResult::kSkip,        \
             __FILE__, __LINE__,                                                                        \
             ::inspection::testing_support::RequireAllTests()                                           \
                 ? "cannot run, and INSPECT_REQUIRE_ALL_TESTS=1 requires every test to run"              \
                 : "Skipped") = ::testing::Message()
