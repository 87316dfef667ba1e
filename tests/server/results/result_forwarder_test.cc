// Store-and-forward of a rig's results to its site's store (server/results/result_forwarder.h)
// against a real private PostgreSQL (tests/lib/postgres_server.h): in order and once, across a
// site outage while the rig keeps storing results, across a forwarder restart (the persisted
// mark), and with two rigs on one site feed. The retried forward after a lost answer is a no-op.
#include "server/results/result_forwarder.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include "server/results/result_feed.h"
#include "tests/lib/postgres_server.h"

namespace inspection {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;

testing::PostgresServer& Postgres() {
  static testing::PostgresServer server;  // one per process; ctest runs each test in its own
  return server;
}

v1::InspectionResult Result(const std::string& job, const std::string& part) {
  v1::InspectionResult r;
  r.set_job_id(job);
  r.set_part_id(part);
  r.set_recipe_id("bore");
  r.set_verdict(v1::VERDICT_OK);
  r.mutable_finish_time()->set_seconds(1000);
  return r;
}

class ResultForwarderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(Postgres().started());
    static std::atomic<int> n{0};
    const std::string tag = std::to_string(getpid()) + "_" + std::to_string(++n);
    site_url_ = Postgres().CreateDatabase("site_" + tag);
    base_ = fs::temp_directory_path() / ("inspect-forward-" + tag);
    fs::remove_all(base_);
  }
  void TearDown() override { fs::remove_all(base_); }
  std::unique_ptr<DataStore> OpenLocal(const std::string& rig) {
    auto s = DataStore::Open(base_ / rig);
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    return s.ok() ? std::move(*s) : nullptr;
  }
  std::unique_ptr<DataStore> OpenSite() {
    auto s = DataStore::Open(base_ / "site-reader", {site_url_, Postgres().PasswordFile()});
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    return s.ok() ? std::move(*s) : nullptr;
  }
  ResultForwardingOptions Options(const std::string& rig) const {
    ResultForwardingOptions o;
    o.rig_id = rig;
    o.site = {site_url_, Postgres().PasswordFile()};
    o.retry_min = milliseconds(50);
    o.retry_max = milliseconds(200);
    o.idle_poll = milliseconds(100);
    return o;
  }

  std::string site_url_;
  fs::path base_;
};

TEST_F(ResultForwarderTest, EveryResultArrivesOnceInOrderAcrossASiteOutageAndARestart) {
  auto local = OpenLocal("rig-a");
  ResultFeed feed(local.get());
  auto forwarder = std::make_unique<ResultForwarder>(local.get(), Options("rig-a"));
  feed.SetAppendListener([f = forwarder.get()] { f->Notify(); });
  for (int i = 1; i <= 5; ++i) ASSERT_TRUE(feed.Append(Result("job-" + std::to_string(i), "P")).ok());
  ASSERT_TRUE(forwarder->WaitForwarded(5, milliseconds(20000))) << forwarder->progress().last_error;

  // The site goes down; the rig keeps storing results.
  ASSERT_TRUE(Postgres().Stop());
  for (int i = 6; i <= 12; ++i) ASSERT_TRUE(feed.Append(Result("job-" + std::to_string(i), "P")).ok());
  EXPECT_FALSE(forwarder->WaitForwarded(12, milliseconds(500)));
  EXPECT_FALSE(forwarder->progress().site_reachable);
  EXPECT_FALSE(forwarder->progress().last_error.empty());
  EXPECT_EQ(*local->LastResultSequence(), 12);  // nothing lost locally
  ASSERT_TRUE(Postgres().Start());
  ASSERT_TRUE(forwarder->WaitForwarded(12, milliseconds(20000))) << forwarder->progress().last_error;

  // A restart of the rig's inspectd: the persisted mark, no second copy.
  forwarder.reset();
  for (int i = 13; i <= 15; ++i) ASSERT_TRUE(local->AppendResult(Result("job-" + std::to_string(i), "P")).ok());
  EXPECT_EQ(local->GetSetting(ResultForwarder::kMarkSetting), "12");
  ResultForwarder again(local.get(), Options("rig-a"));
  ASSERT_TRUE(again.WaitForwarded(15, milliseconds(20000))) << again.progress().last_error;

  auto site = OpenSite();
  auto all = site->ResultsAfter(0, 100);
  ASSERT_TRUE(all.ok()) << all.status().ToString();
  ASSERT_EQ(all->size(), 15u);
  for (size_t i = 0; i < all->size(); ++i) {
    const v1::InspectionResult& r = (*all)[i];
    EXPECT_EQ(r.rig_id(), "rig-a");
    EXPECT_EQ(r.rig_sequence(), int64_t(i + 1)) << "out of order at " << i;
    EXPECT_EQ(r.job_id(), "job-" + std::to_string(i + 1));
    if (i > 0) EXPECT_GT(r.sequence(), (*all)[i - 1].sequence());
  }
}

