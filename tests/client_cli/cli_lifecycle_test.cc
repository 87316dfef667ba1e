// inspectctl delete / pin as a user runs them: the built binary against the real server on
// loopback. Checks exit codes, the printed line and the one-line error of a second delete.
#include "tests/client_cli/cli_fixture.h"

namespace inspection::testing {
namespace {

TEST_F(CliTest, DeleteAndPinAJob) {
  StartServer();
  v1::Job job;
  ASSERT_TRUE(client_->Scan(v1::ScanRequest(), {}, &job).ok());

  CliResult r = Run({"pin", job.job_id()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "job " + job.job_id() + " pinned\n");
  r = Run({"jobs"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find(" pinned"), std::string::npos) << r.out;
  r = Run({"pin", job.job_id(), "--unpin"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "job " + job.job_id() + " unpinned\n");
  r = Run({"jobs"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.find(" pinned"), std::string::npos) << r.out;

  r = Run({"delete", job.job_id()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("deleted job " + job.job_id() + ": ", 0), 0u) << r.out;
  EXPECT_NE(r.out.find(" bytes, " + std::to_string(job.result().artifacts_size()) + " artifacts\n"), std::string::npos)
      << r.out;
  EXPECT_FALSE(std::filesystem::exists(data_dir_ / "artifacts" / job.job_id()));

  r = Run({"delete", job.job_id()});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("inspectctl: NOT_FOUND: ", 0), 0u) << r.err;
}

}  // namespace
}  // namespace inspection::testing
