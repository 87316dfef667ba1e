// The PostgreSQL backend of DataStore (libpq): the metadata of a reconstruct pool or a site,
// shared by every replica. Records are the same serialised messages the SQLite backend keeps
// (BYTEA), with the columns queries filter on beside them. Statements use parameters (never
// string-built SQL); results come back in binary format.
#include "server/storage/internal/postgres_store.h"

#include <arpa/inet.h>
#include <libpq-fe.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <mutex>
#include <optional>
#include <set>
#include <thread>
#include <vector>

#include <spdlog/spdlog.h>

#include "server/storage/internal/schema.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {

// One statement parameter: text (numbers as decimal strings) or binary (BYTEA).
struct Param {
  std::string value;
  bool binary = false;
};
Param T(const std::string& s) { return {s, false}; }
Param I(int64_t v) { return {std::to_string(v), false}; }
Param B(const std::string& bytes) { return {bytes, true}; }

// Owns a PGresult.
class Result {
 public:
  explicit Result(PGresult* r = nullptr) : r_(r) {}
  Result(Result&& o) noexcept : r_(o.r_) { o.r_ = nullptr; }
  Result& operator=(Result&& o) noexcept {
    std::swap(r_, o.r_);
    return *this;
  }
  ~Result() { PQclear(r_); }
  int rows() const { return PQntuples(r_); }
  std::string Bytes(int row, int col) const {
    return std::string(PQgetvalue(r_, row, col), size_t(PQgetlength(r_, row, col)));
  }
  bool IsNull(int row, int col) const { return PQgetisnull(r_, row, col) != 0; }
  // INTEGER (4 bytes) or BIGINT (8 bytes), network byte order in binary results.
  int64_t Int(int row, int col) const {
    const char* p = PQgetvalue(r_, row, col);
    if (PQgetlength(r_, row, col) == 4) {
      uint32_t v;
      std::memcpy(&v, p, 4);
      return int32_t(ntohl(v));
    }
    uint32_t hi, lo;
    std::memcpy(&hi, p, 4);
    std::memcpy(&lo, p + 4, 4);
    return int64_t((uint64_t(ntohl(hi)) << 32) | ntohl(lo));
  }
  const char* SqlState() const { return PQresultErrorField(r_, PG_DIAG_SQLSTATE); }
  PGresult* get() const { return r_; }

 private:
  PGresult* r_;
};

constexpr const char* kUniqueViolation = "23505";
// Serialises schema migrations across replicas starting at once (any constant of ours).
constexpr int64_t kMigrationLockKey = 0x696e73706563;  // "inspec"

// Type-1 gauge studies: one row per study, the Study message whole; self-contained, so it can
// take another version number.
constexpr const char* kPostgresStudiesMigration = R"sql(
    CREATE TABLE IF NOT EXISTS studies (
      study_id TEXT PRIMARY KEY, recipe_id TEXT NOT NULL, finish_ns BIGINT NOT NULL, study BYTEA NOT NULL);
    CREATE INDEX IF NOT EXISTS studies_by_recipe ON studies(recipe_id, finish_ns);
    )sql";

// Instrument verifications: one row per record, the VerificationRecord message whole, found by
// the calibration it was made under and its mode.
constexpr const char* kPostgresVerificationsMigration = R"sql(
    CREATE TABLE IF NOT EXISTS verifications (
      verification_id TEXT PRIMARY KEY, calibration_id TEXT NOT NULL, mode INTEGER NOT NULL,
      finish_ns BIGINT NOT NULL, record BYTEA NOT NULL);
    CREATE INDEX IF NOT EXISTS verifications_by_calibration ON verifications(calibration_id, mode, finish_ns);
    )sql";

const char* const kPostgresMigrations[] = {
    R"sql(
    CREATE TABLE IF NOT EXISTS jobs (
      job_id TEXT PRIMARY KEY, kind INTEGER NOT NULL, state INTEGER NOT NULL, request_id TEXT NOT NULL,
      create_ns BIGINT NOT NULL, calibration_id TEXT NOT NULL DEFAULT '', job BYTEA NOT NULL);
    CREATE INDEX IF NOT EXISTS jobs_by_time ON jobs(create_ns);
    CREATE INDEX IF NOT EXISTS jobs_by_request ON jobs(kind, request_id);
    CREATE INDEX IF NOT EXISTS jobs_by_state ON jobs(state);
    CREATE TABLE IF NOT EXISTS events (
      job_id TEXT NOT NULL, sequence BIGINT NOT NULL, event BYTEA NOT NULL, PRIMARY KEY(job_id, sequence));
    CREATE TABLE IF NOT EXISTS artifacts (
      artifact_id TEXT PRIMARY KEY, job_id TEXT NOT NULL, path TEXT NOT NULL, artifact BYTEA NOT NULL);
    CREATE INDEX IF NOT EXISTS artifacts_by_job ON artifacts(job_id);
    CREATE TABLE IF NOT EXISTS calibrations (
      calibration_id TEXT PRIMARY KEY, create_ns BIGINT NOT NULL, calibration BYTEA NOT NULL);
    CREATE TABLE IF NOT EXISTS settings (key TEXT PRIMARY KEY, value TEXT NOT NULL);
    CREATE TABLE IF NOT EXISTS pins (job_id TEXT PRIMARY KEY);
    CREATE TABLE IF NOT EXISTS recipes (
      recipe_id TEXT NOT NULL, version INTEGER NOT NULL, deleted INTEGER NOT NULL DEFAULT 0,
      recipe BYTEA NOT NULL, PRIMARY KEY(recipe_id, version));
    CREATE TABLE IF NOT EXISTS results (
      sequence BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY, job_id TEXT NOT NULL UNIQUE,
      part_id TEXT NOT NULL, recipe_id TEXT NOT NULL, verdict INTEGER NOT NULL, finish_ns BIGINT NOT NULL,
      result BYTEA NOT NULL);
    CREATE INDEX IF NOT EXISTS results_by_part ON results(part_id, sequence);
    CREATE INDEX IF NOT EXISTS results_by_recipe ON results(recipe_id, sequence);
    )sql",
    R"sql(
    ALTER TABLE results ADD COLUMN rig_id TEXT NOT NULL DEFAULT '';
    ALTER TABLE results ADD COLUMN rig_sequence BIGINT NOT NULL DEFAULT 0;
    CREATE UNIQUE INDEX results_by_rig ON results(rig_id, rig_sequence) WHERE rig_id <> '';
    )sql",
    // The pool's work queue: one row per reconstruct job not yet ended. lease_owner '' = nobody
    // holds it; a lease past lease_expires_ns (database clock) is free to take again.
    R"sql(
    CREATE TABLE work_queue (
      job_id TEXT PRIMARY KEY, enqueue_ns BIGINT NOT NULL, input BYTEA NOT NULL, stack_dir TEXT NOT NULL,
      lease_owner TEXT NOT NULL DEFAULT '', lease_expires_ns BIGINT NOT NULL DEFAULT 0,
      attempts INTEGER NOT NULL DEFAULT 0, cancel_requested INTEGER NOT NULL DEFAULT 0,
      ended INTEGER NOT NULL DEFAULT 0);
    CREATE INDEX work_queue_by_age ON work_queue(enqueue_ns);
    )sql",
    kPostgresStudiesMigration,
    kPostgresVerificationsMigration,
};

