// The SQLite backend of DataStore: one rig's metadata in <data dir>/inspection.db (WAL).
#include "server/storage/internal/sqlite_store.h"

#include <sqlite3.h>

#include <mutex>

#include "server/storage/internal/schema.h"

#include <algorithm>
#include <chrono>
#include <random>

namespace inspection {
namespace fs = std::filesystem;

namespace {

// RAII statement with the few binding helpers this store needs.
class Stmt {
 public:
  Stmt(sqlite3* db, const char* sql) { rc_ = sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr); }
  ~Stmt() { sqlite3_finalize(stmt_); }
  bool ok() const { return rc_ == SQLITE_OK; }
  Stmt& Text(int i, const std::string& s) {
    sqlite3_bind_text(stmt_, i, s.data(), int(s.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Stmt& Blob(int i, const std::string& s) {
    sqlite3_bind_blob(stmt_, i, s.data(), int(s.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Stmt& Int(int i, int64_t v) {
    sqlite3_bind_int64(stmt_, i, v);
    return *this;
  }
  int Step() { return sqlite3_step(stmt_); }
  sqlite3_stmt* stmt() { return stmt_; }
  std::string ColumnBlob(int i) {
    const void* p = sqlite3_column_blob(stmt_, i);
    return p ? std::string(static_cast<const char*>(p), size_t(sqlite3_column_bytes(stmt_, i))) : std::string();
  }
  std::string ColumnText(int i) {
    const unsigned char* p = sqlite3_column_text(stmt_, i);
    return p ? std::string(reinterpret_cast<const char*>(p)) : std::string();
  }

 private:
  sqlite3_stmt* stmt_ = nullptr;
  int rc_ = SQLITE_ERROR;
};

Status DbError(sqlite3* db, const std::string& what) {
  return Status::Internal("database: " + what + ": " + sqlite3_errmsg(db));
}

int64_t CreateNs(const v1::Job& job) { return job.create_time().seconds() * 1000000000LL + job.create_time().nanos(); }

}  // namespace

namespace {

class SqliteDataStore final : public DataStore {
 public:
  explicit SqliteDataStore(fs::path dir) : DataStore(std::move(dir)) {}
  ~SqliteDataStore() override;
  Status Connect();
  const char* backend() const override { return "sqlite"; }
  bool shared() const override { return false; }

  Status PutJob(const v1::Job& job) override;
  StatusOr<v1::Job> GetJob(const std::string& job_id) override;
  std::optional<std::string> FindJobByRequestId(v1::JobKind kind, const std::string& request_id) override;
  StatusOr<std::vector<v1::Job>> ListJobs(v1::JobKind kind, v1::JobState state, int limit, int64_t before_create_ns) override;
  StatusOr<std::vector<v1::Job>> UnfinishedJobs() override;
  Status AppendEvent(const v1::JobEvent& event) override;
  Status AppendEvents(const std::vector<v1::JobEvent>& events) override;
  StatusOr<std::vector<v1::JobEvent>> Events(const std::string& job_id) override;
  Status PutArtifact(const StoredArtifact& artifact) override;
  StatusOr<StoredArtifact> GetArtifact(const std::string& artifact_id) override;
  Status PutCalibration(const v1::Calibration& calibration) override;
  StatusOr<v1::Calibration> GetCalibration(const std::string& calibration_id) override;
  StatusOr<std::vector<v1::Calibration>> ListCalibrations() override;
  Status SetPinned(const std::string& job_id, bool pinned) override;
  StatusOr<std::vector<std::string>> PinnedJobs() override;
  StatusOr<std::vector<v1::Job>> FinishedJobs() override;
  Status DeleteJobRecords(const std::string& job_id) override;
  StatusOr<std::vector<StoredArtifact>> DeleteArtifactsOfKind(const std::string& job_id, v1::ArtifactKind kind) override;
  StatusOr<v1::Recipe> StoreRecipe(v1::Recipe recipe, bool create, int expected_version) override;
  StatusOr<v1::Recipe> GetRecipe(const std::string& recipe_id, int version) override;
  StatusOr<std::vector<v1::Recipe>> ListRecipes() override;
  StatusOr<int> DeleteRecipe(const std::string& recipe_id) override;
  StatusOr<v1::InspectionResult> AppendResult(v1::InspectionResult result) override;
  StatusOr<v1::InspectionResult> ImportResult(v1::InspectionResult result) override;
  StatusOr<std::vector<v1::InspectionResult>> ListResults(const ResultQuery& query) override;
  StatusOr<std::vector<v1::InspectionResult>> ResultsAfter(int64_t after_sequence, int limit) override;
  StatusOr<int64_t> LastResultSequence() override;
  Status PutStudy(const v1::Study& study) override;
  StatusOr<v1::Study> GetStudy(const std::string& study_id) override;
  StatusOr<std::vector<v1::Study>> ListStudies(const std::string& recipe_id, int limit) override;
  Status PutVerification(const v1::VerificationRecord& record) override;
  StatusOr<std::vector<v1::VerificationRecord>> ListVerifications(const std::string& calibration_id,
                                                                  v1::VerificationMode mode, int limit) override;
  Status SetSetting(const std::string& key, const std::string& value) override;
  std::string GetSetting(const std::string& key) override;
  Status EnqueueWork(const v1::Job& job, const v1::JobEvent& queued_event, const QueuedWork& work) override;
  StatusOr<std::optional<QueuedWork>> ClaimWork(const std::string& worker, int64_t lease_ms,
                                                const std::vector<std::string>& preferred) override;
  StatusOr<LeaseRenewal> RenewLeases(const std::string& worker, int64_t lease_ms,
                                     const std::vector<std::string>& running) override;
  StatusOr<bool> CompleteWork(const std::string& worker, const v1::Job& ended, const v1::JobEvent& terminal_event) override;
  StatusOr<bool> ReleaseWork(const std::string& worker, const v1::Job& queued, const v1::JobEvent& event) override;
  StatusOr<bool> CancelQueuedWork(const v1::Job& cancelled, const v1::JobEvent& event) override;
  StatusOr<int64_t> QueueDepth() override;
  StatusOr<std::vector<std::string>> QueuedWorkIds() override;
  StatusOr<std::vector<QueuedWork>> EndedWork() override;
  StatusOr<std::vector<std::string>> WorkInputDirs() override;
  Status ForgetWork(const std::string& job_id) override;

 private:
  // `body` between BEGIN IMMEDIATE and COMMIT (ROLLBACK when it fails). Caller holds mu_.
  template <typename F>
  Status InTransaction(F&& body);
  // The job row and one event (caller holds mu_, inside a transaction).
  Status WriteJobAndEvent(const v1::Job& job, const v1::JobEvent& event);
  Status Exec(const char* sql);
  Status Migrate();

  std::mutex mu_;  // guards db_ (one connection; SQLite's FULLMUTEX alone would not keep
                   // the multi-statement transactions below atomic)
  sqlite3* db_ = nullptr;
};

// Type-1 gauge studies: one row per study, the Study message whole; self-contained, so it can
// take another version number.
constexpr const char* kSqliteStudiesMigration = R"sql(
    CREATE TABLE IF NOT EXISTS studies (
      study_id TEXT PRIMARY KEY, recipe_id TEXT NOT NULL, finish_ns INTEGER NOT NULL, study BLOB NOT NULL);
    CREATE INDEX IF NOT EXISTS studies_by_recipe ON studies(recipe_id, finish_ns);
  )sql";

// Instrument verifications: one row per record, the VerificationRecord message whole, found by
// the calibration it was made under and its mode.
constexpr const char* kSqliteVerificationsMigration = R"sql(
    CREATE TABLE IF NOT EXISTS verifications (
      verification_id TEXT PRIMARY KEY, calibration_id TEXT NOT NULL, mode INTEGER NOT NULL,
      finish_ns INTEGER NOT NULL, record BLOB NOT NULL);
    CREATE INDEX IF NOT EXISTS verifications_by_calibration ON verifications(calibration_id, mode, finish_ns);
  )sql";

// Schema versions of the SQLite backend; index i migrates version i to i + 1. Version 1 is the
// layout every database made before versioning has (CREATE ... IF NOT EXISTS keeps it), so such
// a database is taken as version 0 and migrated like a new one.
const char* const kSqliteMigrations[] = {
    R"sql(
    CREATE TABLE IF NOT EXISTS jobs (
      job_id TEXT PRIMARY KEY, kind INTEGER NOT NULL, state INTEGER NOT NULL, request_id TEXT NOT NULL,
      create_ns INTEGER NOT NULL, calibration_id TEXT NOT NULL DEFAULT '', job BLOB NOT NULL);
    CREATE INDEX IF NOT EXISTS jobs_by_time ON jobs(create_ns);
    CREATE INDEX IF NOT EXISTS jobs_by_request ON jobs(kind, request_id);
    CREATE TABLE IF NOT EXISTS events (
      job_id TEXT NOT NULL, sequence INTEGER NOT NULL, event BLOB NOT NULL, PRIMARY KEY(job_id, sequence));
    CREATE TABLE IF NOT EXISTS artifacts (
      artifact_id TEXT PRIMARY KEY, job_id TEXT NOT NULL, path TEXT NOT NULL, artifact BLOB NOT NULL);
    CREATE TABLE IF NOT EXISTS calibrations (
      calibration_id TEXT PRIMARY KEY, create_ns INTEGER NOT NULL, calibration BLOB NOT NULL);
    CREATE TABLE IF NOT EXISTS settings (key TEXT PRIMARY KEY, value TEXT NOT NULL);
    CREATE TABLE IF NOT EXISTS pins (job_id TEXT PRIMARY KEY);
    CREATE TABLE IF NOT EXISTS recipes (
      recipe_id TEXT NOT NULL, version INTEGER NOT NULL, deleted INTEGER NOT NULL DEFAULT 0,
      recipe BLOB NOT NULL, PRIMARY KEY(recipe_id, version));
    CREATE INDEX IF NOT EXISTS artifacts_by_job ON artifacts(job_id);
    CREATE TABLE IF NOT EXISTS results (
      sequence INTEGER PRIMARY KEY AUTOINCREMENT, job_id TEXT NOT NULL UNIQUE, part_id TEXT NOT NULL,
      recipe_id TEXT NOT NULL, verdict INTEGER NOT NULL, finish_ns INTEGER NOT NULL, result BLOB NOT NULL);
    CREATE INDEX IF NOT EXISTS results_by_part ON results(part_id, sequence);
    CREATE INDEX IF NOT EXISTS results_by_recipe ON results(recipe_id, sequence);
  )sql",
    R"sql(
    ALTER TABLE results ADD COLUMN rig_id TEXT NOT NULL DEFAULT '';
    ALTER TABLE results ADD COLUMN rig_sequence INTEGER NOT NULL DEFAULT 0;
    CREATE UNIQUE INDEX results_by_rig ON results(rig_id, rig_sequence) WHERE rig_id <> '';
  )sql",
    // The work queue (data_store.h): kept in step with PostgreSQL's so one interface serves both;
    // one process uses a SQLite file, so its leases are judged by this process's clock.
    R"sql(
    CREATE TABLE work_queue (
      job_id TEXT PRIMARY KEY, enqueue_ns INTEGER NOT NULL, input BLOB NOT NULL, stack_dir TEXT NOT NULL,
      lease_owner TEXT NOT NULL DEFAULT '', lease_expires_ns INTEGER NOT NULL DEFAULT 0,
      attempts INTEGER NOT NULL DEFAULT 0, cancel_requested INTEGER NOT NULL DEFAULT 0,
      ended INTEGER NOT NULL DEFAULT 0);
    CREATE INDEX work_queue_by_age ON work_queue(enqueue_ns);
  )sql",
    kSqliteStudiesMigration,
    kSqliteVerificationsMigration,
};
static_assert(std::size(kSqliteMigrations) == kStoreSchemaVersion, "one migration per schema version");

}  // namespace

StatusOr<std::unique_ptr<DataStore>> OpenSqliteStore(const fs::path& data_dir) {
  auto store = std::make_unique<SqliteDataStore>(data_dir);
  INSPECT_RETURN_IF_ERROR(store->Connect());
  return std::unique_ptr<DataStore>(std::move(store));
}

Status SqliteDataStore::Connect() {
  const fs::path db_path = data_dir() / "inspection.db";
  if (sqlite3_open_v2(db_path.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX,
                      nullptr) != SQLITE_OK) {
    return Status::FailedPrecondition("data dir: cannot open " + db_path.string() + ": " +
                                      (db_ ? sqlite3_errmsg(db_) : "out of memory"));
  }
  sqlite3_busy_timeout(db_, 5000);
  INSPECT_RETURN_IF_ERROR(Exec("PRAGMA journal_mode=WAL"));
  INSPECT_RETURN_IF_ERROR(Exec("PRAGMA synchronous=NORMAL"));
  return Migrate();
}

Status SqliteDataStore::Migrate() {
  INSPECT_RETURN_IF_ERROR(Exec("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)"));
  int64_t stored = 0;
  {
    Stmt st(db_, "SELECT COALESCE(MAX(version), 0) FROM schema_version");
    if (st.Step() != SQLITE_ROW) return DbError(db_, "reading the schema version");
    stored = sqlite3_column_int64(st.stmt(), 0);
  }
  INSPECT_RETURN_IF_ERROR(CheckSchemaVersion(stored, "inspection.db"));
  for (int64_t v = stored; v < kStoreSchemaVersion; ++v) {
    INSPECT_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
    Status s = Exec(kSqliteMigrations[v]);
    if (s.ok()) {
      Stmt st(db_, "INSERT INTO schema_version(version) VALUES(?)");
      st.Int(1, v + 1);
      if (st.Step() != SQLITE_DONE) s = DbError(db_, "recording schema version " + std::to_string(v + 1));
    }
    if (!s.ok()) {
      (void)Exec("ROLLBACK");
      return s;
    }
    INSPECT_RETURN_IF_ERROR(Exec("COMMIT"));
  }
  return Status::Ok();
}

SqliteDataStore::~SqliteDataStore() {
  if (db_) sqlite3_close(db_);
}

Status SqliteDataStore::Exec(const char* sql) {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &err) != SQLITE_OK) {
    Status s = Status::Internal(std::string("database: ") + (err ? err : "error"));
    sqlite3_free(err);
    return s;
  }
  return Status::Ok();
}

