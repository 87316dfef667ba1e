// The sweep of a shared uploads/ (server/storage/work_folders.h) as a specification, with two
// stores (two replicas) on one real private PostgreSQL and one data folder, and the sweeper's
// clock given by the test: a folder nobody holds and no job refers to goes once it has been seen
// unchanged for the bound; a folder another replica holds (and touches), a job's stored input
// and the sweeper's own held folders stay.
#include "server/storage/work_folders.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "server/storage/data_store.h"
#include "tests/lib/postgres_server.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;
using std::chrono::milliseconds;

testing::PostgresServer& Postgres() {
  static testing::PostgresServer server;  // one per test process
  return server;
}

class WorkFoldersTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string tag = std::to_string(::getpid());
    dir_ = fs::temp_directory_path() / ("inspect_work_folders_" + tag);
    fs::remove_all(dir_);
    ASSERT_TRUE(Postgres().started());
    DatabaseOptions database;
    database.url = Postgres().CreateDatabase("work_folders_" + tag);
    database.password_file = Postgres().PasswordFile();
    for (auto* store : {&sweeping_, &other_}) {
      auto s = DataStore::Open(dir_, database);
      ASSERT_TRUE(s.ok()) << s.status().ToString();
      *store = std::move(*s);
    }
  }
  void TearDown() override {
    sweeping_.reset();
    other_.reset();
    fs::remove_all(dir_);
  }
  static void MakeFolder(const fs::path& p) {
    fs::create_directories(p);
    std::ofstream(p / "frame_0000.png") << "partial";
  }

  fs::path dir_;
  std::unique_ptr<DataStore> sweeping_, other_;
};

TEST_F(WorkFoldersTest, OnlyAFolderNobodyHoldsOrNeedsGoesAndOnlyAfterTheBound) {
  // A dead writer's partial upload; another replica's live upload; a queued job's stored input;
  // the sweeping replica's own extraction folder.
  const fs::path dead = dir_ / "uploads" / "upload-dead";
  MakeFolder(dead);
  std::shared_ptr<OwnedFolder> live = other_->NewUploadFolder("upload");
  MakeFolder(live->path());
  const fs::path input = dir_ / "uploads" / "upload-queued";
  MakeFolder(input);
  v1::Job job;
  job.set_job_id("rec-queued");
  job.set_kind(v1::JOB_KIND_RECONSTRUCT);
  job.set_state(v1::JOB_STATE_QUEUED);
  v1::JobEvent queued;
  queued.set_job_id(job.job_id());
  queued.set_sequence(1);
  QueuedWork work;
  work.job_id = job.job_id();
  work.input = "start";
  work.stack_dir = "uploads/upload-queued";
  ASSERT_TRUE(sweeping_->EnqueueWork(job, queued, work).ok());
  std::shared_ptr<OwnedFolder> own = sweeping_->NewUploadFolder("stack");
  MakeFolder(own->path());

  OrphanUploadSweeper sweeper(sweeping_.get(), milliseconds(6000));
  const auto t0 = std::chrono::steady_clock::now();
  // First sight: nothing is judged yet.
  EXPECT_EQ(*sweeper.Sweep(t0), 0);
  other_->live_work_folders().TouchAll();  // replica 2's keeper, a third of the bound later
  EXPECT_EQ(*sweeper.Sweep(t0 + milliseconds(2000)), 0);
  other_->live_work_folders().TouchAll();
  EXPECT_EQ(*sweeper.Sweep(t0 + milliseconds(5999)), 0);  // just under the bound: kept
  EXPECT_TRUE(fs::exists(dead));
  other_->live_work_folders().TouchAll();
  EXPECT_EQ(*sweeper.Sweep(t0 + milliseconds(6000)), 1);
  EXPECT_FALSE(fs::exists(dead));
  EXPECT_TRUE(fs::exists(live->path() / "frame_0000.png"));
  EXPECT_TRUE(fs::exists(input / "frame_0000.png"));
  EXPECT_TRUE(fs::exists(own->path() / "frame_0000.png"));

  // Replica 2 dies: its folder stays on the disk, nobody touches it any more.
  const fs::path left = live->path();
  live->Release();
  // Its last touch was noticed by the sweep at 6000: the bound runs from there.
  EXPECT_EQ(*sweeper.Sweep(t0 + milliseconds(8000)), 0);
  EXPECT_EQ(*sweeper.Sweep(t0 + milliseconds(11999)), 0);
  EXPECT_TRUE(fs::exists(left));
  EXPECT_EQ(*sweeper.Sweep(t0 + milliseconds(12000)), 1);
  EXPECT_FALSE(fs::exists(left));
  // A job's stored input is never an orphan, however long it waits; the sweeper's own either.
  EXPECT_EQ(*sweeper.Sweep(t0 + milliseconds(100000)), 0);
  EXPECT_TRUE(fs::exists(input / "frame_0000.png"));
  EXPECT_TRUE(fs::exists(own->path() / "frame_0000.png"));
  // Its own folder goes with its holder, as before.
  const fs::path own_path = own->path();
  own.reset();
  EXPECT_FALSE(fs::exists(own_path));
}

TEST_F(WorkFoldersTest, NothingIsRemovedWhenTheQueueCannotBeRead) {
  const fs::path dead = dir_ / "uploads" / "upload-dead";
  MakeFolder(dead);
  OrphanUploadSweeper sweeper(sweeping_.get(), milliseconds(1000));
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(*sweeper.Sweep(t0), 0);
  ASSERT_TRUE(Postgres().Stop());
  auto swept = sweeper.Sweep(t0 + milliseconds(5000));
  EXPECT_EQ(swept.status().code(), StatusCode::kUnavailable) << swept.status().ToString();
  EXPECT_TRUE(fs::exists(dead));  // without the queue, no folder can be told from a job's input
  ASSERT_TRUE(Postgres().Start());
  EXPECT_EQ(*sweeper.Sweep(t0 + milliseconds(6000)), 1);
}

}  // namespace
}  // namespace inspection