// The database server's clock in nanoseconds: every replica's leases are judged by one clock.
#define INSPECT_PG_NOW_NS "(extract(epoch from clock_timestamp()) * 1000000000)::bigint"

// A text[] literal of job ids for "= ANY($n::text[])".
std::string TextArray(const std::vector<std::string>& ids) {
  std::string out = "{";
  for (size_t i = 0; i < ids.size(); ++i) {
    out += (i ? ",\"" : "\"");
    for (char c : ids[i]) {
      if (c == '"' || c == '\\') out += '\\';
      out += c;
    }
    out += '"';
  }
  return out + "}";
}
static_assert(std::size(kPostgresMigrations) == kStoreSchemaVersion, "one migration per schema version");

// libpq's messages end in a newline and continue on tab-indented lines: one line for logs.
std::string OneLine(std::string m) {
  while (!m.empty() && (m.back() == '\n' || m.back() == ' ')) m.pop_back();
  for (size_t i = m.find("\n"); i != std::string::npos; i = m.find("\n", i)) m.replace(i, 1, "; ");
  for (size_t i = m.find("\t"); i != std::string::npos; i = m.find("\t", i)) m.erase(i, 1);
  return m;
}

int64_t CreateNs(const v1::Job& job) { return job.create_time().seconds() * 1000000000LL + job.create_time().nanos(); }

template <typename M>
Status ParseRows(const Result& r, int col, std::vector<M>* out, const char* what) {
  for (int i = 0; i < r.rows(); ++i) {
    M m;
    if (!m.ParseFromString(r.Bytes(i, col))) return Status::DataLoss(std::string("a stored ") + what + " is corrupt");
    out->push_back(std::move(m));
  }
  return Status::Ok();
}

// Channels of the pool's notifications (payload: the job id).
constexpr char kWorkChannel[] = "inspectd_work";
constexpr char kJobChannel[] = "inspectd_job";

// One connection that LISTENs on both channels, on a thread of its own, handing each
// notification to the listener. Reconnects (once a second) after the server went away; what was
// notified meanwhile is lost, which the waiters' polling covers. The thread sleeps in poll() on
// the connection's socket and an eventfd the destructor signals, so closing a store (every pool
// replica's shutdown) returns at once instead of waiting out a poll timeout.
class NotificationListener {
 public:
  using Connect = std::function<PGconn*()>;
  NotificationListener(Connect connect, DataStore::ChangeListener listener)
      : connect_(std::move(connect)),
        listener_(std::move(listener)),
        wake_fd_(eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK)),
        thread_([this] { Run(); }) {
    if (wake_fd_ < 0) spdlog::warn("database: eventfd failed ({}): closing the store waits out a 200 ms poll", errno);
  }
  ~NotificationListener() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    if (wake_fd_ >= 0) {
      const uint64_t one = 1;
      [[maybe_unused]] const ssize_t n = write(wake_fd_, &one, sizeof(one));  // cannot fail short of overflow
    }
    thread_.join();
    if (wake_fd_ >= 0) close(wake_fd_);
  }

 private:
  void Run() {
    PGconn* conn = nullptr;
    for (;;) {
      {
        std::lock_guard<std::mutex> lock(mu_);
        if (stop_) break;
      }
      if (!conn) {
        conn = connect_();
        if (conn && !ListenOn(conn)) {
          PQfinish(conn);
          conn = nullptr;
        }
        if (!conn) {
          std::unique_lock<std::mutex> lock(mu_);
          cv_.wait_for(lock, std::chrono::seconds(1), [&] { return stop_; });
          continue;
        }
      }
      // Wakes at a notification or when the store is closing (the eventfd); the 200 ms timeout
      // only matters when there is no eventfd.
      pollfd fds[2] = {{PQsocket(conn), POLLIN, 0}, {wake_fd_, POLLIN, 0}};
      const nfds_t nfds = wake_fd_ >= 0 ? 2 : 1;
      if (poll(fds, nfds, 200) < 0 && errno != EINTR) fds[0].revents = POLLERR;
      if (fds[1].revents != 0) continue;  // stop_ is set: the loop's check ends it
      pollfd& fd = fds[0];
      if (fd.revents != 0 && PQconsumeInput(conn) == 0) {
        spdlog::debug("database: the notification connection broke: {}", OneLine(PQerrorMessage(conn)));
        PQfinish(conn);
        conn = nullptr;
        continue;
      }
      while (PGnotify* n = PQnotifies(conn)) {
        const DataStore::Change change =
            std::strcmp(n->relname, kWorkChannel) == 0 ? DataStore::Change::kWorkQueued : DataStore::Change::kJobChanged;
        listener_(change, n->extra ? std::string(n->extra) : std::string());
        PQfreemem(n);
      }
    }
    if (conn) PQfinish(conn);
  }
  static bool ListenOn(PGconn* conn) {
    const std::string sql = std::string("LISTEN ") + kWorkChannel + "; LISTEN " + kJobChannel;
    PGresult* r = PQexec(conn, sql.c_str());
    const bool ok = r && PQresultStatus(r) == PGRES_COMMAND_OK;
    if (!ok) spdlog::debug("database: LISTEN failed: {}", OneLine(PQerrorMessage(conn)));
    PQclear(r);
    return ok;
  }

  const Connect connect_;
  const DataStore::ChangeListener listener_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  const int wake_fd_;   // eventfd: written once by the destructor; -1 when eventfd failed
  std::thread thread_;  // last: started once the members it reads exist
};

class PostgresDataStore final : public DataStore {
 public:
  PostgresDataStore(fs::path dir, PGconn* conn, std::function<PGconn*()> connect)
      : DataStore(std::move(dir)), conn_(conn), connect_(std::move(connect)) {}
  ~PostgresDataStore() override {
    ListenForChanges(nullptr);
    PQfinish(conn_);
  }
  const char* backend() const override { return "postgresql"; }
  bool shared() const override { return true; }
  void ListenForChanges(ChangeListener listener) override {
    std::lock_guard<std::mutex> lock(listener_mu_);
    listener_.reset();  // joins its thread: no call runs after this
    if (listener) listener_ = std::make_unique<NotificationListener>(connect_, std::move(listener));
  }
  Status Migrate();