Status SqliteDataStore::PutJob(const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_,
          "INSERT OR REPLACE INTO jobs(job_id, kind, state, request_id, create_ns, calibration_id, job) "
          "VALUES(?,?,?,?,?,?,?)");
  if (!st.ok()) return DbError(db_, "prepare PutJob");
  st.Text(1, job.job_id()).Int(2, job.kind()).Int(3, job.state()).Text(4, job.request_id()).Int(5, CreateNs(job));
  st.Text(6, job.kind() == v1::JOB_KIND_SCAN ? job.result().calibration_id() : std::string());
  st.Blob(7, job.SerializeAsString());
  if (st.Step() != SQLITE_DONE) return DbError(db_, "PutJob");
  return Status::Ok();
}

StatusOr<v1::Job> SqliteDataStore::GetJob(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT job FROM jobs WHERE job_id = ?");
  st.Text(1, job_id);
  if (st.Step() != SQLITE_ROW) return Status::NotFound("job_id '" + job_id + "' not found");
  v1::Job job;
  if (!job.ParseFromString(st.ColumnBlob(0))) return Status::DataLoss("job " + job_id + " record is corrupt");
  return job;
}

std::optional<std::string> SqliteDataStore::FindJobByRequestId(v1::JobKind kind, const std::string& request_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT job_id FROM jobs WHERE kind = ? AND request_id = ? ORDER BY create_ns LIMIT 1");
  st.Int(1, kind).Text(2, request_id);
  if (st.Step() != SQLITE_ROW) return std::nullopt;
  return st.ColumnText(0);
}

