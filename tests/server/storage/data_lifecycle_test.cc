// Data lifecycle: the retention selection on hand-made job lists, the disk-full mapping, the reserve.
#include "server/storage/data_lifecycle.h"

#include <gtest/gtest.h>

#include <cerrno>

namespace inspection {
namespace {

StoredJob Job(std::string id, int64_t end, int64_t bytes, bool finished = true, bool pinned = false) {
  return {std::move(id), end, bytes, finished, pinned};
}

TEST(DataLifecycleTest, AgeLimitDeletesOldFinishedJobsOldestFirst) {
  RetentionPolicy p;
  p.max_age_s = 3600;
  const int64_t now = 100000;
  auto del = SelectJobsToDelete(
      {Job("new", now - 10, 5), Job("old2", now - 7200, 5), Job("old1", now - 9000, 5), Job("edge", now - 3600, 5)}, p,
      now);
  EXPECT_EQ(del, (std::vector<std::string>{"old1", "old2"}));  // exactly max_age is kept
}

TEST(DataLifecycleTest, ByteBudgetDeletesOldestUntilUnderBudget) {
  RetentionPolicy p;
  p.max_bytes = 250;
  auto del = SelectJobsToDelete({Job("a", 1, 100), Job("b", 2, 100), Job("c", 3, 100), Job("d", 4, 100)}, p, 10);
  EXPECT_EQ(del, (std::vector<std::string>{"a", "b"}));  // 400 -> 200 <= 250
}

TEST(DataLifecycleTest, PinnedRunningAndKeepLastAreNeverDeleted) {
  RetentionPolicy p;
  p.max_bytes = 1;  // everything over budget
  p.keep_last = 1;
  auto del = SelectJobsToDelete({Job("running", 0, 1000, /*finished=*/false), Job("pinned", 1, 100, true, true),
                                 Job("old", 2, 100), Job("newest", 3, 100)},
                                p, 10);
  EXPECT_EQ(del, (std::vector<std::string>{"old"}));
}

TEST(DataLifecycleTest, NoLimitsDeleteNothing) {
  RetentionPolicy p;
  p.keep_last = 3;
  EXPECT_FALSE(p.enabled());
  EXPECT_TRUE(SelectJobsToDelete({Job("a", 1, 1 << 30)}, p, 1 << 30).empty());
  p.keep_last = -1;
  EXPECT_EQ(p.Validate().message(), "retention.keep_last must be >= 0");
}

TEST(DataLifecycleTest, FullDiskIsResourceExhaustedNotInternal) {
  Status full = WriteFailure(ENOSPC, "cannot write frame_0009.png");
  EXPECT_EQ(full.code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(full.message(), "data disk full: cannot write frame_0009.png");
  EXPECT_TRUE(IsDiskFull(full));
  EXPECT_TRUE(IsDiskFull(full.WithContext("scan")));
  EXPECT_EQ(WriteFailure(EDQUOT, "x").code(), StatusCode::kResourceExhausted);
  Status other = WriteFailure(EACCES, "cannot write x");
  EXPECT_EQ(other.code(), StatusCode::kInternal);
  EXPECT_FALSE(IsDiskFull(other));
}

TEST(DataLifecycleTest, ReserveComparesWithTheRealFileSystem) {
  auto free_bytes = FreeDiskBytes("/");
  ASSERT_TRUE(free_bytes.ok());
  EXPECT_GT(*free_bytes, 0);
  EXPECT_TRUE(CheckFreeSpaceReserve("/", 0).ok());
  EXPECT_TRUE(CheckFreeSpaceReserve("/", 1).ok());
  Status st = CheckFreeSpaceReserve("/", *free_bytes + (int64_t(1) << 40));
  EXPECT_EQ(st.code(), StatusCode::kResourceExhausted);
  EXPECT_NE(st.message().find("--min-free-mb"), std::string::npos);
  EXPECT_EQ(FreeDiskBytes("/no/such/dir").status().code(), StatusCode::kInternal);
}

}  // namespace
}  // namespace inspection