  Status PutJob(const v1::Job& job) override;
  StatusOr<v1::Job> GetJob(const std::string& job_id) override;
  std::optional<std::string> FindJobByRequestId(v1::JobKind kind, const std::string& request_id) override;
  StatusOr<std::vector<v1::Job>> ListJobs(v1::JobKind kind, v1::JobState state, int limit,
                                          int64_t before_create_ns) override;
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
  StatusOr<std::vector<StoredArtifact>> DeleteArtifactsOfKind(const std::string& job_id,
                                                              v1::ArtifactKind kind) override;
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
  // The job row and one event, inside the caller's transaction (caller holds mu_).
  Status WriteJobAndEvent(const v1::Job& job, const v1::JobEvent& event, const char* what);
  // Runs one statement; `error` is set (and the result empty) on failure. A connection found
  // broken outside a transaction is reset once and the statement retried: the server may have
  // restarted. Still broken: UNAVAILABLE.
  Result Run(const char* sql, const std::vector<Param>& params, Status* error, const char* what,
             bool script = false);
  // Runs a script of statements without parameters (migrations, BEGIN / COMMIT).
  Status Exec(const char* sql, const char* what) {
    Status s;
    Run(sql, {}, &s, what, /*script=*/true);
    return s;
  }
  // Runs `body` between BEGIN and COMMIT (ROLLBACK when it fails).
  template <typename F>
  Status InTransaction(const char* what, F&& body);

  std::mutex mu_;  // guards conn_ and in_transaction_: one connection, one statement at a time
  PGconn* conn_;
  bool in_transaction_ = false;
  const std::function<PGconn*()> connect_;  // a new connection like conn_ (nullptr: cannot)
  std::mutex listener_mu_;
  std::unique_ptr<NotificationListener> listener_;
};

Result PostgresDataStore::Run(const char* sql, const std::vector<Param>& params, Status* error, const char* what,
                              bool script) {
  std::vector<const char*> values;
  std::vector<int> lengths, formats;
  for (const Param& p : params) {
    values.push_back(p.value.data());
    lengths.push_back(int(p.value.size()));
    formats.push_back(p.binary ? 1 : 0);
  }
  for (int attempt = 0; attempt < 2; ++attempt) {
    // A script may hold several statements, which only PQexec runs (its results are text).
    Result r(script ? PQexec(conn_, sql)
                    : PQexecParams(conn_, sql, int(params.size()), nullptr, values.data(), lengths.data(),
                                   formats.data(), /*resultFormat=*/1));
    const ExecStatusType st = r.get() ? PQresultStatus(r.get()) : PGRES_FATAL_ERROR;
    if (st == PGRES_COMMAND_OK || st == PGRES_TUPLES_OK) {
      *error = Status::Ok();
      return r;
    }
    if (PQstatus(conn_) == CONNECTION_BAD) {
      if (attempt == 0 && !in_transaction_) {
        PQreset(conn_);
        if (PQstatus(conn_) == CONNECTION_OK) continue;
      }
      in_transaction_ = false;
      *error = Status::Unavailable(std::string("database: connection lost during ") + what + ": " +
                                   OneLine(PQerrorMessage(conn_)));
      return Result();
    }
    const char* state = r.get() ? r.SqlState() : nullptr;
    const std::string message = OneLine(r.get() ? PQresultErrorMessage(r.get()) : PQerrorMessage(conn_));
    *error = (state && std::strcmp(state, kUniqueViolation) == 0)
                 ? Status::AlreadyExists(std::string("database: ") + what + ": " + message)
                 : Status::Internal(std::string("database: ") + what + ": " + message);
    return r;  // kept for SqlState()
  }
  return Result();
}

template <typename F>
Status PostgresDataStore::InTransaction(const char* what, F&& body) {
  INSPECT_RETURN_IF_ERROR(Exec("BEGIN", what));
  in_transaction_ = true;
  Status s = body();
  if (s.ok()) s = Exec("COMMIT", what);
  if (!s.ok() && in_transaction_) (void)Exec("ROLLBACK", what);
  in_transaction_ = false;
  return s;
}

Status PostgresDataStore::Migrate() {
  std::lock_guard<std::mutex> lock(mu_);
  return InTransaction("schema migration", [&]() -> Status {
    Status s;
    Run("SELECT pg_advisory_xact_lock($1)", {I(kMigrationLockKey)}, &s, "schema lock");
    INSPECT_RETURN_IF_ERROR(s);
    INSPECT_RETURN_IF_ERROR(
        Exec("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)", "schema_version"));
    Result r = Run("SELECT COALESCE(MAX(version), 0)::bigint FROM schema_version", {}, &s, "schema version");
    INSPECT_RETURN_IF_ERROR(s);
    const int64_t stored = r.Int(0, 0);
    INSPECT_RETURN_IF_ERROR(CheckSchemaVersion(stored, "(PostgreSQL)"));
    for (int64_t v = stored; v < kStoreSchemaVersion; ++v) {
      INSPECT_RETURN_IF_ERROR(Exec(kPostgresMigrations[v], "schema migration"));
      Run("INSERT INTO schema_version(version) VALUES($1)", {I(v + 1)}, &s, "schema version");
      INSPECT_RETURN_IF_ERROR(s);
    }
    return Status::Ok();
  });
}

Status PostgresDataStore::PutJob(const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("INSERT INTO jobs(job_id, kind, state, request_id, create_ns, calibration_id, job) "
      "VALUES($1,$2,$3,$4,$5,$6,$7) ON CONFLICT (job_id) DO UPDATE SET kind = EXCLUDED.kind, "
      "state = EXCLUDED.state, request_id = EXCLUDED.request_id, create_ns = EXCLUDED.create_ns, "
      "calibration_id = EXCLUDED.calibration_id, job = EXCLUDED.job",
      {T(job.job_id()), I(job.kind()), I(job.state()), T(job.request_id()), I(CreateNs(job)),
       T(job.kind() == v1::JOB_KIND_SCAN ? job.result().calibration_id() : std::string()),
       B(job.SerializeAsString())},
      &s, "PutJob");
  return s;
}

StatusOr<v1::Job> PostgresDataStore::GetJob(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job FROM jobs WHERE job_id = $1", {T(job_id)}, &s, "GetJob");
  INSPECT_RETURN_IF_ERROR(s);
  if (r.rows() == 0) return Status::NotFound("job_id '" + job_id + "' not found");
  v1::Job job;
  if (!job.ParseFromString(r.Bytes(0, 0))) return Status::DataLoss("job " + job_id + " record is corrupt");
  return job;
}

std::optional<std::string> PostgresDataStore::FindJobByRequestId(v1::JobKind kind, const std::string& request_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job_id FROM jobs WHERE kind = $1 AND request_id = $2 ORDER BY create_ns LIMIT 1",
                 {I(kind), T(request_id)}, &s, "FindJobByRequestId");
  if (!s.ok() || r.rows() == 0) return std::nullopt;
  return r.Bytes(0, 0);
}

StatusOr<std::vector<v1::Job>> PostgresDataStore::ListJobs(v1::JobKind kind, v1::JobState state, int limit,
                                                           int64_t before_create_ns) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job FROM jobs WHERE ($1 = 0 OR kind = $1) AND ($2 = 0 OR state = $2) AND "
                 "($3::bigint = 0 OR create_ns < $3::bigint) ORDER BY create_ns DESC LIMIT $4",
                 {I(kind), I(state), I(before_create_ns), I(limit)}, &s, "ListJobs");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::Job> jobs;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &jobs, "job"));
  return jobs;
}