StatusOr<std::vector<v1::Job>> SqliteDataStore::ListJobs(v1::JobKind kind, v1::JobState state, int limit,
                                                   int64_t before_create_ns) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_,
          "SELECT job FROM jobs WHERE (?1 = 0 OR kind = ?1) AND (?2 = 0 OR state = ?2) AND (?3 = 0 OR create_ns < ?3) "
          "ORDER BY create_ns DESC LIMIT ?4");
  st.Int(1, kind).Int(2, state).Int(3, before_create_ns).Int(4, limit);
  std::vector<v1::Job> jobs;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    v1::Job job;
    if (job.ParseFromString(st.ColumnBlob(0))) jobs.push_back(std::move(job));
  }
  return jobs;
}

StatusOr<std::vector<v1::Job>> SqliteDataStore::UnfinishedJobs() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT job FROM jobs WHERE state IN (?, ?)");
  st.Int(1, v1::JOB_STATE_QUEUED).Int(2, v1::JOB_STATE_RUNNING);
  std::vector<v1::Job> jobs;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    v1::Job job;
    if (job.ParseFromString(st.ColumnBlob(0))) jobs.push_back(std::move(job));
  }
  return jobs;
}

Status SqliteDataStore::AppendEvent(const v1::JobEvent& event) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "INSERT OR REPLACE INTO events(job_id, sequence, event) VALUES(?,?,?)");
  st.Text(1, event.job_id()).Int(2, int64_t(event.sequence())).Blob(3, event.SerializeAsString());
  if (st.Step() != SQLITE_DONE) return DbError(db_, "AppendEvent");
  return Status::Ok();
}

Status SqliteDataStore::AppendEvents(const std::vector<v1::JobEvent>& events) {
  std::lock_guard<std::mutex> lock(mu_);
  return InTransaction([&]() -> Status {
    for (const v1::JobEvent& event : events) {
      Stmt st(db_, "INSERT OR REPLACE INTO events(job_id, sequence, event) VALUES(?,?,?)");
      st.Text(1, event.job_id()).Int(2, int64_t(event.sequence())).Blob(3, event.SerializeAsString());
      if (st.Step() != SQLITE_DONE) return DbError(db_, "AppendEvents");
    }
    return Status::Ok();
  });
}

