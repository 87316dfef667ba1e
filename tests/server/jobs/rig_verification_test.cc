// The rig's verification state (server/jobs/rig_verification.h) from stored records: a full
// verification is valid until its own next_full_due (inspectd verification_interval_days as it
// ran), a record without one (an older inspectd's) for kFullVerificationIntervalDays; a newer
// failed interim check decides until the next full verification.
#include "server/jobs/rig_verification.h"

#include <google/protobuf/util/time_util.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "server/storage/data_store.h"

namespace inspection {
namespace {

namespace fs = std::filesystem;
using google::protobuf::util::TimeUtil;

google::protobuf::Timestamp DaysFromNow(const google::protobuf::Timestamp& now, double days) {
  return TimeUtil::NanosecondsToTimestamp(TimeUtil::TimestampToNanoseconds(now) +
                                          static_cast<int64_t>(days * 86400.0) * 1000000000LL);
}

class RigVerificationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("rig-verification-test-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    auto store = DataStore::Open(dir_);
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    store_ = std::move(*store);
    now_ = CurrentTimestamp();
  }
  void TearDown() override {
    store_.reset();
    fs::remove_all(dir_);
  }
  v1::VerificationRecord Record(const std::string& id, v1::VerificationMode mode, double finished_days_ago) {
    v1::VerificationRecord r;
    r.set_verification_id(id);
    r.set_mode(mode);
    r.set_calibration_id("cal-1");
    r.set_state(v1::VERIFICATION_STATE_VERIFIED);
    *r.mutable_finish_time() = DaysFromNow(now_, -finished_days_ago);
    return r;
  }
  RigVerification Read() {
    auto v = ReadRigVerification(*store_, "cal-1", now_);
    EXPECT_TRUE(v.ok()) << v.status().ToString();
    return v.ok() ? *v : RigVerification{};
  }

  fs::path dir_;
  std::unique_ptr<DataStore> store_;
  google::protobuf::Timestamp now_;
};

TEST_F(RigVerificationTest, AFullRecordIsValidUntilItsOwnDueDate) {
  // Made 10 days ago under a 7-day interval: due since 3 days.
  v1::VerificationRecord full = Record("ver-a", v1::VERIFICATION_MODE_FULL, 10);
  *full.mutable_next_full_due() = DaysFromNow(full.finish_time(), 7);
  ASSERT_TRUE(store_->PutVerification(full).ok());
  EXPECT_DOUBLE_EQ(FullIntervalDays(full), 7.0);
  RigVerification v = Read();
  EXPECT_EQ(v.state, v1::VERIFICATION_STATE_DUE);
  EXPECT_EQ(v.detail, "full verification ver-a is 10.0 days old (interval 7.0 days)");

  // The same age under a 90-day interval: verified, no warning.
  *full.mutable_next_full_due() = DaysFromNow(full.finish_time(), 90);
  ASSERT_TRUE(store_->PutVerification(full).ok());
  v = Read();
  EXPECT_EQ(v.state, v1::VERIFICATION_STATE_VERIFIED);
  EXPECT_EQ(VerificationWarning(v), "");
}

TEST_F(RigVerificationTest, ARecordWithoutADueDateIsValidForThirtyDays) {
  v1::VerificationRecord full = Record("ver-old", v1::VERIFICATION_MODE_FULL, 29.5);
  ASSERT_TRUE(store_->PutVerification(full).ok());
  EXPECT_DOUBLE_EQ(FullIntervalDays(full), kFullVerificationIntervalDays);
  EXPECT_EQ(Read().state, v1::VERIFICATION_STATE_VERIFIED);
  *full.mutable_finish_time() = DaysFromNow(now_, -30.5);
  ASSERT_TRUE(store_->PutVerification(full).ok());
  RigVerification v = Read();
  EXPECT_EQ(v.state, v1::VERIFICATION_STATE_DUE);
  EXPECT_EQ(v.detail, "full verification ver-old is 30.5 days old (interval 30 days)");
}

TEST_F(RigVerificationTest, ANewerFailedInterimCheckDecidesUntilTheNextFullVerification) {
  v1::VerificationRecord full = Record("ver-full", v1::VERIFICATION_MODE_FULL, 5);
  *full.mutable_next_full_due() = DaysFromNow(full.finish_time(), 30);
  ASSERT_TRUE(store_->PutVerification(full).ok());
  v1::VerificationRecord interim = Record("ver-int", v1::VERIFICATION_MODE_INTERIM, 1);
  interim.set_state(v1::VERIFICATION_STATE_FAILED);
  interim.add_findings("alpha_z: step 10.359 um against 10.123 um, beyond U 0.165 um");
  ASSERT_TRUE(store_->PutVerification(interim).ok());
  RigVerification v = Read();
  EXPECT_EQ(v.state, v1::VERIFICATION_STATE_FAILED);
  EXPECT_EQ(v.detail, "interim check ver-int: alpha_z: step 10.359 um against 10.123 um, beyond U 0.165 um");

  // A full verification after it restores the state.
  v1::VerificationRecord again = Record("ver-full2", v1::VERIFICATION_MODE_FULL, 0.5);
  *again.mutable_next_full_due() = DaysFromNow(again.finish_time(), 30);
  ASSERT_TRUE(store_->PutVerification(again).ok());
  v = Read();
  EXPECT_EQ(v.state, v1::VERIFICATION_STATE_VERIFIED);
  ASSERT_TRUE(v.full.has_value());
  EXPECT_EQ(v.full->verification_id(), "ver-full2");
}

}  // namespace
}  // namespace inspection