StatusOr<std::vector<v1::Job>> PostgresDataStore::UnfinishedJobs() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job FROM jobs WHERE state IN ($1, $2)", {I(v1::JOB_STATE_QUEUED), I(v1::JOB_STATE_RUNNING)},
                 &s, "UnfinishedJobs");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::Job> jobs;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &jobs, "job"));
  return jobs;
}

Status PostgresDataStore::AppendEvent(const v1::JobEvent& event) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("INSERT INTO events(job_id, sequence, event) VALUES($1,$2,$3) "
      "ON CONFLICT (job_id, sequence) DO UPDATE SET event = EXCLUDED.event",
      {T(event.job_id()), I(int64_t(event.sequence())), B(event.SerializeAsString())}, &s, "AppendEvent");
  return s;
}

Status PostgresDataStore::AppendEvents(const std::vector<v1::JobEvent>& events) {
  std::lock_guard<std::mutex> lock(mu_);
  // One statement per batch of up to 200 rows: one round trip however many progress events came.
  constexpr size_t kRows = 200;
  for (size_t begin = 0; begin < events.size(); begin += kRows) {
    const size_t end = std::min(events.size(), begin + kRows);
    std::string sql = "INSERT INTO events(job_id, sequence, event) VALUES";
    std::vector<Param> params;
    for (size_t i = begin; i < end; ++i) {
      const size_t n = params.size();
      sql += (i > begin ? ",(" : "(");
      sql += "$" + std::to_string(n + 1) + "::text,$" + std::to_string(n + 2) + "::bigint,$" + std::to_string(n + 3) +
             "::bytea)";
      params.push_back(T(events[i].job_id()));
      params.push_back(I(int64_t(events[i].sequence())));
      params.push_back(B(events[i].SerializeAsString()));
    }
    // Watchers of these jobs on other replicas read them at once instead of at their next poll.
    sql = "WITH i AS (" + sql +
          " ON CONFLICT (job_id, sequence) DO UPDATE SET event = EXCLUDED.event RETURNING job_id) "
          "SELECT pg_notify('inspectd_job', job_id) FROM (SELECT DISTINCT job_id FROM i) d";
    Status s;
    Run(sql.c_str(), params, &s, "AppendEvents");
    INSPECT_RETURN_IF_ERROR(s);
  }
  return Status::Ok();
}

StatusOr<std::vector<v1::JobEvent>> PostgresDataStore::Events(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT event FROM events WHERE job_id = $1 ORDER BY sequence", {T(job_id)}, &s, "Events");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::JobEvent> events;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &events, "job event"));
  return events;
}

Status PostgresDataStore::PutArtifact(const StoredArtifact& a) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("INSERT INTO artifacts(artifact_id, job_id, path, artifact) VALUES($1,$2,$3,$4) "
      "ON CONFLICT (artifact_id) DO UPDATE SET job_id = EXCLUDED.job_id, path = EXCLUDED.path, "
      "artifact = EXCLUDED.artifact",
      {T(a.artifact.artifact_id()), T(a.job_id), T(a.path.string()), B(a.artifact.SerializeAsString())}, &s,
      "PutArtifact");
  return s;
}

StatusOr<StoredArtifact> PostgresDataStore::GetArtifact(const std::string& artifact_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job_id, path, artifact FROM artifacts WHERE artifact_id = $1", {T(artifact_id)}, &s,
                 "GetArtifact");
  INSPECT_RETURN_IF_ERROR(s);
  if (r.rows() == 0) return Status::NotFound("artifact_id '" + artifact_id + "' not found");
  StoredArtifact a;
  a.job_id = r.Bytes(0, 0);
  a.path = r.Bytes(0, 1);
  if (!a.artifact.ParseFromString(r.Bytes(0, 2))) return Status::DataLoss("artifact record is corrupt");
  return a;
}

Status PostgresDataStore::PutCalibration(const v1::Calibration& c) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("INSERT INTO calibrations(calibration_id, create_ns, calibration) VALUES($1,$2,$3) "
      "ON CONFLICT (calibration_id) DO UPDATE SET create_ns = EXCLUDED.create_ns, calibration = EXCLUDED.calibration",
      {T(c.calibration_id()), I(c.create_time().seconds() * 1000000000LL + c.create_time().nanos()),
       B(c.SerializeAsString())},
      &s, "PutCalibration");
  return s;
}

StatusOr<v1::Calibration> PostgresDataStore::GetCalibration(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT calibration FROM calibrations WHERE calibration_id = $1", {T(id)}, &s, "GetCalibration");
  INSPECT_RETURN_IF_ERROR(s);
  if (r.rows() == 0) return Status::NotFound("calibration_id '" + id + "' not found");
  v1::Calibration c;
  if (!c.ParseFromString(r.Bytes(0, 0))) return Status::DataLoss("calibration record is corrupt");
  return c;
}

StatusOr<std::vector<v1::Calibration>> PostgresDataStore::ListCalibrations() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT calibration FROM calibrations ORDER BY create_ns DESC", {}, &s, "ListCalibrations");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::Calibration> out;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &out, "calibration"));
  return out;
}

Status PostgresDataStore::SetPinned(const std::string& job_id, bool pinned) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run(pinned ? "INSERT INTO pins(job_id) VALUES($1) ON CONFLICT DO NOTHING" : "DELETE FROM pins WHERE job_id = $1",
      {T(job_id)}, &s, "SetPinned");
  return s;
}

StatusOr<std::vector<std::string>> PostgresDataStore::PinnedJobs() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job_id FROM pins", {}, &s, "PinnedJobs");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<std::string> ids;
  for (int i = 0; i < r.rows(); ++i) ids.push_back(r.Bytes(i, 0));
  return ids;
}

StatusOr<std::vector<v1::Job>> PostgresDataStore::FinishedJobs() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job FROM jobs WHERE state IN ($1, $2, $3)",
                 {I(v1::JOB_STATE_SUCCEEDED), I(v1::JOB_STATE_FAILED), I(v1::JOB_STATE_CANCELLED)}, &s,
                 "FinishedJobs");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::Job> jobs;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &jobs, "job"));
  return jobs;
}

Status PostgresDataStore::DeleteJobRecords(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  return InTransaction("DeleteJobRecords", [&]() -> Status {
    for (const char* sql : {"DELETE FROM artifacts WHERE job_id = $1", "DELETE FROM events WHERE job_id = $1",
                            "DELETE FROM pins WHERE job_id = $1", "DELETE FROM jobs WHERE job_id = $1"}) {
      Status s;
      Run(sql, {T(job_id)}, &s, "DeleteJobRecords");
      INSPECT_RETURN_IF_ERROR(s);
    }
    return Status::Ok();
  });
}