StatusOr<std::vector<v1::JobEvent>> SqliteDataStore::Events(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT event FROM events WHERE job_id = ? ORDER BY sequence");
  st.Text(1, job_id);
  std::vector<v1::JobEvent> events;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    v1::JobEvent e;
    if (e.ParseFromString(st.ColumnBlob(0))) events.push_back(std::move(e));
  }
  return events;
}

Status SqliteDataStore::PutArtifact(const StoredArtifact& a) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "INSERT OR REPLACE INTO artifacts(artifact_id, job_id, path, artifact) VALUES(?,?,?,?)");
  st.Text(1, a.artifact.artifact_id())
      .Text(2, a.job_id)
      .Text(3, a.path.string())
      .Blob(4, a.artifact.SerializeAsString());
  if (st.Step() != SQLITE_DONE) return DbError(db_, "PutArtifact");
  return Status::Ok();
}

StatusOr<StoredArtifact> SqliteDataStore::GetArtifact(const std::string& artifact_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT job_id, path, artifact FROM artifacts WHERE artifact_id = ?");
  st.Text(1, artifact_id);
  if (st.Step() != SQLITE_ROW) return Status::NotFound("artifact_id '" + artifact_id + "' not found");
  StoredArtifact a;
  a.job_id = st.ColumnText(0);
  a.path = st.ColumnText(1);
  if (!a.artifact.ParseFromString(st.ColumnBlob(2))) return Status::DataLoss("artifact record is corrupt");
  return a;
}

Status SqliteDataStore::PutCalibration(const v1::Calibration& c) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "INSERT OR REPLACE INTO calibrations(calibration_id, create_ns, calibration) VALUES(?,?,?)");
  st.Text(1, c.calibration_id())
      .Int(2, c.create_time().seconds() * 1000000000LL + c.create_time().nanos())
      .Blob(3, c.SerializeAsString());
  if (st.Step() != SQLITE_DONE) return DbError(db_, "PutCalibration");
  return Status::Ok();
}

StatusOr<v1::Calibration> SqliteDataStore::GetCalibration(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT calibration FROM calibrations WHERE calibration_id = ?");
  st.Text(1, id);
  if (st.Step() != SQLITE_ROW) return Status::NotFound("calibration_id '" + id + "' not found");
  v1::Calibration c;
  if (!c.ParseFromString(st.ColumnBlob(0))) return Status::DataLoss("calibration record is corrupt");
  return c;
}

StatusOr<std::vector<v1::Calibration>> SqliteDataStore::ListCalibrations() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT calibration FROM calibrations ORDER BY create_ns DESC");
  std::vector<v1::Calibration> out;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    v1::Calibration c;
    if (c.ParseFromString(st.ColumnBlob(0))) out.push_back(std::move(c));
  }
  return out;
}

Status SqliteDataStore::SetPinned(const std::string& job_id, bool pinned) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, pinned ? "INSERT OR IGNORE INTO pins(job_id) VALUES(?)" : "DELETE FROM pins WHERE job_id = ?");
  st.Text(1, job_id);
  if (st.Step() != SQLITE_DONE) return DbError(db_, "SetPinned");
  return Status::Ok();
}

StatusOr<std::vector<std::string>> SqliteDataStore::PinnedJobs() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT job_id FROM pins");
  std::vector<std::string> ids;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) ids.push_back(st.ColumnText(0));
  return ids;
}

StatusOr<std::vector<v1::Job>> SqliteDataStore::FinishedJobs() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT job FROM jobs WHERE state IN (?, ?, ?)");
  st.Int(1, v1::JOB_STATE_SUCCEEDED).Int(2, v1::JOB_STATE_FAILED).Int(3, v1::JOB_STATE_CANCELLED);
  std::vector<v1::Job> jobs;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    v1::Job job;
    if (job.ParseFromString(st.ColumnBlob(0))) jobs.push_back(std::move(job));
  }
  return jobs;
}

Status SqliteDataStore::DeleteJobRecords(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  INSPECT_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
  for (const char* sql : {"DELETE FROM artifacts WHERE job_id = ?", "DELETE FROM events WHERE job_id = ?",
                          "DELETE FROM pins WHERE job_id = ?", "DELETE FROM jobs WHERE job_id = ?"}) {
    Stmt st(db_, sql);
    st.Text(1, job_id);
    if (st.Step() != SQLITE_DONE) {
      Status s = DbError(db_, "DeleteJobRecords");
      Exec("ROLLBACK").IgnoreError();
      return s;
    }
  }
  return Exec("COMMIT");
}

StatusOr<std::vector<StoredArtifact>> SqliteDataStore::DeleteArtifactsOfKind(const std::string& job_id,
                                                                       v1::ArtifactKind kind) {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<StoredArtifact> removed;
  {
    Stmt st(db_, "SELECT path, artifact FROM artifacts WHERE job_id = ?");
    st.Text(1, job_id);
    for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
      StoredArtifact a;
      a.job_id = job_id;
      a.path = st.ColumnText(0);
      if (a.artifact.ParseFromString(st.ColumnBlob(1)) && a.artifact.kind() == kind) removed.push_back(std::move(a));
    }
  }
  v1::Job job;
  {
    Stmt st(db_, "SELECT job FROM jobs WHERE job_id = ?");
    st.Text(1, job_id);
    if (st.Step() != SQLITE_ROW) return Status::NotFound("job_id '" + job_id + "' not found");
    if (!job.ParseFromString(st.ColumnBlob(0))) return Status::DataLoss("job " + job_id + " record is corrupt");
  }
  auto* artifacts = job.mutable_result()->mutable_artifacts();
  artifacts->erase(
      std::remove_if(artifacts->begin(), artifacts->end(), [&](const v1::Artifact& a) { return a.kind() == kind; }),
      artifacts->end());
  INSPECT_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
  bool ok = true;
  for (const StoredArtifact& a : removed) {
    Stmt st(db_, "DELETE FROM artifacts WHERE artifact_id = ?");
    st.Text(1, a.artifact.artifact_id());
    ok = ok && st.Step() == SQLITE_DONE;
  }
  {
    Stmt st(db_, "UPDATE jobs SET job = ? WHERE job_id = ?");
    st.Blob(1, job.SerializeAsString()).Text(2, job_id);
    ok = ok && st.Step() == SQLITE_DONE;
  }
  if (!ok) {
    Status s = DbError(db_, "DeleteArtifactsOfKind");
    Exec("ROLLBACK").IgnoreError();
    return s;
  }
  INSPECT_RETURN_IF_ERROR(Exec("COMMIT"));
  return removed;
}

