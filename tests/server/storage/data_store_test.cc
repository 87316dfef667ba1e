// DataStore as a specification, run against both backends: SQLite in the data directory and a
// real private PostgreSQL server (tests/lib/postgres_server.h). Every behaviour callers rely on
// (ordering, paging, versioned recipes, the result sequence, transactions, schema versions) is
// asserted on each.
#include "server/storage/data_store.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <optional>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "tests/lib/postgres_server.h"

namespace inspection {
namespace {

namespace fs = std::filesystem;

testing::PostgresServer& Postgres() {
  // One server per process (ctest runs each test in its own), stopped and removed at exit.
  static testing::PostgresServer server;
  return server;
}

class DataStoreTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    static std::atomic<int> counter{0};
    dir_ = fs::temp_directory_path() / ("inspect-store-" + std::to_string(getpid()) + "-" + std::to_string(++counter));
    fs::remove_all(dir_);
    if (GetParam() == "postgresql") {
      ASSERT_TRUE(Postgres().started());
      db_name_ = "store_" + std::to_string(getpid()) + "_" + std::to_string(counter.load());
      options_.url = Postgres().CreateDatabase(db_name_);
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
  static v1::Job Job(const std::string& id, v1::JobKind kind, v1::JobState state, int64_t create_s,
                     const std::string& request_id = "") {
    v1::Job j;
    j.set_job_id(id);
    j.set_kind(kind);
    j.set_state(state);
    j.set_request_id(request_id);
    j.mutable_create_time()->set_seconds(create_s);
    return j;
  }
  static v1::InspectionResult Result(const std::string& job, const std::string& part, v1::Verdict verdict,
                                     int64_t finish_s) {
    v1::InspectionResult r;
    r.set_job_id(job);
    r.set_part_id(part);
    r.set_recipe_id("bore");
    r.set_verdict(verdict);
    r.mutable_finish_time()->set_seconds(finish_s);
    return r;
  }

  fs::path dir_;
  std::string db_name_;
  DatabaseOptions options_;
  std::unique_ptr<DataStore> store_;
};

TEST_P(DataStoreTest, BackendIsTheOneAskedFor) { EXPECT_EQ(store_->backend(), GetParam()); }

TEST_P(DataStoreTest, JobsRoundTripListAndPage) {
  ASSERT_TRUE(store_->PutJob(Job("job-a", v1::JOB_KIND_SCAN, v1::JOB_STATE_SUCCEEDED, 100, "req-1")).ok());
  ASSERT_TRUE(store_->PutJob(Job("job-b", v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_QUEUED, 200)).ok());
  ASSERT_TRUE(store_->PutJob(Job("job-c", v1::JOB_KIND_SCAN, v1::JOB_STATE_RUNNING, 300)).ok());
  // Replace: the row follows the message.
  ASSERT_TRUE(store_->PutJob(Job("job-c", v1::JOB_KIND_SCAN, v1::JOB_STATE_FAILED, 300)).ok());

  auto a = store_->GetJob("job-a");
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->request_id(), "req-1");
  auto missing = store_->GetJob("job-x");
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("job-x"), std::string::npos);

  auto all = store_->ListJobs(v1::JOB_KIND_UNSPECIFIED, v1::JOB_STATE_UNSPECIFIED, 10, 0);
  ASSERT_TRUE(all.ok());
  ASSERT_EQ(all->size(), 3u);
  EXPECT_EQ((*all)[0].job_id(), "job-c");  // newest first
  EXPECT_EQ((*all)[2].job_id(), "job-a");
  auto scans = store_->ListJobs(v1::JOB_KIND_SCAN, v1::JOB_STATE_UNSPECIFIED, 10, 0);
  ASSERT_EQ(scans->size(), 2u);
  auto page = store_->ListJobs(v1::JOB_KIND_UNSPECIFIED, v1::JOB_STATE_UNSPECIFIED, 1, 300LL * 1000000000LL);
  ASSERT_TRUE(page.ok()) << page.status().ToString();
  ASSERT_EQ(page->size(), 1u);
  EXPECT_EQ((*page)[0].job_id(), "job-b");
  auto failed = store_->ListJobs(v1::JOB_KIND_UNSPECIFIED, v1::JOB_STATE_FAILED, 10, 0);
  ASSERT_EQ(failed->size(), 1u);
  EXPECT_EQ((*failed)[0].job_id(), "job-c");