StatusOr<std::vector<StoredArtifact>> PostgresDataStore::DeleteArtifactsOfKind(const std::string& job_id,
                                                                               v1::ArtifactKind kind) {
  std::lock_guard<std::mutex> lock(mu_);
  std::vector<StoredArtifact> removed;
  Status status = InTransaction("DeleteArtifactsOfKind", [&]() -> Status {
    Status s;
    // FOR UPDATE: another replica rewriting the job between read and write would lose an edit.
    Result jr = Run("SELECT job FROM jobs WHERE job_id = $1 FOR UPDATE", {T(job_id)}, &s, "DeleteArtifactsOfKind");
    INSPECT_RETURN_IF_ERROR(s);
    if (jr.rows() == 0) return Status::NotFound("job_id '" + job_id + "' not found");
    v1::Job job;
    if (!job.ParseFromString(jr.Bytes(0, 0))) return Status::DataLoss("job " + job_id + " record is corrupt");
    Result ar = Run("SELECT path, artifact FROM artifacts WHERE job_id = $1", {T(job_id)}, &s, "DeleteArtifactsOfKind");
    INSPECT_RETURN_IF_ERROR(s);
    for (int i = 0; i < ar.rows(); ++i) {
      StoredArtifact a;
      a.job_id = job_id;
      a.path = ar.Bytes(i, 0);
      if (a.artifact.ParseFromString(ar.Bytes(i, 1)) && a.artifact.kind() == kind) removed.push_back(std::move(a));
    }
    auto* artifacts = job.mutable_result()->mutable_artifacts();
    artifacts->erase(std::remove_if(artifacts->begin(), artifacts->end(),
                                    [&](const v1::Artifact& a) { return a.kind() == kind; }),
                     artifacts->end());
    for (const StoredArtifact& a : removed) {
      Run("DELETE FROM artifacts WHERE artifact_id = $1", {T(a.artifact.artifact_id())}, &s, "DeleteArtifactsOfKind");
      INSPECT_RETURN_IF_ERROR(s);
    }
    Run("UPDATE jobs SET job = $1 WHERE job_id = $2", {B(job.SerializeAsString()), T(job_id)}, &s,
        "DeleteArtifactsOfKind");
    return s;
  });
  INSPECT_RETURN_IF_ERROR(status);
  return removed;
}

StatusOr<v1::Recipe> PostgresDataStore::StoreRecipe(v1::Recipe recipe, bool create, int expected_version) {
  std::lock_guard<std::mutex> lock(mu_);
  const std::string id = recipe.recipe_id();
  Status status = InTransaction("StoreRecipe", [&]() -> Status {
    Status s;
    // One writer per recipe id across replicas: the transaction-scoped lock on the id's hash.
    Run("SELECT pg_advisory_xact_lock(hashtextextended($1, 0))", {T(id)}, &s, "StoreRecipe");
    INSPECT_RETURN_IF_ERROR(s);
    Result q = Run("SELECT COALESCE(MAX(version), 0)::bigint, MAX(CASE WHEN deleted = 0 THEN version END)::bigint "
                   "FROM recipes WHERE recipe_id = $1",
                   {T(id)}, &s, "StoreRecipe");
    INSPECT_RETURN_IF_ERROR(s);
    const int64_t highest = q.Int(0, 0);
    const bool in_use = !q.IsNull(0, 1);
    const int64_t current = in_use ? q.Int(0, 1) : 0;
    if (create && in_use) {
      return Status(StatusCode::kAlreadyExists, "recipe_id '" + id + "' exists (version " + std::to_string(current) +
                                                    "); UpdateRecipe makes a new version");
    }
    if (!create && !in_use) return Status::NotFound("recipe_id '" + id + "' not found");
    if (!create && expected_version > 0 && expected_version != current) {
      return Status::Aborted("recipe '" + id + "' is at version " + std::to_string(current) +
                             ", not expected_version " + std::to_string(expected_version) + " (updated meanwhile)");
    }
    recipe.set_version(int32_t(highest + 1));
    Run("INSERT INTO recipes(recipe_id, version, deleted, recipe) VALUES($1,$2,0,$3)",
        {T(id), I(recipe.version()), B(recipe.SerializeAsString())}, &s, "StoreRecipe");
    return s;
  });
  INSPECT_RETURN_IF_ERROR(status);
  return recipe;
}

StatusOr<v1::Recipe> PostgresDataStore::GetRecipe(const std::string& recipe_id, int version) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  // A hidden recipe's versions stay readable by version for the results that ran them.
  Result r = version > 0 ? Run("SELECT recipe FROM recipes WHERE recipe_id = $1 AND version = $2",
                               {T(recipe_id), I(version)}, &s, "GetRecipe")
                         : Run("SELECT recipe FROM recipes WHERE recipe_id = $1 AND deleted = 0 "
                               "ORDER BY version DESC LIMIT 1",
                               {T(recipe_id)}, &s, "GetRecipe");
  INSPECT_RETURN_IF_ERROR(s);
  if (r.rows() == 0) {
    return Status::NotFound("recipe_id '" + recipe_id + "'" +
                            (version > 0 ? " version " + std::to_string(version) : std::string()) + " not found");
  }
  v1::Recipe recipe;
  if (!recipe.ParseFromString(r.Bytes(0, 0))) return Status::DataLoss("recipe " + recipe_id + " record is corrupt");
  return recipe;
}

StatusOr<std::vector<v1::Recipe>> PostgresDataStore::ListRecipes() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT recipe FROM recipes r WHERE deleted = 0 AND version = "
                 "(SELECT MAX(version) FROM recipes WHERE recipe_id = r.recipe_id) ORDER BY recipe_id",
                 {}, &s, "ListRecipes");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::Recipe> out;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &out, "recipe"));
  return out;
}

StatusOr<int> PostgresDataStore::DeleteRecipe(const std::string& recipe_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("UPDATE recipes SET deleted = 1 WHERE recipe_id = $1 AND deleted = 0", {T(recipe_id)}, &s,
                 "DeleteRecipe");
  INSPECT_RETURN_IF_ERROR(s);
  const int n = std::atoi(PQcmdTuples(r.get()));
  if (n == 0) return Status::NotFound("recipe_id '" + recipe_id + "' not found");
  return n;
}

StatusOr<v1::InspectionResult> PostgresDataStore::AppendResult(v1::InspectionResult result) {
  std::lock_guard<std::mutex> lock(mu_);
  const auto& t = result.finish_time();
  // An identity column: a deleted row's number is never handed out again. The record carries its
  // own number, set in the same transaction.
  Status status = InTransaction("AppendResult", [&]() -> Status {
    Status s;
    Result r = Run("INSERT INTO results(job_id, part_id, recipe_id, verdict, finish_ns, result) "
                   "VALUES($1,$2,$3,$4,$5,'') RETURNING sequence",
                   {T(result.job_id()), T(result.part_id()), T(result.recipe_id()), I(result.verdict()),
                    I(t.seconds() * 1000000000LL + t.nanos())},
                   &s, "AppendResult");
    if (s.code() == StatusCode::kAlreadyExists) {
      return Status::AlreadyExists("job " + result.job_id() + " already has a result");
    }
    INSPECT_RETURN_IF_ERROR(s);
    result.set_sequence(r.Int(0, 0));
    Run("UPDATE results SET result = $1 WHERE sequence = $2", {B(result.SerializeAsString()), I(result.sequence())},
        &s, "AppendResult");
    return s;
  });
  INSPECT_RETURN_IF_ERROR(status);
  return result;
}