StatusOr<v1::Recipe> SqliteDataStore::StoreRecipe(v1::Recipe recipe, bool create, int expected_version) {
  std::lock_guard<std::mutex> lock(mu_);
  const std::string& id = recipe.recipe_id();
  Stmt q(db_, "SELECT MAX(version), MAX(CASE WHEN deleted = 0 THEN version END) FROM recipes WHERE recipe_id = ?");
  q.Text(1, id);
  if (q.Step() != SQLITE_ROW) return DbError(db_, "StoreRecipe");
  const int64_t highest = sqlite3_column_int64(q.stmt(), 0);  // NULL reads as 0
  const bool in_use = sqlite3_column_type(q.stmt(), 1) != SQLITE_NULL;
  const int64_t current = in_use ? sqlite3_column_int64(q.stmt(), 1) : 0;
  if (create && in_use) {
    return Status(StatusCode::kAlreadyExists, "recipe_id '" + id + "' exists (version " + std::to_string(current) +
                                                  "); UpdateRecipe makes a new version");
  }
  if (!create && !in_use) return Status::NotFound("recipe_id '" + id + "' not found");
  if (!create && expected_version > 0 && expected_version != current) {
    return Status::Aborted("recipe '" + id + "' is at version " + std::to_string(current) + ", not expected_version " +
                           std::to_string(expected_version) + " (updated meanwhile)");
  }
  recipe.set_version(int32_t(highest + 1));
  Stmt st(db_, "INSERT INTO recipes(recipe_id, version, deleted, recipe) VALUES(?,?,0,?)");
  st.Text(1, id).Int(2, recipe.version()).Blob(3, recipe.SerializeAsString());
  if (st.Step() != SQLITE_DONE) return DbError(db_, "StoreRecipe");
  return recipe;
}

StatusOr<v1::Recipe> SqliteDataStore::GetRecipe(const std::string& recipe_id, int version) {
  std::lock_guard<std::mutex> lock(mu_);
  // A hidden recipe's versions stay readable by version for the results that ran them.
  Stmt st(db_, version > 0 ? "SELECT recipe FROM recipes WHERE recipe_id = ?1 AND version = ?2"
                           : "SELECT recipe FROM recipes WHERE recipe_id = ?1 AND deleted = 0 "
                             "ORDER BY version DESC LIMIT 1");
  st.Text(1, recipe_id);
  if (version > 0) st.Int(2, version);
  if (st.Step() != SQLITE_ROW) {
    return Status::NotFound("recipe_id '" + recipe_id + "'" +
                            (version > 0 ? " version " + std::to_string(version) : std::string()) + " not found");
  }
  v1::Recipe recipe;
  if (!recipe.ParseFromString(st.ColumnBlob(0))) return Status::DataLoss("recipe " + recipe_id + " record is corrupt");
  return recipe;
}

StatusOr<std::vector<v1::Recipe>> SqliteDataStore::ListRecipes() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_,
          "SELECT recipe FROM recipes r WHERE deleted = 0 AND version = "
          "(SELECT MAX(version) FROM recipes WHERE recipe_id = r.recipe_id) ORDER BY recipe_id");
  std::vector<v1::Recipe> out;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    v1::Recipe recipe;
    if (recipe.ParseFromString(st.ColumnBlob(0))) out.push_back(std::move(recipe));
  }
  return out;
}

StatusOr<int> SqliteDataStore::DeleteRecipe(const std::string& recipe_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "UPDATE recipes SET deleted = 1 WHERE recipe_id = ? AND deleted = 0");
  st.Text(1, recipe_id);
  if (st.Step() != SQLITE_DONE) return DbError(db_, "DeleteRecipe");
  const int n = sqlite3_changes(db_);
  if (n == 0) return Status::NotFound("recipe_id '" + recipe_id + "' not found");
  return n;
}

StatusOr<v1::InspectionResult> SqliteDataStore::AppendResult(v1::InspectionResult result) {
  std::lock_guard<std::mutex> lock(mu_);
  const auto& t = result.finish_time();
  // AUTOINCREMENT: a deleted row's number is never handed out again, so a feed client's "last
  // sequence seen" stays meaningful. The blob carries its own number, set in the same transaction.
  INSPECT_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
  Stmt st(db_, "INSERT INTO results(job_id, part_id, recipe_id, verdict, finish_ns, result) VALUES(?,?,?,?,?,x'')");
  st.Text(1, result.job_id())
      .Text(2, result.part_id())
      .Text(3, result.recipe_id())
      .Int(4, result.verdict())
      .Int(5, t.seconds() * 1000000000LL + t.nanos());
  if (st.Step() != SQLITE_DONE) {
    const bool duplicate = sqlite3_extended_errcode(db_) == SQLITE_CONSTRAINT_UNIQUE;
    Status error = duplicate ? Status::AlreadyExists("job " + result.job_id() + " already has a result")
                             : DbError(db_, "AppendResult");
    (void)Exec("ROLLBACK");
    return error;
  }
  result.set_sequence(sqlite3_last_insert_rowid(db_));
  Stmt update(db_, "UPDATE results SET result = ? WHERE sequence = ?");
  update.Blob(1, result.SerializeAsString()).Int(2, result.sequence());
  if (update.Step() != SQLITE_DONE) {
    Status error = DbError(db_, "AppendResult");
    (void)Exec("ROLLBACK");
    return error;
  }
  INSPECT_RETURN_IF_ERROR(Exec("COMMIT"));
  return result;
}

