// The studies table (schema version 4) on both backends: SQLite in the data directory and a real
// private PostgreSQL server (tests/lib/postgres_server.h). A study is stored whole, replaced
// under its id, listed newest first per recipe, and survives a reopen.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <atomic>
#include <filesystem>
#include <string>

#include "server/storage/data_store.h"
#include "tests/lib/postgres_server.h"

namespace inspection {
namespace {

namespace fs = std::filesystem;

testing::PostgresServer& Postgres() {
  static testing::PostgresServer server;  // one per process (ctest runs each test in its own)
  return server;
}

class StudyStoreTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    static std::atomic<int> counter{0};
    dir_ = fs::temp_directory_path() / ("inspect-study-store-" + std::to_string(getpid()) + "-" +
                                        std::to_string(++counter));
    fs::remove_all(dir_);
    if (GetParam() == "postgresql") {
      ASSERT_TRUE(Postgres().started());
      const std::string db = "study_" + std::to_string(getpid()) + "_" + std::to_string(counter.load());
      options_.url = Postgres().CreateDatabase(db);
      options_.password_file = Postgres().PasswordFile();
    }
    Reopen();
  }
  void TearDown() override {
    store_.reset();
    fs::remove_all(dir_);
  }
  void Reopen() {
    store_.reset();
    auto s = DataStore::Open(dir_, options_);
    ASSERT_TRUE(s.ok()) << s.status().ToString();
    store_ = std::move(*s);
  }
  static v1::Study Study(const std::string& id, const std::string& recipe, int64_t finish_s, double cg) {
    v1::Study s;
    s.set_study_id(id);
    s.set_recipe_id(recipe);
    s.set_recipe_version(2);
    s.set_repeats(25);
    s.mutable_finish_time()->set_seconds(finish_s);
    v1::MeasurementCapability* c = s.add_measurements();
    c->set_name("step");
    c->set_cg(cg);
    for (int i = 0; i < 25; ++i) c->add_values(1.0 + 0.001 * i);
    return s;
  }

  fs::path dir_;
  DatabaseOptions options_;
  std::unique_ptr<DataStore> store_;
};

TEST_P(StudyStoreTest, StudiesRoundTripReplaceAndListNewestFirstPerRecipe) {
  ASSERT_TRUE(store_->PutStudy(Study("study-a", "r1", 100, 1.5)).ok());
  ASSERT_TRUE(store_->PutStudy(Study("study-b", "r2", 200, 0.9)).ok());
  ASSERT_TRUE(store_->PutStudy(Study("study-c", "r1", 300, 2.1)).ok());
  auto a = store_->GetStudy("study-a");
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->SerializeAsString(), Study("study-a", "r1", 100, 1.5).SerializeAsString());
  EXPECT_EQ(a->measurements(0).values(24), 1.024);
  auto missing = store_->GetStudy("study-z");
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("study-z"), std::string::npos);

  auto all = store_->ListStudies("", 50);
  ASSERT_TRUE(all.ok());
  ASSERT_EQ(all->size(), 3u);
  EXPECT_EQ((*all)[0].study_id(), "study-c");
  EXPECT_EQ((*all)[2].study_id(), "study-a");
  auto r1 = store_->ListStudies("r1", 50);
  ASSERT_EQ(r1->size(), 2u);
  EXPECT_EQ((*r1)[0].study_id(), "study-c");
  EXPECT_EQ(store_->ListStudies("r1", 1)->size(), 1u);
  EXPECT_TRUE(store_->ListStudies("r9", 50)->empty());

  // Stored again under its id: replaced, not duplicated.
  ASSERT_TRUE(store_->PutStudy(Study("study-a", "r1", 400, 1.7)).ok());
  r1 = store_->ListStudies("r1", 50);
  ASSERT_EQ(r1->size(), 2u);
  EXPECT_EQ((*r1)[0].study_id(), "study-a");
  EXPECT_DOUBLE_EQ((*r1)[0].measurements(0).cg(), 1.7);

  Reopen();
  EXPECT_EQ(store_->ListStudies("", 50)->size(), 3u);
  EXPECT_DOUBLE_EQ(store_->GetStudy("study-b")->measurements(0).cg(), 0.9);
}

INSTANTIATE_TEST_SUITE_P(Backends, StudyStoreTest, ::testing::Values("sqlite", "postgresql"),
                         [](const auto& info) { return info.param; });

v1::Study Study1() {
  v1::Study s;
  s.set_study_id("study-1");
  s.set_recipe_id("r");
  return s;
}

// A version-2 database (the layout before studies) migrates in place and keeps its rows.
TEST(StudyStoreMigrationTest, AVersionTwoSqliteDatabaseGainsTheStudiesTable) {
  const fs::path dir = fs::temp_directory_path() / ("inspect-study-migrate-" + std::to_string(getpid()));
  fs::remove_all(dir);
  {
    auto s = DataStore::Open(dir);
    ASSERT_TRUE(s.ok());
    v1::Job j;
    j.set_job_id("job-old");
    j.set_kind(v1::JOB_KIND_SCAN);
    ASSERT_TRUE((*s)->PutJob(j).ok());
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir / "inspection.db").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "DROP TABLE studies; DROP TABLE work_queue; DELETE FROM schema_version WHERE version > 2", nullptr, nullptr,
                         nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  auto s = DataStore::Open(dir);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_TRUE((*s)->GetJob("job-old").ok());
  ASSERT_TRUE((*s)->PutStudy(Study1()).ok());
  EXPECT_EQ((*s)->ListStudies("", 10)->size(), 1u);
  s->reset();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace inspection