StatusOr<v1::InspectionResult> PostgresDataStore::ImportResult(v1::InspectionResult result) {
  if (result.rig_id().empty() || result.rig_sequence() <= 0) {
    return Status::InvalidArgument("a forwarded result needs rig_id and rig_sequence");
  }
  std::lock_guard<std::mutex> lock(mu_);
  const auto& t = result.finish_time();
  bool duplicate = false;
  Status status = InTransaction("ImportResult", [&]() -> Status {
    Status s;
    // ON CONFLICT DO NOTHING on the rig's (id, number): a retried forward stores nothing.
    Result r = Run("INSERT INTO results(job_id, part_id, recipe_id, verdict, finish_ns, result, rig_id, rig_sequence) "
                   "VALUES($1,$2,$3,$4,$5,'',$6,$7) ON CONFLICT (rig_id, rig_sequence) WHERE rig_id <> '' "
                   "DO NOTHING RETURNING sequence",
                   {T(result.job_id()), T(result.part_id()), T(result.recipe_id()), I(result.verdict()),
                    I(t.seconds() * 1000000000LL + t.nanos()), T(result.rig_id()), I(result.rig_sequence())},
                   &s, "ImportResult");
    INSPECT_RETURN_IF_ERROR(s);
    if (r.rows() == 0) {
      duplicate = true;
      Result q = Run("SELECT result FROM results WHERE rig_id = $1 AND rig_sequence = $2",
                     {T(result.rig_id()), I(result.rig_sequence())}, &s, "ImportResult");
      INSPECT_RETURN_IF_ERROR(s);
      if (q.rows() == 0 || !result.ParseFromString(q.Bytes(0, 0))) {
        return Status::DataLoss("a forwarded inspection result record is corrupt");
      }
      return Status::Ok();
    }
    result.set_sequence(r.Int(0, 0));
    Run("UPDATE results SET result = $1 WHERE sequence = $2", {B(result.SerializeAsString()), I(result.sequence())},
        &s, "ImportResult");
    return s;
  });
  INSPECT_RETURN_IF_ERROR(status);
  (void)duplicate;
  return result;
}

StatusOr<std::vector<v1::InspectionResult>> PostgresDataStore::ListResults(const ResultQuery& q) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT result FROM results WHERE ($1 = '' OR part_id = $1) AND ($2 = '' OR recipe_id = $2) "
                 "AND ($3 = 0 OR verdict = $3) AND ($4::bigint = 0 OR finish_ns >= $4::bigint) "
                 "AND ($5::bigint = 0 OR finish_ns < $5::bigint) AND ($6::bigint = 0 OR sequence < $6::bigint) "
                 "ORDER BY sequence DESC LIMIT $7",
                 {T(q.part_id), T(q.recipe_id), I(q.verdict), I(q.finished_from_ns), I(q.finished_before_ns),
                  I(q.before_sequence), I(q.limit)},
                 &s, "ListResults");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::InspectionResult> out;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &out, "inspection result"));
  return out;
}

StatusOr<std::vector<v1::InspectionResult>> PostgresDataStore::ResultsAfter(int64_t after_sequence, int limit) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT result FROM results WHERE sequence > $1 ORDER BY sequence LIMIT $2", {I(after_sequence), I(limit)},
                 &s, "ResultsAfter");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::InspectionResult> out;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &out, "inspection result"));
  return out;
}

StatusOr<int64_t> PostgresDataStore::LastResultSequence() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT COALESCE(MAX(sequence), 0)::bigint FROM results", {}, &s, "LastResultSequence");
  INSPECT_RETURN_IF_ERROR(s);
  return r.Int(0, 0);
}

Status PostgresDataStore::SetSetting(const std::string& key, const std::string& value) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("INSERT INTO settings(key, value) VALUES($1,$2) ON CONFLICT (key) DO UPDATE SET value = EXCLUDED.value",
      {T(key), T(value)}, &s, "SetSetting");
  return s;
}

std::string PostgresDataStore::GetSetting(const std::string& key) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT value FROM settings WHERE key = $1", {T(key)}, &s, "GetSetting");
  return s.ok() && r.rows() > 0 ? r.Bytes(0, 0) : std::string();
}

Status PostgresDataStore::WriteJobAndEvent(const v1::Job& job, const v1::JobEvent& event, const char* what) {
  Status s;
  Run("INSERT INTO jobs(job_id, kind, state, request_id, create_ns, calibration_id, job) "
      "VALUES($1,$2,$3,$4,$5,'',$6) ON CONFLICT (job_id) DO UPDATE SET kind = EXCLUDED.kind, "
      "state = EXCLUDED.state, request_id = EXCLUDED.request_id, create_ns = EXCLUDED.create_ns, job = EXCLUDED.job",
      {T(job.job_id()), I(job.kind()), I(job.state()), T(job.request_id()), I(CreateNs(job)),
       B(job.SerializeAsString())},
      &s, what);
  INSPECT_RETURN_IF_ERROR(s);
  Run("INSERT INTO events(job_id, sequence, event) VALUES($1,$2,$3) "
      "ON CONFLICT (job_id, sequence) DO UPDATE SET event = EXCLUDED.event",
      {T(event.job_id()), I(int64_t(event.sequence())), B(event.SerializeAsString())}, &s, what);
  return s;
}

// The job's rows written together are one statement (data-modifying WITH): atomic as a
// transaction, in one round trip instead of BEGIN, three statements and COMMIT. A reconstruct's
// latency on a loaded host is mostly such round trips.
#define INSPECT_PG_UPSERT_JOB(select)                                                                        \
  "INSERT INTO jobs(job_id, kind, state, request_id, create_ns, calibration_id, job) " select               \
  " ON CONFLICT (job_id) DO UPDATE SET kind = EXCLUDED.kind, state = EXCLUDED.state, "                      \
  "request_id = EXCLUDED.request_id, create_ns = EXCLUDED.create_ns, job = EXCLUDED.job"
#define INSPECT_PG_UPSERT_EVENT(select) \
  "INSERT INTO events(job_id, sequence, event) " select " ON CONFLICT (job_id, sequence) DO UPDATE SET event = EXCLUDED.event"

Status PostgresDataStore::EnqueueWork(const v1::Job& job, const v1::JobEvent& queued_event, const QueuedWork& work) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("WITH j AS (" INSPECT_PG_UPSERT_JOB("SELECT $1::text, $2::integer, $3::integer, $4::text, $5::bigint, '', $6::bytea")
      "), e AS (" INSPECT_PG_UPSERT_EVENT("SELECT $1::text, $7::bigint, $8::bytea")
      "), w AS (INSERT INTO work_queue(job_id, enqueue_ns, input, stack_dir) VALUES($1::text, " INSPECT_PG_NOW_NS
      ", $9::bytea, $10::text) RETURNING job_id) SELECT pg_notify('inspectd_work', job_id) FROM w",
      {T(job.job_id()), I(job.kind()), I(job.state()), T(job.request_id()), I(CreateNs(job)), B(job.SerializeAsString()),
       I(int64_t(queued_event.sequence())), B(queued_event.SerializeAsString()), B(work.input), T(work.stack_dir)},
      &s, "EnqueueWork");
  // Job ids are random: a queue row with this one is this call's own, written before the answer
  // was lost and the statement retried on a fresh connection.
  if (s.code() == StatusCode::kAlreadyExists) return Status::Ok();
  return s;
}