TEST_F(ResultForwarderTest, ARetriedForwardIsNotStoredTwice) {
  auto site = OpenSite();
  v1::InspectionResult r = Result("job-1", "P");
  r.set_rig_id("rig-a");
  r.set_rig_sequence(1);
  auto first = site->ImportResult(r);
  auto second = site->ImportResult(r);  // the answer to the first was lost
  ASSERT_TRUE(first.ok() && second.ok()) << first.status().ToString() << " " << second.status().ToString();
  EXPECT_EQ(first->sequence(), second->sequence());
  EXPECT_EQ(site->ResultsAfter(0, 10)->size(), 1u);
  v1::InspectionResult anonymous = Result("job-2", "P");
  EXPECT_EQ(site->ImportResult(anonymous).status().code(), StatusCode::kInvalidArgument);
}

TEST_F(ResultForwarderTest, TwoRigsShareOneSiteFeedWithTheirIds) {
  auto a = OpenLocal("rig-a");
  auto b = OpenLocal("rig-b");
  for (int i = 1; i <= 3; ++i) {
    ASSERT_TRUE(a->AppendResult(Result("a-" + std::to_string(i), "PA")).ok());
    ASSERT_TRUE(b->AppendResult(Result("b-" + std::to_string(i), "PB")).ok());
  }
  ResultForwarder fa(a.get(), Options("rig-a"));
  ResultForwarder fb(b.get(), Options("rig-b"));
  ASSERT_TRUE(fa.WaitForwarded(3, milliseconds(20000))) << fa.progress().last_error;
  ASSERT_TRUE(fb.WaitForwarded(3, milliseconds(20000))) << fb.progress().last_error;
  auto site = OpenSite();
  ResultFeed site_feed(site.get());
  auto all = site_feed.Next(0, 100, milliseconds(0));
  ASSERT_TRUE(all.ok());
  ASSERT_EQ(all->size(), 6u);
  std::map<std::string, int64_t> last_per_rig;
  for (const auto& r : *all) {
    EXPECT_EQ(r.part_id(), r.rig_id() == "rig-a" ? "PA" : "PB");
    EXPECT_GT(r.rig_sequence(), last_per_rig[r.rig_id()]);  // each rig in its own order
    last_per_rig[r.rig_id()] = r.rig_sequence();
  }
  EXPECT_EQ(last_per_rig.size(), 2u);
  // A site watcher waiting at the end sees a result another process forwards (no local Append).
  const int64_t end = all->back().sequence();
  ASSERT_TRUE(a->AppendResult(Result("a-4", "PA")).ok());
  fa.Notify();
  auto next = site_feed.Next(end, 10, milliseconds(20000));
  ASSERT_TRUE(next.ok());
  ASSERT_EQ(next->size(), 1u);
  EXPECT_EQ((*next)[0].job_id(), "a-4");
}

TEST(ResultForwardingOptionsTest, NamesTheSettingThatIsWrong) {
  ResultForwardingOptions o;
  o.site.url = "postgresql://u@h/site";
  EXPECT_EQ(ValidateResultForwardingOptions(o).message().rfind("rig_id", 0), 0u);
  o.rig_id = "rig-a";
  EXPECT_TRUE(ValidateResultForwardingOptions(o).ok());
  o.site.url = "sqlite";
  EXPECT_EQ(ValidateResultForwardingOptions(o).message().rfind("site_database", 0), 0u);
}

}  // namespace
}  // namespace inspection