StatusOr<v1::InspectionResult> SqliteDataStore::ImportResult(v1::InspectionResult result) {
  if (result.rig_id().empty() || result.rig_sequence() <= 0) {
    return Status::InvalidArgument("a forwarded result needs rig_id and rig_sequence");
  }
  std::lock_guard<std::mutex> lock(mu_);
  INSPECT_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
  {
    Stmt q(db_, "SELECT result FROM results WHERE rig_id = ? AND rig_sequence = ?");
    q.Text(1, result.rig_id()).Int(2, result.rig_sequence());
    if (q.Step() == SQLITE_ROW) {
      v1::InspectionResult stored;
      const bool ok = stored.ParseFromString(q.ColumnBlob(0));
      (void)Exec("ROLLBACK");
      if (!ok) return Status::DataLoss("an inspection result record is corrupt");
      return stored;
    }
  }
  const auto& t = result.finish_time();
  Stmt st(db_,
          "INSERT INTO results(job_id, part_id, recipe_id, verdict, finish_ns, result, rig_id, rig_sequence) "
          "VALUES(?,?,?,?,?,x'',?,?)");
  st.Text(1, result.job_id())
      .Text(2, result.part_id())
      .Text(3, result.recipe_id())
      .Int(4, result.verdict())
      .Int(5, t.seconds() * 1000000000LL + t.nanos())
      .Text(6, result.rig_id())
      .Int(7, result.rig_sequence());
  if (st.Step() != SQLITE_DONE) {
    Status error = DbError(db_, "ImportResult");
    (void)Exec("ROLLBACK");
    return error;
  }
  result.set_sequence(sqlite3_last_insert_rowid(db_));
  Stmt update(db_, "UPDATE results SET result = ? WHERE sequence = ?");
  update.Blob(1, result.SerializeAsString()).Int(2, result.sequence());
  if (update.Step() != SQLITE_DONE) {
    Status error = DbError(db_, "ImportResult");
    (void)Exec("ROLLBACK");
    return error;
  }
  INSPECT_RETURN_IF_ERROR(Exec("COMMIT"));
  return result;
}

namespace {
StatusOr<std::vector<v1::InspectionResult>> ReadResults(Stmt& st) {
  std::vector<v1::InspectionResult> out;
  int rc = st.Step();
  for (; rc == SQLITE_ROW; rc = st.Step()) {
    v1::InspectionResult r;
    if (!r.ParseFromString(st.ColumnBlob(0))) return Status::DataLoss("an inspection result record is corrupt");
    out.push_back(std::move(r));
  }
  if (rc != SQLITE_DONE)
    return Status::Internal("reading inspection results failed (sqlite " + std::to_string(rc) + ")");
  return out;
}
}  // namespace

StatusOr<std::vector<v1::InspectionResult>> SqliteDataStore::ListResults(const ResultQuery& q) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_,
          "SELECT result FROM results WHERE (?1 = '' OR part_id = ?1) AND (?2 = '' OR recipe_id = ?2) "
          "AND (?3 = 0 OR verdict = ?3) AND (?4 = 0 OR finish_ns >= ?4) AND (?5 = 0 OR finish_ns < ?5) "
          "AND (?6 = 0 OR sequence < ?6) ORDER BY sequence DESC LIMIT ?7");
  st.Text(1, q.part_id)
      .Text(2, q.recipe_id)
      .Int(3, q.verdict)
      .Int(4, q.finished_from_ns)
      .Int(5, q.finished_before_ns)
      .Int(6, q.before_sequence)
      .Int(7, q.limit);
  return ReadResults(st);
}

StatusOr<std::vector<v1::InspectionResult>> SqliteDataStore::ResultsAfter(int64_t after_sequence, int limit) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT result FROM results WHERE sequence > ? ORDER BY sequence LIMIT ?");
  st.Int(1, after_sequence).Int(2, limit);
  return ReadResults(st);
}

StatusOr<int64_t> SqliteDataStore::LastResultSequence() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT COALESCE(MAX(sequence), 0) FROM results");
  if (st.Step() != SQLITE_ROW) return DbError(db_, "LastResultSequence");
  return int64_t(sqlite3_column_int64(st.stmt(), 0));
}

Status SqliteDataStore::SetSetting(const std::string& key, const std::string& value) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "INSERT OR REPLACE INTO settings(key, value) VALUES(?,?)");
  st.Text(1, key).Text(2, value);
  if (st.Step() != SQLITE_DONE) return DbError(db_, "SetSetting");
  return Status::Ok();
}

std::string SqliteDataStore::GetSetting(const std::string& key) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT value FROM settings WHERE key = ?");
  st.Text(1, key);
  return st.Step() == SQLITE_ROW ? st.ColumnText(0) : std::string();
}

namespace {
int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}
}  // namespace

template <typename F>
Status SqliteDataStore::InTransaction(F&& body) {
  INSPECT_RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
  Status s = body();
  if (!s.ok()) {
    Exec("ROLLBACK").IgnoreError();
    return s;
  }
  return Exec("COMMIT");
}

Status SqliteDataStore::WriteJobAndEvent(const v1::Job& job, const v1::JobEvent& event) {
  {
    Stmt st(db_,
            "INSERT OR REPLACE INTO jobs(job_id, kind, state, request_id, create_ns, calibration_id, job) "
            "VALUES(?,?,?,?,?,'',?)");
    st.Text(1, job.job_id()).Int(2, job.kind()).Int(3, job.state()).Text(4, job.request_id()).Int(5, CreateNs(job));
    st.Blob(6, job.SerializeAsString());
    if (st.Step() != SQLITE_DONE) return DbError(db_, "job record");
  }
  Stmt st(db_, "INSERT OR REPLACE INTO events(job_id, sequence, event) VALUES(?,?,?)");
  st.Text(1, event.job_id()).Int(2, int64_t(event.sequence())).Blob(3, event.SerializeAsString());
  if (st.Step() != SQLITE_DONE) return DbError(db_, "job event");
  return Status::Ok();
}