  EXPECT_EQ(store_->FindJobByRequestId(v1::JOB_KIND_SCAN, "req-1").value_or(""), "job-a");
  EXPECT_FALSE(store_->FindJobByRequestId(v1::JOB_KIND_RECONSTRUCT, "req-1").has_value());
  EXPECT_EQ(store_->UnfinishedJobs()->size(), 1u);
  EXPECT_EQ(store_->FinishedJobs()->size(), 2u);
}

TEST_P(DataStoreTest, EventsComeBackInSequenceOrder) {
  for (int seq : {2, 0, 1}) {
    v1::JobEvent e;
    e.set_job_id("job-a");
    e.set_sequence(seq);
    e.set_message("event " + std::to_string(seq));
    ASSERT_TRUE(store_->AppendEvent(e).ok());
  }
  auto events = store_->Events("job-a");
  ASSERT_TRUE(events.ok());
  ASSERT_EQ(events->size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ((*events)[size_t(i)].sequence(), uint64_t(i));
  EXPECT_TRUE(store_->Events("job-none")->empty());
}

TEST_P(DataStoreTest, ABatchOfEventsIsStoredWholeAndReplacesBySequence) {
  std::vector<v1::JobEvent> batch;
  for (int seq = 1; seq <= 250; ++seq) {  // more than one statement's rows (200) on PostgreSQL
    v1::JobEvent e;
    e.set_job_id(seq % 2 ? "job-a" : "job-b");
    e.set_sequence(uint64_t((seq + 1) / 2));
    e.set_message("event " + std::to_string(seq));
    batch.push_back(e);
  }
  ASSERT_TRUE(store_->AppendEvents(batch).ok());
  auto a = store_->Events("job-a");
  ASSERT_TRUE(a.ok());
  ASSERT_EQ(a->size(), 125u);
  EXPECT_EQ((*a)[0].message(), "event 1");
  EXPECT_EQ((*a)[124].message(), "event 249");
  EXPECT_EQ(store_->Events("job-b")->size(), 125u);
  // The same sequence again replaces (a retried batch changes nothing).
  batch.resize(1);
  batch[0].set_message("again");
  ASSERT_TRUE(store_->AppendEvents(batch).ok());
  EXPECT_EQ(store_->Events("job-a")->front().message(), "again");
  EXPECT_EQ(store_->Events("job-a")->size(), 125u);
  EXPECT_TRUE(store_->AppendEvents({}).ok());
}

TEST_P(DataStoreTest, ArtifactsOfAKindLeaveRowsAndTheJobsResultTogether) {
  v1::Job job = Job("job-a", v1::JOB_KIND_SCAN, v1::JOB_STATE_SUCCEEDED, 100);
  for (auto [id, kind] : {std::pair{"art-1", v1::ARTIFACT_KIND_DEPTH_TIFF}, std::pair{"art-2", v1::ARTIFACT_KIND_STACK_ZIP}}) {
    v1::Artifact* a = job.mutable_result()->add_artifacts();
    a->set_artifact_id(id);
    a->set_kind(kind);
    StoredArtifact stored{*a, "job-a", dir_ / "artifacts" / "job-a" / id};
    ASSERT_TRUE(store_->PutArtifact(stored).ok());
  }
  ASSERT_TRUE(store_->PutJob(job).ok());
  auto got = store_->GetArtifact("art-2");
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->job_id, "job-a");
  EXPECT_EQ(got->path, dir_ / "artifacts" / "job-a" / "art-2");

  auto removed = store_->DeleteArtifactsOfKind("job-a", v1::ARTIFACT_KIND_STACK_ZIP);
  ASSERT_TRUE(removed.ok()) << removed.status().ToString();
  ASSERT_EQ(removed->size(), 1u);
  EXPECT_EQ((*removed)[0].artifact.artifact_id(), "art-2");
  EXPECT_EQ(store_->GetArtifact("art-2").status().code(), StatusCode::kNotFound);
  auto after = store_->GetJob("job-a");
  ASSERT_EQ(after->result().artifacts_size(), 1);
  EXPECT_EQ(after->result().artifacts(0).artifact_id(), "art-1");
  EXPECT_EQ(store_->DeleteArtifactsOfKind("job-x", v1::ARTIFACT_KIND_STACK_ZIP).status().code(),
            StatusCode::kNotFound);

  ASSERT_TRUE(store_->SetPinned("job-a", true).ok());
  ASSERT_TRUE(store_->SetPinned("job-a", true).ok());  // idempotent
  EXPECT_EQ(store_->PinnedJobs()->size(), 1u);
  ASSERT_TRUE(store_->DeleteJobRecords("job-a").ok());
  EXPECT_EQ(store_->GetJob("job-a").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->GetArtifact("art-1").status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(store_->PinnedJobs()->empty());
}

TEST_P(DataStoreTest, RecipesAreVersionedAndDeletingHidesEveryVersion) {
  v1::Recipe r;
  r.set_recipe_id("bore");
  r.set_description("first");
  auto v1r = store_->StoreRecipe(r, /*create=*/true, 0);
  ASSERT_TRUE(v1r.ok()) << v1r.status().ToString();
  EXPECT_EQ(v1r->version(), 1);
  EXPECT_EQ(store_->StoreRecipe(r, true, 0).status().code(), StatusCode::kAlreadyExists);
  r.set_description("second");
  EXPECT_EQ(store_->StoreRecipe(r, false, 1)->version(), 2);
  EXPECT_EQ(store_->StoreRecipe(r, false, 1).status().code(), StatusCode::kAborted);  // someone updated it
  EXPECT_EQ(store_->GetRecipe("bore", 0)->description(), "second");
  EXPECT_EQ(store_->GetRecipe("bore", 1)->description(), "first");
  EXPECT_EQ(store_->ListRecipes()->size(), 1u);
  EXPECT_EQ(*store_->DeleteRecipe("bore"), 2);
  EXPECT_EQ(store_->GetRecipe("bore", 0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->GetRecipe("bore", 2)->description(), "second");  // results still name it
  EXPECT_TRUE(store_->ListRecipes()->empty());
  EXPECT_EQ(store_->DeleteRecipe("bore").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->StoreRecipe(r, false, 0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->StoreRecipe(r, true, 0)->version(), 3);  // numbering continues
}

TEST_P(DataStoreTest, ResultsGetIncreasingSequenceNumbersOncePerJob) {
  auto r1 = store_->AppendResult(Result("job-1", "P-1", v1::VERDICT_OK, 10));
  auto r2 = store_->AppendResult(Result("job-2", "P-2", v1::VERDICT_NOT_OK, 20));
  auto r3 = store_->AppendResult(Result("job-3", "P-1", v1::VERDICT_OK, 30));
  ASSERT_TRUE(r1.ok() && r2.ok() && r3.ok()) << r1.status().ToString();
  EXPECT_LT(r1->sequence(), r2->sequence());
  EXPECT_LT(r2->sequence(), r3->sequence());
  EXPECT_EQ(store_->AppendResult(Result("job-2", "P-2", v1::VERDICT_OK, 40)).status().code(),
            StatusCode::kAlreadyExists);
  EXPECT_EQ(*store_->LastResultSequence(), r3->sequence());

  auto after = store_->ResultsAfter(r1->sequence(), 10);
  ASSERT_EQ(after->size(), 2u);
  EXPECT_EQ((*after)[0].job_id(), "job-2");
  EXPECT_EQ((*after)[0].sequence(), r2->sequence());  // the stored record carries its number
  ResultQuery q;
  q.part_id = "P-1";
  auto p1 = store_->ListResults(q);
  ASSERT_EQ(p1->size(), 2u);
  EXPECT_EQ((*p1)[0].job_id(), "job-3");  // newest first
  q = {};
  q.verdict = v1::VERDICT_NOT_OK;
  EXPECT_EQ(store_->ListResults(q)->size(), 1u);
  q = {};
  q.finished_from_ns = 20LL * 1000000000LL;
  q.finished_before_ns = 30LL * 1000000000LL;
  ASSERT_TRUE(store_->ListResults(q).ok()) << store_->ListResults(q).status().ToString();
  ASSERT_EQ(store_->ListResults(q)->size(), 1u);
  q = {};
  q.before_sequence = r3->sequence();
  q.limit = 1;
  ASSERT_EQ(store_->ListResults(q)->size(), 1u);
  EXPECT_EQ((*store_->ListResults(q))[0].job_id(), "job-2");
}

TEST_P(DataStoreTest, EverythingSurvivesAReopen) {
  ASSERT_TRUE(store_->PutJob(Job("job-a", v1::JOB_KIND_SCAN, v1::JOB_STATE_SUCCEEDED, 100)).ok());
  ASSERT_TRUE(store_->SetSetting("active_calibration", "cal-1").ok());
  v1::Calibration c;
  c.set_calibration_id("cal-1");
  c.mutable_create_time()->set_seconds(5);
  ASSERT_TRUE(store_->PutCalibration(c).ok());
  ASSERT_TRUE(store_->AppendResult(Result("job-a", "P", v1::VERDICT_OK, 1)).ok());
  Reopen();
  EXPECT_TRUE(store_->GetJob("job-a").ok());
  EXPECT_EQ(store_->GetSetting("active_calibration"), "cal-1");
  EXPECT_EQ(store_->GetSetting("unset"), "");
  EXPECT_EQ(store_->ListCalibrations()->size(), 1u);
  EXPECT_EQ(store_->GetCalibration("cal-9").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(*store_->LastResultSequence(), 1);
}

TEST_P(DataStoreTest, ASchemaNewerThanThisBinaryIsRefusedNamingBothVersions) {
  store_.reset();
  if (GetParam() == "postgresql") {
    Postgres().Execute(db_name_, "INSERT INTO schema_version(version) VALUES(7)");
  } else {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((dir_ / "inspection.db").c_str(), &db), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(db, "INSERT INTO schema_version(version) VALUES(7)", nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(db);
  }
  auto s = DataStore::Open(dir_, options_);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(s.status().message().find("schema version 7"), std::string::npos) << s.status().message();
  EXPECT_NE(s.status().message().find("newer than this inspectd knows (5)"), std::string::npos) << s.status().message();
}

// The pool's work queue (schema version 3): leases, takeover after expiry, completion only by
// the holder, hand-back, cancel of a queued and of a held job.
v1::JobEvent QueueEvent(const std::string& job_id, uint64_t sequence, v1::JobState state) {
  v1::JobEvent e;
  e.set_job_id(job_id);
  e.set_sequence(sequence);
  e.set_state(state);
  return e;
}

QueuedWork Work(const std::string& job_id) {
  QueuedWork w;
  w.job_id = job_id;
  w.input = std::string("start\0bytes", 11);
  w.stack_dir = "uploads/" + job_id;
  return w;
}

TEST_P(DataStoreTest, TheWorkQueueLeasesEachJobToOneWorkerAndOnlyTheHolderEndsIt) {
  for (int i = 1; i <= 3; ++i) {
    const std::string id = "rec-" + std::to_string(i);
    ASSERT_TRUE(store_->EnqueueWork(Job(id, v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_QUEUED, i),
                                    QueueEvent(id, 1, v1::JOB_STATE_QUEUED), Work(id))
                    .ok());
  }
  EXPECT_EQ(*store_->QueueDepth(), 3);
  EXPECT_EQ(store_->GetJob("rec-2")->state(), v1::JOB_STATE_QUEUED);  // job row and queue row together
  ASSERT_EQ(store_->Events("rec-2")->size(), 1u);

  // Oldest first, but a preferred job (decoded here already) before it.
  auto a = store_->ClaimWork("worker-a", 60000, {"rec-3"});
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(a->has_value());
  EXPECT_EQ((*a)->job_id, "rec-3");
  EXPECT_EQ((*a)->input, std::string("start\0bytes", 11));
  EXPECT_EQ((*a)->stack_dir, "uploads/rec-3");
  EXPECT_EQ((*a)->attempts, 1);
  auto b = store_->ClaimWork("worker-b", 60000, {});
  ASSERT_TRUE(b.ok() && b->has_value());
  EXPECT_EQ((*b)->job_id, "rec-1");
  EXPECT_EQ(*store_->QueueDepth(), 1);

  // The holder renews; another worker cannot end a job it does not hold.
  auto renewal = store_->RenewLeases("worker-a", 60000, {"rec-3"});
  ASSERT_TRUE(renewal.ok());
  EXPECT_EQ(renewal->held, std::vector<std::string>{"rec-3"});
  // A job the worker does not hold is not reported as held (nor its lease touched).
  renewal = store_->RenewLeases("worker-a", 60000, {"rec-3", "rec-1"});
  ASSERT_TRUE(renewal.ok());
  EXPECT_EQ(renewal->held, std::vector<std::string>{"rec-3"});
  v1::Job ended = Job("rec-3", v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_SUCCEEDED, 3);
  EXPECT_FALSE(*store_->CompleteWork("worker-b", ended, QueueEvent("rec-3", 2, v1::JOB_STATE_SUCCEEDED)));
  EXPECT_EQ(store_->GetJob("rec-3")->state(), v1::JOB_STATE_QUEUED);
  EXPECT_TRUE(*store_->CompleteWork("worker-a", ended, QueueEvent("rec-3", 2, v1::JOB_STATE_SUCCEEDED)));
  EXPECT_EQ(store_->GetJob("rec-3")->state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(store_->Events("rec-3")->size(), 2u);
  EXPECT_FALSE(*store_->CompleteWork("worker-a", ended, QueueEvent("rec-3", 2, v1::JOB_STATE_SUCCEEDED)))
      << "a job ends once";

  // Hand-back: queued again, taken by the next worker as a second attempt.
  v1::Job requeued = Job("rec-1", v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_QUEUED, 1);
  EXPECT_TRUE(*store_->ReleaseWork("worker-b", requeued, QueueEvent("rec-1", 2, v1::JOB_STATE_QUEUED)));
  EXPECT_EQ(*store_->QueueDepth(), 2);
  auto c = store_->ClaimWork("worker-c", 60000, {});
  ASSERT_TRUE(c.ok() && c->has_value());
  EXPECT_EQ((*c)->job_id, "rec-1");
  EXPECT_EQ((*c)->attempts, 2);

  // Cancel: a queued job ends at once; a held one is flagged for its holder.
  v1::Job cancelled = Job("rec-2", v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_CANCELLED, 2);
  EXPECT_TRUE(*store_->CancelQueuedWork(cancelled, QueueEvent("rec-2", 2, v1::JOB_STATE_CANCELLED)));
  EXPECT_EQ(store_->GetJob("rec-2")->state(), v1::JOB_STATE_CANCELLED);
  v1::Job cancel_held = Job("rec-1", v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_CANCELLED, 1);
  EXPECT_FALSE(*store_->CancelQueuedWork(cancel_held, QueueEvent("rec-1", 3, v1::JOB_STATE_CANCELLED)));
  EXPECT_EQ(store_->GetJob("rec-1")->state(), v1::JOB_STATE_QUEUED);
  renewal = store_->RenewLeases("worker-c", 60000, {"rec-1"});
  ASSERT_TRUE(renewal.ok());
  EXPECT_EQ(renewal->cancel_requested, std::vector<std::string>{"rec-1"});
  EXPECT_EQ(*store_->QueuedWorkIds(), std::vector<std::string>{"rec-1"});
  EXPECT_EQ(*store_->QueueDepth(), 0);
  // The ended jobs' inputs are listed for removal until forgotten.
  auto ended_work = store_->EndedWork();
  ASSERT_TRUE(ended_work.ok());
  std::vector<std::string> ended_dirs;
  for (const QueuedWork& w : *ended_work) ended_dirs.push_back(w.stack_dir);
  std::sort(ended_dirs.begin(), ended_dirs.end());
  EXPECT_EQ(ended_dirs, (std::vector<std::string>{"uploads/rec-2", "uploads/rec-3"}));
  ASSERT_TRUE(store_->ForgetWork("rec-3").ok());
  ASSERT_TRUE(store_->ForgetWork("rec-1").ok());  // not ended: kept
  EXPECT_EQ(store_->EndedWork()->size(), 1u);
  EXPECT_EQ(*store_->QueuedWorkIds(), std::vector<std::string>{"rec-1"});
  // Every row's input folder, ended or not: what the sweep of uploads/ must leave.
  auto inputs = store_->WorkInputDirs();
  ASSERT_TRUE(inputs.ok()) << inputs.status().ToString();
  std::sort(inputs->begin(), inputs->end());
  EXPECT_EQ(*inputs, (std::vector<std::string>{"uploads/rec-1", "uploads/rec-2"}));
}

TEST_P(DataStoreTest, AnExpiredLeaseIsTakenOverAndTheEarlierAttemptsArtifactRowsGo) {
  ASSERT_TRUE(store_->EnqueueWork(Job("rec-1", v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_QUEUED, 1),
                                  QueueEvent("rec-1", 1, v1::JOB_STATE_QUEUED), Work("rec-1"))
                  .ok());
  auto dead = store_->ClaimWork("worker-dead", /*lease_ms=*/1, {});
  ASSERT_TRUE(dead.ok() && dead->has_value());
  StoredArtifact art;
  art.job_id = "rec-1";
  art.path = dir_ / "artifacts/rec-1/depth.tiff";
  art.artifact.set_artifact_id("art-1");
  ASSERT_TRUE(store_->PutArtifact(art).ok());
  // Poll (with a deadline) until the 1 ms lease has run out on the store's clock.
  std::optional<QueuedWork> taken;
  for (auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
       !taken && std::chrono::steady_clock::now() < deadline;) {
    auto c = store_->ClaimWork("worker-b", 60000, {});
    ASSERT_TRUE(c.ok()) << c.status().ToString();
    taken = *c;
  }
  ASSERT_TRUE(taken.has_value()) << "the expired lease was never taken over";
  EXPECT_EQ(taken->attempts, 2);
  EXPECT_EQ(store_->GetArtifact("art-1").status().code(), StatusCode::kNotFound);
  // The dead worker's late end is refused; the new holder's is recorded.
  v1::Job ended = Job("rec-1", v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_SUCCEEDED, 1);
  EXPECT_FALSE(*store_->CompleteWork("worker-dead", ended, QueueEvent("rec-1", 2, v1::JOB_STATE_SUCCEEDED)));
  EXPECT_TRUE(*store_->CompleteWork("worker-b", ended, QueueEvent("rec-1", 2, v1::JOB_STATE_SUCCEEDED)));
  EXPECT_TRUE(store_->QueuedWorkIds()->empty());
}

// A claim whose answer never reached its worker (the connection broke after the database ran
// it): the worker does not know it holds the job, so its renewals leave that lease alone and the
// job is taken again once the lease runs out, instead of being held for ever.
TEST_P(DataStoreTest, ALeaseTheWorkerDoesNotKnowItHoldsIsNotRenewedAndIsTakenAgain) {
  for (const std::string id : {"rec-1", "rec-2"}) {
    ASSERT_TRUE(store_->EnqueueWork(Job(id, v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_QUEUED, id == "rec-1" ? 1 : 2),
                                    QueueEvent(id, 1, v1::JOB_STATE_QUEUED), Work(id))
                    .ok());
  }
  auto running = store_->ClaimWork("worker-a", 60000, {});  // the job worker-a runs
  ASSERT_TRUE(running.ok() && running->has_value());
  ASSERT_EQ((*running)->job_id, "rec-1");
  auto lost = store_->ClaimWork("worker-a", /*lease_ms=*/1, {});  // its answer "lost"
  ASSERT_TRUE(lost.ok() && lost->has_value());
  ASSERT_EQ((*lost)->job_id, "rec-2");
  // Renewals name only rec-1; poll (with a deadline) until rec-2's 1 ms lease has run out.
  std::optional<QueuedWork> taken;
  for (auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
       !taken && std::chrono::steady_clock::now() < deadline;) {
    auto renewal = store_->RenewLeases("worker-a", 60000, {"rec-1"});
    ASSERT_TRUE(renewal.ok()) << renewal.status().ToString();
    EXPECT_EQ(renewal->held, std::vector<std::string>{"rec-1"});
    auto c = store_->ClaimWork("worker-b", 60000, {});
    ASSERT_TRUE(c.ok()) << c.status().ToString();
    taken = *c;
  }
  ASSERT_TRUE(taken.has_value()) << "the unknown lease was renewed and never taken over";
  EXPECT_EQ(taken->job_id, "rec-2");
  EXPECT_EQ(taken->attempts, 2);
  EXPECT_FALSE(*store_->CompleteWork("worker-a", Job("rec-2", v1::JOB_KIND_RECONSTRUCT, v1::JOB_STATE_SUCCEEDED, 2),
                                     QueueEvent("rec-2", 2, v1::JOB_STATE_SUCCEEDED)));
  EXPECT_EQ(*store_->QueueDepth(), 0);  // rec-1 still held by worker-a, rec-2 by worker-b
}

// Verification records (schema version 5): stored whole, replaced under their id, listed newest
// first per calibration and mode, kept across a reopen.
v1::VerificationRecord Verification(const std::string& id, const std::string& calibration, v1::VerificationMode mode,
                                    int64_t finish_s, double alpha_z) {
  v1::VerificationRecord r;
  r.set_verification_id(id);
  r.set_calibration_id(calibration);
  r.set_mode(mode);
  r.mutable_finish_time()->set_seconds(finish_s);
  r.set_scans(mode == v1::VERIFICATION_MODE_FULL ? 15 : 3);
  v1::VerificationCharacteristic* c = r.add_characteristics();
  c->set_name("alpha_z");
  c->set_value(alpha_z);
  c->set_standard_uncertainty(0.0009);
  c->set_expanded_uncertainty(0.0018);
  v1::VerificationStepPoint* step = r.add_steps();
  step->set_specimen("pgr10");
  step->set_certified_um(10.0);
  step->set_measured_um(9.959);
  r.set_state(mode == v1::VERIFICATION_MODE_FULL ? v1::VERIFICATION_STATE_VERIFIED : v1::VERIFICATION_STATE_FAILED);
  if (mode == v1::VERIFICATION_MODE_INTERIM) r.add_findings("pgr10 step: 10.01 um against 9.959 um");
  return r;
}

TEST_P(DataStoreTest, VerificationsRoundTripReplaceAndListNewestFirstPerCalibrationAndMode) {
  ASSERT_TRUE(store_->PutVerification(Verification("ver-a", "cal-1", v1::VERIFICATION_MODE_FULL, 100, 1.001)).ok());
  ASSERT_TRUE(store_->PutVerification(Verification("ver-b", "cal-1", v1::VERIFICATION_MODE_INTERIM, 200, 1.004)).ok());
  ASSERT_TRUE(store_->PutVerification(Verification("ver-c", "cal-1", v1::VERIFICATION_MODE_FULL, 300, 1.002)).ok());
  ASSERT_TRUE(store_->PutVerification(Verification("ver-d", "cal-2", v1::VERIFICATION_MODE_FULL, 400, 0.999)).ok());
  ASSERT_TRUE(store_->PutVerification(Verification("ver-e", "", v1::VERIFICATION_MODE_FULL, 500, 1.0)).ok());

  auto full = store_->ListVerifications("cal-1", v1::VERIFICATION_MODE_FULL, 10);
  ASSERT_TRUE(full.ok()) << full.status().ToString();
  ASSERT_EQ(full->size(), 2u);
  EXPECT_EQ((*full)[0].verification_id(), "ver-c");
  EXPECT_EQ((*full)[1].verification_id(), "ver-a");
  EXPECT_EQ((*full)[0].SerializeAsString(),
            Verification("ver-c", "cal-1", v1::VERIFICATION_MODE_FULL, 300, 1.002).SerializeAsString());
  auto any = store_->ListVerifications("cal-1", v1::VERIFICATION_MODE_UNSPECIFIED, 10);
  ASSERT_TRUE(any.ok());
  ASSERT_EQ(any->size(), 3u);
  EXPECT_EQ((*any)[1].verification_id(), "ver-b");
  EXPECT_EQ((*any)[1].findings(0), "pgr10 step: 10.01 um against 9.959 um");
  EXPECT_EQ(store_->ListVerifications("cal-1", v1::VERIFICATION_MODE_FULL, 1)->size(), 1u);
  EXPECT_EQ(store_->ListVerifications("cal-9", v1::VERIFICATION_MODE_UNSPECIFIED, 10)->size(), 0u);
  auto uncalibrated = store_->ListVerifications("", v1::VERIFICATION_MODE_FULL, 10);
  ASSERT_TRUE(uncalibrated.ok());
  ASSERT_EQ(uncalibrated->size(), 1u);
  EXPECT_EQ((*uncalibrated)[0].verification_id(), "ver-e");

  // Stored again under its id: replaced, not duplicated; and kept across a reopen.
  ASSERT_TRUE(store_->PutVerification(Verification("ver-c", "cal-1", v1::VERIFICATION_MODE_FULL, 300, 1.003)).ok());
  Reopen();
  full = store_->ListVerifications("cal-1", v1::VERIFICATION_MODE_FULL, 10);
  ASSERT_TRUE(full.ok());
  ASSERT_EQ(full->size(), 2u);
  EXPECT_DOUBLE_EQ((*full)[0].characteristics(0).value(), 1.003);
}

INSTANTIATE_TEST_SUITE_P(Backends, DataStoreTest, ::testing::Values("sqlite", "postgresql"),
                         [](const auto& info) { return info.param; });

TEST(DataStoreOpenTest, AMalformedDatabaseUrlIsInvalidArgumentNamingTheKey) {
  const fs::path dir = fs::temp_directory_path() / ("inspect-store-bad-" + std::to_string(getpid()));
  for (const std::string url : {"mysql://x", "postgresql://u:pw@host:notaport/db", "postgresql://h/db?nosuch=1"}) {
    auto s = DataStore::Open(dir, {url, ""});
    ASSERT_FALSE(s.ok()) << url;
    EXPECT_EQ(s.status().code(), StatusCode::kInvalidArgument) << url << ": " << s.status().ToString();
    EXPECT_EQ(s.status().message().rfind("database: ", 0), 0u) << s.status().message();
    EXPECT_EQ(s.status().message().find(":pw@"), std::string::npos) << "password leaked: " << s.status().message();
  }
  EXPECT_EQ(DataStore::Open(dir, {"", "/some/file"}).status().code(), StatusCode::kInvalidArgument);
  fs::remove_all(dir);
}

TEST(DataStoreOpenTest, AnUnreachableServerIsUnavailableAndTheWrongPasswordSaysSoWithoutTheSecret) {
  const fs::path dir = fs::temp_directory_path() / ("inspect-store-down-" + std::to_string(getpid()));
  // A port nothing listens on: the PostgreSQL server's own port + 1 is as good as any free one.
  auto down = DataStore::Open(dir, {"postgresql://postgres:topsecret@127.0.0.1:1/postgres?connect_timeout=2", ""});
  ASSERT_FALSE(down.ok());
  EXPECT_EQ(down.status().code(), StatusCode::kUnavailable) << down.status().ToString();
  EXPECT_EQ(down.status().message().find("topsecret"), std::string::npos) << down.status().message();

  ASSERT_TRUE(Postgres().started());
  const fs::path wrong = dir / "wrong-password";
  fs::create_directories(dir);
  std::ofstream(wrong) << "not-the-password\n";
  auto denied = DataStore::Open(dir, {Postgres().Url(), wrong});
  ASSERT_FALSE(denied.ok());
  EXPECT_NE(denied.status().message().find("password authentication failed"), std::string::npos)
      << denied.status().message();
  EXPECT_EQ(denied.status().message().find("not-the-password"), std::string::npos);
  auto right = DataStore::Open(dir, {Postgres().Url(), Postgres().PasswordFile()});
  EXPECT_TRUE(right.ok()) << right.status().ToString();
  fs::remove_all(dir);
}

TEST(DataStoreOpenTest, RedactDatabaseUrlHidesPasswordsInEveryForm) {
  EXPECT_EQ(RedactDatabaseUrl("postgresql://u:pw@h:5432/db"), "postgresql://u:***@h:5432/db");
  EXPECT_EQ(RedactDatabaseUrl("postgresql://u@h/db?sslmode=require&password=pw"),
            "postgresql://u@h/db?sslmode=require&password=***");
  EXPECT_EQ(RedactDatabaseUrl("host=h password=pw dbname=d"), "host=h password=*** dbname=d");
  EXPECT_EQ(RedactDatabaseUrl("postgresql://u@h/db"), "postgresql://u@h/db");
}

TEST(DataStoreOpenTest, ThePostgresStoreReconnectsAfterTheServerRestarts) {
  ASSERT_TRUE(Postgres().started());
  const fs::path dir = fs::temp_directory_path() / ("inspect-store-restart-" + std::to_string(getpid()));
  const std::string url = Postgres().CreateDatabase("store_restart_" + std::to_string(getpid()));
  auto s = DataStore::Open(dir, {url, Postgres().PasswordFile()});
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  std::unique_ptr<DataStore> store = std::move(*s);
  ASSERT_TRUE(store->SetSetting("k", "before").ok());
  ASSERT_TRUE(Postgres().Stop());
  EXPECT_EQ(store->SetSetting("k", "while down").code(), StatusCode::kUnavailable);
  ASSERT_TRUE(Postgres().Start());
  EXPECT_TRUE(store->SetSetting("k", "after").ok());  // reset once, then the statement
  EXPECT_EQ(store->GetSetting("k"), "after");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace inspection