StatusOr<std::optional<QueuedWork>> PostgresDataStore::ClaimWork(const std::string& worker, int64_t lease_ms,
                                                                 const std::vector<std::string>& preferred) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  // SKIP LOCKED: a row another worker is taking right now is passed over, not waited for. A rerun
  // (attempts > 1) loses, in the same statement, the artifact rows an earlier attempt recorded
  // before its worker died: the rerun's are the job's only ones.
  Result r = Run("WITH c AS (UPDATE work_queue SET lease_owner = $1, lease_expires_ns = " INSPECT_PG_NOW_NS
                 " + $2::bigint, attempts = attempts + 1 WHERE job_id = (SELECT job_id FROM work_queue "
                 "WHERE ended = 0 AND (lease_owner = '' OR lease_expires_ns < " INSPECT_PG_NOW_NS ") "
                 "ORDER BY (job_id = ANY($3::text[])) DESC, enqueue_ns, job_id LIMIT 1 FOR UPDATE SKIP LOCKED) "
                 "RETURNING job_id, input, stack_dir, attempts, cancel_requested), "
                 "d AS (DELETE FROM artifacts WHERE job_id IN (SELECT job_id FROM c WHERE attempts > 1)) "
                 "SELECT job_id, input, stack_dir, attempts, cancel_requested FROM c",
                 {T(worker), I(lease_ms * 1000000), T(TextArray(preferred))}, &s, "ClaimWork");
  INSPECT_RETURN_IF_ERROR(s);
  if (r.rows() == 0) return std::optional<QueuedWork>();
  QueuedWork w;
  w.job_id = r.Bytes(0, 0);
  w.input = r.Bytes(0, 1);
  w.stack_dir = r.Bytes(0, 2);
  w.attempts = int(r.Int(0, 3));
  w.cancel_requested = r.Int(0, 4) != 0;
  return std::optional<QueuedWork>(std::move(w));
}

StatusOr<LeaseRenewal> PostgresDataStore::RenewLeases(const std::string& worker, int64_t lease_ms,
                                                      const std::vector<std::string>& running) {
  std::lock_guard<std::mutex> lock(mu_);
  if (running.empty()) return LeaseRenewal{};
  Status s;
  Result r = Run("UPDATE work_queue SET lease_expires_ns = " INSPECT_PG_NOW_NS " + $2::bigint WHERE lease_owner = $1 "
                 "AND ended = 0 AND job_id = ANY($3::text[]) RETURNING job_id, cancel_requested",
                 {T(worker), I(lease_ms * 1000000), T(TextArray(running))}, &s, "RenewLeases");
  INSPECT_RETURN_IF_ERROR(s);
  LeaseRenewal out;
  for (int i = 0; i < r.rows(); ++i) {
    out.held.push_back(r.Bytes(i, 0));
    if (r.Int(i, 1) != 0) out.cancel_requested.push_back(r.Bytes(i, 0));
  }
  return out;
}

StatusOr<bool> PostgresDataStore::CompleteWork(const std::string& worker, const v1::Job& ended,
                                               const v1::JobEvent& terminal_event) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  // The row stays, marked ended, until the input folder is gone (EndedWork / ForgetWork): a
  // replica dying in between leaves the folder to the others' sweep, not on the disk for ever.
  // The job and its event are written only when the worker still held it (FROM q): otherwise
  // another worker runs it now, and its outcome is the job's.
  Result r = Run("WITH q AS (UPDATE work_queue SET ended = 1, lease_owner = '' WHERE job_id = $1::text AND "
                 "lease_owner = $2::text AND ended = 0 RETURNING job_id), "
                 "j AS (" INSPECT_PG_UPSERT_JOB("SELECT $1::text, $3::integer, $4::integer, $5::text, $6::bigint, '', $7::bytea FROM q")
                 "), e AS (" INSPECT_PG_UPSERT_EVENT("SELECT $1::text, $8::bigint, $9::bytea FROM q")
                 ") SELECT count(*)::bigint FROM q CROSS JOIN LATERAL (SELECT pg_notify('inspectd_job', q.job_id)) n",
                 {T(ended.job_id()), T(worker), I(ended.kind()), I(ended.state()), T(ended.request_id()), I(CreateNs(ended)),
                  B(ended.SerializeAsString()), I(int64_t(terminal_event.sequence())), B(terminal_event.SerializeAsString())},
                 &s, "CompleteWork");
  INSPECT_RETURN_IF_ERROR(s);
  return r.Int(0, 0) > 0;
}

StatusOr<bool> PostgresDataStore::ReleaseWork(const std::string& worker, const v1::Job& queued,
                                              const v1::JobEvent& event) {
  std::lock_guard<std::mutex> lock(mu_);
  bool held = false;
  Status status = InTransaction("ReleaseWork", [&]() -> Status {
    Status s;
    Result r = Run("UPDATE work_queue SET lease_owner = '', lease_expires_ns = 0 WHERE job_id = $1 AND lease_owner = $2 "
                   "AND ended = 0 RETURNING job_id",
                   {T(queued.job_id()), T(worker)}, &s, "ReleaseWork");
    INSPECT_RETURN_IF_ERROR(s);
    held = r.rows() > 0;
    if (!held) return Status::Ok();
    INSPECT_RETURN_IF_ERROR(WriteJobAndEvent(queued, event, "ReleaseWork"));
    Run("SELECT pg_notify('inspectd_work', $1)", {T(queued.job_id())}, &s, "ReleaseWork");  // delivered at COMMIT
    return s;
  });
  INSPECT_RETURN_IF_ERROR(status);
  return held;
}

StatusOr<bool> PostgresDataStore::CancelQueuedWork(const v1::Job& cancelled, const v1::JobEvent& event) {
  std::lock_guard<std::mutex> lock(mu_);
  bool removed = false;
  Status status = InTransaction("CancelQueuedWork", [&]() -> Status {
    Status s;
    Result r = Run("UPDATE work_queue SET ended = 1, lease_owner = '' WHERE job_id = $1 AND ended = 0 AND "
                   "(lease_owner = '' OR lease_expires_ns < " INSPECT_PG_NOW_NS ") RETURNING job_id",
                   {T(cancelled.job_id())}, &s, "CancelQueuedWork");
    INSPECT_RETURN_IF_ERROR(s);
    removed = r.rows() > 0;
    if (removed) return WriteJobAndEvent(cancelled, event, "CancelQueuedWork");
    Run("UPDATE work_queue SET cancel_requested = 1 WHERE job_id = $1 AND ended = 0", {T(cancelled.job_id())}, &s, "CancelQueuedWork");
    return s;
  });
  INSPECT_RETURN_IF_ERROR(status);
  return removed;
}