Status SqliteDataStore::EnqueueWork(const v1::Job& job, const v1::JobEvent& queued_event, const QueuedWork& work) {
  std::lock_guard<std::mutex> lock(mu_);
  return InTransaction([&]() -> Status {
    INSPECT_RETURN_IF_ERROR(WriteJobAndEvent(job, queued_event));
    Stmt st(db_, "INSERT INTO work_queue(job_id, enqueue_ns, input, stack_dir) VALUES(?,?,?,?)");
    st.Text(1, job.job_id()).Int(2, NowNs()).Blob(3, work.input).Text(4, work.stack_dir);
    if (st.Step() != SQLITE_DONE) return DbError(db_, "EnqueueWork");
    return Status::Ok();
  });
}

StatusOr<std::optional<QueuedWork>> SqliteDataStore::ClaimWork(const std::string& worker, int64_t lease_ms,
                                                               const std::vector<std::string>& preferred) {
  std::lock_guard<std::mutex> lock(mu_);
  std::optional<QueuedWork> claimed;
  Status status = InTransaction([&]() -> Status {
    const int64_t now = NowNs();
    std::vector<QueuedWork> free;
    {
      Stmt st(db_,
              "SELECT job_id, input, stack_dir, attempts, cancel_requested FROM work_queue "
              "WHERE ended = 0 AND (lease_owner = '' OR lease_expires_ns < ?) ORDER BY enqueue_ns, job_id");
      st.Int(1, now);
      for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
        QueuedWork w;
        w.job_id = st.ColumnText(0);
        w.input = st.ColumnBlob(1);
        w.stack_dir = st.ColumnText(2);
        w.attempts = int(sqlite3_column_int64(st.stmt(), 3));
        w.cancel_requested = sqlite3_column_int64(st.stmt(), 4) != 0;
        free.push_back(std::move(w));
      }
    }
    if (free.empty()) return Status::Ok();
    auto pick = std::find_if(free.begin(), free.end(), [&](const QueuedWork& w) {
      return std::find(preferred.begin(), preferred.end(), w.job_id) != preferred.end();
    });
    QueuedWork w = std::move(pick != free.end() ? *pick : free.front());
    w.attempts += 1;
    {
      Stmt st(db_, "UPDATE work_queue SET lease_owner = ?, lease_expires_ns = ?, attempts = ? WHERE job_id = ?");
      st.Text(1, worker).Int(2, now + lease_ms * 1000000).Int(3, w.attempts).Text(4, w.job_id);
      if (st.Step() != SQLITE_DONE) return DbError(db_, "ClaimWork");
    }
    if (w.attempts > 1) {
      Stmt st(db_, "DELETE FROM artifacts WHERE job_id = ?");
      st.Text(1, w.job_id);
      if (st.Step() != SQLITE_DONE) return DbError(db_, "ClaimWork");
    }
    claimed = std::move(w);
    return Status::Ok();
  });
  INSPECT_RETURN_IF_ERROR(status);
  return claimed;
}

StatusOr<LeaseRenewal> SqliteDataStore::RenewLeases(const std::string& worker, int64_t lease_ms,
                                                    const std::vector<std::string>& running) {
  std::lock_guard<std::mutex> lock(mu_);
  LeaseRenewal out;
  Status status = InTransaction([&]() -> Status {
    for (const std::string& id : running) {
      {
        Stmt st(db_, "UPDATE work_queue SET lease_expires_ns = ? WHERE lease_owner = ? AND ended = 0 AND job_id = ?");
        st.Int(1, NowNs() + lease_ms * 1000000).Text(2, worker).Text(3, id);
        if (st.Step() != SQLITE_DONE) return DbError(db_, "RenewLeases");
      }
      Stmt st(db_, "SELECT cancel_requested FROM work_queue WHERE lease_owner = ? AND ended = 0 AND job_id = ?");
      st.Text(1, worker).Text(2, id);
      if (st.Step() == SQLITE_ROW) {
        out.held.push_back(id);
        if (sqlite3_column_int64(st.stmt(), 0) != 0) out.cancel_requested.push_back(id);
      }
    }
    return Status::Ok();
  });
  INSPECT_RETURN_IF_ERROR(status);
  return out;
}

StatusOr<bool> SqliteDataStore::CompleteWork(const std::string& worker, const v1::Job& ended,
                                             const v1::JobEvent& terminal_event) {
  std::lock_guard<std::mutex> lock(mu_);
  bool held = false;
  Status status = InTransaction([&]() -> Status {
    // Marked ended until the input folder is gone (EndedWork / ForgetWork).
    Stmt st(db_, "UPDATE work_queue SET ended = 1, lease_owner = '' WHERE job_id = ? AND lease_owner = ? AND ended = 0");
    st.Text(1, ended.job_id()).Text(2, worker);
    if (st.Step() != SQLITE_DONE) return DbError(db_, "CompleteWork");
    held = sqlite3_changes(db_) > 0;
    return held ? WriteJobAndEvent(ended, terminal_event) : Status::Ok();
  });
  INSPECT_RETURN_IF_ERROR(status);
  return held;
}

StatusOr<bool> SqliteDataStore::ReleaseWork(const std::string& worker, const v1::Job& queued,
                                            const v1::JobEvent& event) {
  std::lock_guard<std::mutex> lock(mu_);
  bool held = false;
  Status status = InTransaction([&]() -> Status {
    Stmt st(db_,
            "UPDATE work_queue SET lease_owner = '', lease_expires_ns = 0 WHERE job_id = ? AND lease_owner = ? AND ended = 0");
    st.Text(1, queued.job_id()).Text(2, worker);
    if (st.Step() != SQLITE_DONE) return DbError(db_, "ReleaseWork");
    held = sqlite3_changes(db_) > 0;
    return held ? WriteJobAndEvent(queued, event) : Status::Ok();
  });
  INSPECT_RETURN_IF_ERROR(status);
  return held;
}