StatusOr<int64_t> PostgresDataStore::QueueDepth() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT count(*)::bigint FROM work_queue WHERE ended = 0 AND (lease_owner = '' OR lease_expires_ns < "
                 INSPECT_PG_NOW_NS ")",
                 {}, &s, "QueueDepth");
  INSPECT_RETURN_IF_ERROR(s);
  return r.Int(0, 0);
}

StatusOr<std::vector<std::string>> PostgresDataStore::QueuedWorkIds() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job_id FROM work_queue WHERE ended = 0", {}, &s, "QueuedWorkIds");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<std::string> ids;
  for (int i = 0; i < r.rows(); ++i) ids.push_back(r.Bytes(i, 0));
  return ids;
}

StatusOr<std::vector<std::string>> PostgresDataStore::WorkInputDirs() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT stack_dir FROM work_queue WHERE stack_dir <> ''", {}, &s, "WorkInputDirs");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<std::string> dirs;
  for (int i = 0; i < r.rows(); ++i) dirs.push_back(r.Bytes(i, 0));
  return dirs;
}

StatusOr<std::vector<QueuedWork>> PostgresDataStore::EndedWork() {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT job_id, stack_dir FROM work_queue WHERE ended = 1", {}, &s, "EndedWork");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<QueuedWork> out;
  for (int i = 0; i < r.rows(); ++i) {
    QueuedWork w;
    w.job_id = r.Bytes(i, 0);
    w.stack_dir = r.Bytes(i, 1);
    out.push_back(std::move(w));
  }
  return out;
}

Status PostgresDataStore::ForgetWork(const std::string& job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("DELETE FROM work_queue WHERE job_id = $1 AND ended = 1", {T(job_id)}, &s, "ForgetWork");
  return s;
}

}  // namespace

StatusOr<std::unique_ptr<DataStore>> OpenPostgresStore(const fs::path& data_dir, const std::string& conninfo,
                                                       const std::string& password) {
  // expand_dbname: `conninfo` (a URL or key=value string) supplies every other parameter.
  std::vector<const char*> keys = {"dbname", "connect_timeout", "application_name"};
  std::vector<const char*> values = {conninfo.c_str(), "10", "inspectd"};
  if (!password.empty()) {
    keys.push_back("password");
    values.push_back(password.c_str());
  }
  keys.push_back(nullptr);
  values.push_back(nullptr);
  PGconn* conn = PQconnectdbParams(keys.data(), values.data(), /*expand_dbname=*/1);
  if (conn == nullptr) return Status::Unavailable("database: out of memory connecting");
  if (PQstatus(conn) != CONNECTION_OK) {
    std::string message = OneLine(PQerrorMessage(conn));
    PQfinish(conn);
    return Status::Unavailable("database: cannot connect to " + RedactDatabaseUrl(conninfo) + ": " + message);
  }
  // Server notices ("relation already exists, skipping") are the migration's expected chatter:
  // they would go to stderr unformatted. Logs stay quiet by default.
  PQsetNoticeProcessor(conn, [](void*, const char* message) { spdlog::debug("database: {}", OneLine(message)); },
                       nullptr);
  // The notification listener's own connection, made with the same parameters.
  auto connect = [conninfo, password]() -> PGconn* {
    std::vector<const char*> k = {"dbname", "connect_timeout", "application_name"};
    std::vector<const char*> v = {conninfo.c_str(), "10", "inspectd-listen"};
    if (!password.empty()) {
      k.push_back("password");
      v.push_back(password.c_str());
    }
    k.push_back(nullptr);
    v.push_back(nullptr);
    PGconn* c = PQconnectdbParams(k.data(), v.data(), /*expand_dbname=*/1);
    if (c && PQstatus(c) != CONNECTION_OK) {
      spdlog::debug("database: the notification connection failed: {}", OneLine(PQerrorMessage(c)));
      PQfinish(c);
      c = nullptr;
    }
    return c;
  };
  auto store = std::make_unique<PostgresDataStore>(data_dir, conn, std::move(connect));
  INSPECT_RETURN_IF_ERROR(store->Migrate());
  return std::unique_ptr<DataStore>(std::move(store));
}

Status PostgresDataStore::PutStudy(const v1::Study& study) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("INSERT INTO studies(study_id, recipe_id, finish_ns, study) VALUES($1,$2,$3,$4) "
      "ON CONFLICT (study_id) DO UPDATE SET recipe_id = EXCLUDED.recipe_id, finish_ns = EXCLUDED.finish_ns, "
      "study = EXCLUDED.study",
      {T(study.study_id()), T(study.recipe_id()),
       I(study.finish_time().seconds() * 1000000000LL + study.finish_time().nanos()), B(study.SerializeAsString())},
      &s, "PutStudy");
  return s;
}

StatusOr<v1::Study> PostgresDataStore::GetStudy(const std::string& study_id) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT study FROM studies WHERE study_id = $1", {T(study_id)}, &s, "GetStudy");
  INSPECT_RETURN_IF_ERROR(s);
  if (r.rows() == 0) return Status::NotFound("study_id '" + study_id + "' not found");
  v1::Study study;
  if (!study.ParseFromString(r.Bytes(0, 0))) return Status::DataLoss("study record is corrupt");
  return study;
}

StatusOr<std::vector<v1::Study>> PostgresDataStore::ListStudies(const std::string& recipe_id, int limit) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run("SELECT study FROM studies WHERE ($1 = '' OR recipe_id = $1) ORDER BY finish_ns DESC, study_id LIMIT $2",
                 {T(recipe_id), I(limit)}, &s, "ListStudies");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::Study> out;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &out, "study"));
  return out;
}

Status PostgresDataStore::PutVerification(const v1::VerificationRecord& record) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Run("INSERT INTO verifications(verification_id, calibration_id, mode, finish_ns, record) VALUES($1,$2,$3,$4,$5) "
      "ON CONFLICT (verification_id) DO UPDATE SET calibration_id = EXCLUDED.calibration_id, mode = EXCLUDED.mode, "
      "finish_ns = EXCLUDED.finish_ns, record = EXCLUDED.record",
      {T(record.verification_id()), T(record.calibration_id()), I(int64_t(record.mode())),
       I(record.finish_time().seconds() * 1000000000LL + record.finish_time().nanos()), B(record.SerializeAsString())},
      &s, "PutVerification");
  return s;
}

StatusOr<std::vector<v1::VerificationRecord>> PostgresDataStore::ListVerifications(const std::string& calibration_id,
                                                                                   v1::VerificationMode mode,
                                                                                   int limit) {
  std::lock_guard<std::mutex> lock(mu_);
  Status s;
  Result r = Run(
      "SELECT record FROM verifications WHERE calibration_id = $1 AND ($2 = 0 OR mode = $2) "
      "ORDER BY finish_ns DESC, verification_id LIMIT $3",
      {T(calibration_id), I(int64_t(mode)), I(limit)}, &s, "ListVerifications");
  INSPECT_RETURN_IF_ERROR(s);
  std::vector<v1::VerificationRecord> out;
  INSPECT_RETURN_IF_ERROR(ParseRows(r, 0, &out, "verification record"));
  return out;
}

}  // namespace inspection