StatusOr<bool> SqliteDataStore::CancelQueuedWork(const v1::Job& cancelled, const v1::JobEvent& event) {
  std::lock_guard<std::mutex> lock(mu_);
  bool removed = false;
  Status status = InTransaction([&]() -> Status {
    {
      Stmt st(db_,
              "UPDATE work_queue SET ended = 1, lease_owner = '' WHERE job_id = ? AND ended = 0 AND "
              "(lease_owner = '' OR lease_expires_ns < ?)");
      st.Text(1, cancelled.job_id()).Int(2, NowNs());
      if (st.Step() != SQLITE_DONE) return DbError(db_, "CancelQueuedWork");
      removed = sqlite3_changes(db_) > 0;
    }
    if (removed) return WriteJobAndEvent(cancelled, event);
    Stmt st(db_, "UPDATE work_queue SET cancel_requested = 1 WHERE job_id = ? AND ended = 0");
    st.Text(1, cancelled.job_id());
    if (st.Step() != SQLITE_DONE) return DbError(db_, "CancelQueuedWork");
    return Status::Ok();
  });
  INSPECT_RETURN_IF_ERROR(status);
  return removed;
}

StatusOr<int64_t> SqliteDataStore::QueueDepth() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT count(*) FROM work_queue WHERE ended = 0 AND (lease_owner = '' OR lease_expires_ns < ?)");
  st.Int(1, NowNs());
  if (st.Step() != SQLITE_ROW) return DbError(db_, "QueueDepth");
  return int64_t(sqlite3_column_int64(st.stmt(), 0));
}

StatusOr<std::vector<std::string>> SqliteDataStore::QueuedWorkIds() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT job_id FROM work_queue WHERE ended = 0");
  std::vector<std::string> ids;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) ids.push_back(st.ColumnText(0));
  return ids;
}

StatusOr<std::vector<std::string>> SqliteDataStore::WorkInputDirs() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT stack_dir FROM work_queue WHERE stack_dir <> ''");
  std::vector<std::string> dirs;
  int rc = st.Step();
  for (; rc == SQLITE_ROW; rc = st.Step()) dirs.push_back(st.ColumnText(0));
  if (rc != SQLITE_DONE) return DbError(db_, "WorkInputDirs");
  return dirs;
}

StatusOr<std::vector<QueuedWork>> SqliteDataStore::EndedWork() {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT job_id, stack_dir FROM work_queue WHERE ended = 1");
  std::vector<QueuedWork> out;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    QueuedWork w;
    w.job_id = st.ColumnText(0);
    w.stack_dir = st.ColumnText(1);
    out.push_back(std::move(w));
  }
  return out;
}

Status SqliteDataStore::PutStudy(const v1::Study& study) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "INSERT OR REPLACE INTO studies(study_id, recipe_id, finish_ns, study) VALUES(?,?,?,?)");
  st.Text(1, study.study_id())
      .Text(2, study.recipe_id())
      .Int(3, study.finish_time().seconds() * 1000000000LL + study.finish_time().nanos())
      .Blob(4, study.SerializeAsString());
  if (st.Step() != SQLITE_DONE) return DbError(db_, "PutStudy");
  return Status::Ok();
}

StatusOr<v1::Study> SqliteDataStore::GetStudy(const std::string& study_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT study FROM studies WHERE study_id = ?");
  st.Text(1, study_id);
  if (st.Step() != SQLITE_ROW) return Status::NotFound("study_id '" + study_id + "' not found");
  v1::Study s;
  if (!s.ParseFromString(st.ColumnBlob(0))) return Status::DataLoss("study record is corrupt");
  return s;
}

StatusOr<std::vector<v1::Study>> SqliteDataStore::ListStudies(const std::string& recipe_id, int limit) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "SELECT study FROM studies WHERE (?1 = '' OR recipe_id = ?1) ORDER BY finish_ns DESC, study_id LIMIT ?2");
  st.Text(1, recipe_id).Int(2, limit);
  std::vector<v1::Study> out;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    v1::Study s;
    if (!s.ParseFromString(st.ColumnBlob(0))) return Status::DataLoss("study record is corrupt");
    out.push_back(std::move(s));
  }
  return out;
}

Status SqliteDataStore::ForgetWork(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_, "DELETE FROM work_queue WHERE job_id = ? AND ended = 1");
  st.Text(1, job_id);
  if (st.Step() != SQLITE_DONE) return DbError(db_, "ForgetWork");
  return Status::Ok();
}

Status SqliteDataStore::PutVerification(const v1::VerificationRecord& record) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_,
          "INSERT OR REPLACE INTO verifications(verification_id, calibration_id, mode, finish_ns, record) "
          "VALUES(?,?,?,?,?)");
  st.Text(1, record.verification_id())
      .Text(2, record.calibration_id())
      .Int(3, int64_t(record.mode()))
      .Int(4, record.finish_time().seconds() * 1000000000LL + record.finish_time().nanos())
      .Blob(5, record.SerializeAsString());
  if (st.Step() != SQLITE_DONE) return DbError(db_, "PutVerification");
  return Status::Ok();
}

StatusOr<std::vector<v1::VerificationRecord>> SqliteDataStore::ListVerifications(const std::string& calibration_id,
                                                                                 v1::VerificationMode mode, int limit) {
  std::lock_guard<std::mutex> lock(mu_);
  Stmt st(db_,
          "SELECT record FROM verifications WHERE calibration_id = ?1 AND (?2 = 0 OR mode = ?2) "
          "ORDER BY finish_ns DESC, verification_id LIMIT ?3");
  st.Text(1, calibration_id).Int(2, int64_t(mode)).Int(3, limit);
  std::vector<v1::VerificationRecord> out;
  for (int rc = st.Step(); rc == SQLITE_ROW; rc = st.Step()) {
    v1::VerificationRecord r;
    if (!r.ParseFromString(st.ColumnBlob(0))) return Status::DataLoss("verification record is corrupt");
    out.push_back(std::move(r));
  }
  return out;
}

}  // namespace inspection
