// DataStore: the server's durable state, so scans, jobs and their results survive a restart.
// Metadata (jobs, events, artifacts' records, calibrations' records, recipes, results, settings)
// lives in a database behind this interface: SQLite in <data dir>/inspection.db (WAL) for one rig,
// the default, or PostgreSQL for a pool or a site (DatabaseOptions.url "postgresql://...";
// server/storage/postgres_store.cc). Both keep a versioned schema (storage/schema.h) and refuse a
// database whose schema is newer than this binary knows. Bulk data lives in folders of the data
// directory (for a pool: a folder every replica mounts):
//   artifacts/<job_id>/      result files of a succeeded job; a scan's stack only as stack.zip
//   scans/<scan_id>/         stack folders of the earlier layout (read in place, deleted)
//   calibrations/<id>/       calibration bundles
//   uploads/, tmp/           work areas, emptied at start-up (SQLite); on a pool's shared folder
//                            a dead writer's uploads are swept instead (work_folders.h)
// Thread-safe: each backend keeps one connection guarded by a mutex (writes are small; bulk I/O
// is outside).
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/storage/owned_folder.h"
#include "server/storage/work_folders.h"

namespace inspection {

namespace v1 = ::inspection::v1;

struct StoredArtifact {
  v1::Artifact artifact;
  std::string job_id;
  std::filesystem::path path;
};

// A ListResults filter; empty / 0 fields match everything.
struct ResultQuery {
  std::string part_id;
  std::string recipe_id;
  v1::Verdict verdict = v1::VERDICT_UNSPECIFIED;
  int64_t finished_from_ns = 0;    // inclusive
  int64_t finished_before_ns = 0;  // exclusive
  int64_t before_sequence = 0;     // paging: only older results
  int limit = 50;
};

// A reconstruct job waiting in, or taken from, the pool's work queue (the JobManager's pool mode,
// server/jobs/job_manager.h): what any replica needs to run the job from its stored input.
struct QueuedWork {
  std::string job_id;
  std::string input;      // the serialised v1::ReconstructStart the job was accepted with
  std::string stack_dir;  // the stored input: the stack's folder, relative to the data directory
  int attempts = 0;       // replicas that took it, this one included (> 1: a rerun)
  bool cancel_requested = false;
};

// What a worker's lease renewal found: the jobs it still holds, and those of them a CancelJob
// on any replica asked to stop.
struct LeaseRenewal {
  std::vector<std::string> held;
  std::vector<std::string> cancel_requested;
};

// Where the metadata lives. Validated by DataStore::Open (INVALID_ARGUMENT naming `database`).
struct DatabaseOptions {
  // "" or "sqlite": <data dir>/inspection.db. "postgresql://user@host:port/db?..." (or
  // "postgres://", or a libpq key=value string starting with "host=" / "dbname="): PostgreSQL.
  std::string url;
  // A file whose first line is the password (PostgreSQL only); never logged. Empty: none, or
  // the one in the URL / ~/.pgpass.
  std::filesystem::path password_file;
};

// The URL without its password, for logs and errors.
std::string RedactDatabaseUrl(const std::string& url);
// INVALID_ARGUMENT naming `database` (or `database_password_file`) when Open would refuse them;
// connects to nothing.
Status ValidateDatabaseOptions(const DatabaseOptions& database);

class DataStore {
 public:
  // Opens the store of `data_dir` with its metadata where `database` says (SQLite by default),
  // creating the folders and migrating the schema to this binary's version.
  // INVALID_ARGUMENT naming `database` for a malformed URL; UNAVAILABLE when the database server
  // cannot be reached (the caller may retry); FAILED_PRECONDITION when the stored schema is newer
  // than this binary knows (naming both versions) or the folders cannot be made.
  static StatusOr<std::unique_ptr<DataStore>> Open(const std::filesystem::path& data_dir,
                                                   const DatabaseOptions& database = {});
  virtual ~DataStore() = default;
  // "sqlite" or "postgresql": what the metadata lives in.
  virtual const char* backend() const = 0;
  // True when other processes write to the same database (PostgreSQL: a pool or a site), so
  // waiting for this process's own writes is not enough to see new rows.
  virtual bool shared() const = 0;

  // What another process sharing the database just did (PostgreSQL LISTEN / NOTIFY): work was
  // queued or handed back (an idle worker may take it now), or a job's events or end were stored
  // (a watcher of that job may read them now). A hint only: notifications are lost while the
  // listening connection is down, so waiters keep polling as well.
  enum class Change { kWorkQueued, kJobChanged };
  using ChangeListener = std::function<void(Change change, const std::string& job_id)>;
  // Calls `listener` on a thread of the store's for every change (also this process's own);
  // an empty listener stops the calls (it returns after a call in progress ended). A store whose
  // database no other process shares never calls it.
  virtual void ListenForChanges(ChangeListener listener) { (void)listener; }

  const std::filesystem::path& data_dir() const { return data_dir_; }
  std::filesystem::path scans_dir() const { return data_dir_ / "scans"; }
  std::filesystem::path artifacts_dir() const { return data_dir_ / "artifacts"; }
  std::filesystem::path calibrations_dir() const { return data_dir_ / "calibrations"; }
  std::filesystem::path uploads_dir() const { return data_dir_ / "uploads"; }
  std::filesystem::path tmp_dir() const { return data_dir_ / "tmp"; }
  // A new folder uploads/<prefix>-<random> (not created yet), removed when the last holder lets
  // go, and held (work_folders.h) until then or its Release(): another replica's sweep leaves it.
  std::shared_ptr<OwnedFolder> NewUploadFolder(const std::string& prefix);
  LiveWorkFolders& live_work_folders() { return live_work_folders_; }

  // Inserts or replaces the job row (the Job message is the whole record).
  virtual Status PutJob(const v1::Job& job) = 0;
  virtual StatusOr<v1::Job> GetJob(const std::string& job_id) = 0;
  // Job id of an earlier job of this kind with this request id, if any.
  virtual std::optional<std::string> FindJobByRequestId(v1::JobKind kind, const std::string& request_id) = 0;
  // Newest first; kind/state UNSPECIFIED = any. `before_ns` pages (0 = from newest).
  virtual StatusOr<std::vector<v1::Job>> ListJobs(v1::JobKind kind, v1::JobState state, int limit, int64_t before_create_ns) = 0;
  // Jobs that were queued or running when the server stopped.
  virtual StatusOr<std::vector<v1::Job>> UnfinishedJobs() = 0;

  virtual Status AppendEvent(const v1::JobEvent& event) = 0;
  // Several events (of any jobs) in one step: all stored, or none.
  virtual Status AppendEvents(const std::vector<v1::JobEvent>& events) = 0;
  virtual StatusOr<std::vector<v1::JobEvent>> Events(const std::string& job_id) = 0;

  virtual Status PutArtifact(const StoredArtifact& artifact) = 0;
  virtual StatusOr<StoredArtifact> GetArtifact(const std::string& artifact_id) = 0;

  virtual Status PutCalibration(const v1::Calibration& calibration) = 0;
  virtual StatusOr<v1::Calibration> GetCalibration(const std::string& calibration_id) = 0;
  virtual StatusOr<std::vector<v1::Calibration>> ListCalibrations() = 0;

  // Data lifecycle. Pinned jobs are kept by the retention sweeper.
  virtual Status SetPinned(const std::string& job_id, bool pinned) = 0;
  virtual StatusOr<std::vector<std::string>> PinnedJobs() = 0;
  // Jobs that ended (SUCCEEDED, FAILED, CANCELLED), in no particular order.
  virtual StatusOr<std::vector<v1::Job>> FinishedJobs() = 0;
  // Removes a job's rows (job, events, artifacts, pin) in one transaction; its files are the
  // caller's to remove afterwards (nothing is served from files without a row).
  virtual Status DeleteJobRecords(const std::string& job_id) = 0;
  // Removes the job's artifacts of `kind`: their rows and their entries in the stored
  // Job.result, in one transaction. Returns the removed artifacts (paths for the caller).
  virtual StatusOr<std::vector<StoredArtifact>> DeleteArtifactsOfKind(const std::string& job_id, v1::ArtifactKind kind) = 0;

  // Recipes. Every version is kept (results name the version they ran); deleting a recipe hides
  // all its versions, and a recipe created again under the same id continues the numbering, so a
  // (recipe_id, version) pair always means one document.
  // create: the id must not be in use (ALREADY_EXISTS); the stored version is 1 + the highest
  // ever stored. update: the id must be in use (NOT_FOUND); expected_version > 0 must be the
  // current version (ABORTED otherwise: someone else updated it first). Returns the stored recipe.
  virtual StatusOr<v1::Recipe> StoreRecipe(v1::Recipe recipe, bool create, int expected_version) = 0;
  // version 0 = the current one. NOT_FOUND naming the id (and version).
  virtual StatusOr<v1::Recipe> GetRecipe(const std::string& recipe_id, int version) = 0;
  // The current version of every recipe in use, by id.
  virtual StatusOr<std::vector<v1::Recipe>> ListRecipes() = 0;
  // Hides every version; NOT_FOUND when the id is not in use. Returns the versions hidden.
  virtual StatusOr<int> DeleteRecipe(const std::string& recipe_id) = 0;

  // Inspection results (the result feed). Stores `result` under the next sequence number
  // (increasing, never reused, also after deletions) and returns it with the number set.
  // ALREADY_EXISTS when the job already has a result.
  virtual StatusOr<v1::InspectionResult> AppendResult(v1::InspectionResult result) = 0;
  // A result forwarded by a rig to this (site) store: result.rig_id and result.rig_sequence (the
  // rig's own number) must be set. Stored under the next site-wide sequence number; a result this
  // rig forwarded before (same rig_id and rig_sequence: a retry after a lost answer) is not stored
  // again: the stored one is returned. INVALID_ARGUMENT without rig_id / rig_sequence.
  virtual StatusOr<v1::InspectionResult> ImportResult(v1::InspectionResult result) = 0;
  // Newest first, matching `query`; at most query.limit.
  virtual StatusOr<std::vector<v1::InspectionResult>> ListResults(const ResultQuery& query) = 0;
  // Oldest first: the results with a sequence number > after_sequence, at most `limit`.
  virtual StatusOr<std::vector<v1::InspectionResult>> ResultsAfter(int64_t after_sequence, int limit) = 0;
  // The highest sequence number stored (0 = none).
  virtual StatusOr<int64_t> LastResultSequence() = 0;

  // The work queue of a reconstruct pool (schema version 3). A job is queued with its input, taken
  // by one worker at a time under a lease (`lease_ms`, on the database's clock for PostgreSQL) that
  // the worker renews; a lease that runs out (the worker died) lets another worker take the job
  // again. The job's record and its queue row change together, in one transaction.
  // Stores the QUEUED job, its first event and its queue row.
  virtual Status EnqueueWork(const v1::Job& job, const v1::JobEvent& queued_event, const QueuedWork& work) = 0;
  // Takes the oldest job nobody holds (never taken, handed back, or its lease ran out), those in
  // `preferred` first (their frames are decoded in this process already), under a lease for
  // `worker`. A rerun (attempts > 1) loses the artifact rows an earlier attempt left. nullopt: none.
  // PostgreSQL: FOR UPDATE SKIP LOCKED, so workers taking at once never block on or take the same row.
  virtual StatusOr<std::optional<QueuedWork>> ClaimWork(const std::string& worker, int64_t lease_ms,
                                                        const std::vector<std::string>& preferred) = 0;
  // Extends the leases `worker` holds on the jobs in `running` (those it is running now) and says
  // which of them it still holds. A lease on any other job is left to run out: a claim whose
  // answer never reached the worker (the connection broke after the database ran it) or a job it
  // took but could not read is then taken again, by any worker, instead of being renewed for ever.
  virtual StatusOr<LeaseRenewal> RenewLeases(const std::string& worker, int64_t lease_ms,
                                             const std::vector<std::string>& running) = 0;
  // Ends a job `worker` holds: the ended job and its terminal event are stored and its queue row
  // is marked ended (its input folder to remove: EndedWork). false (nothing written) when the
  // worker no longer holds it: another took it over, or it ended already.
  virtual StatusOr<bool> CompleteWork(const std::string& worker, const v1::Job& ended,
                                      const v1::JobEvent& terminal_event) = 0;
  // Hands a job back (a draining replica): the lease is cleared and the job stored as `queued`
  // (state QUEUED) with `event`. false when the worker no longer held it.
  virtual StatusOr<bool> ReleaseWork(const std::string& worker, const v1::Job& queued, const v1::JobEvent& event) = 0;
  // Cancels a job nobody holds: its queue row is marked ended, `cancelled` and `event` are stored; true. A job
  // a worker holds is flagged instead (the worker sees it at its next renewal) and false returned.
  virtual StatusOr<bool> CancelQueuedWork(const v1::Job& cancelled, const v1::JobEvent& event) = 0;
  // Jobs waiting for a worker (queued, handed back, or held under a lease that ran out).
  virtual StatusOr<int64_t> QueueDepth() = 0;
  // Every job in the queue that has not ended, held or not.
  virtual StatusOr<std::vector<std::string>> QueuedWorkIds() = 0;
  // The stored input folder (stack_dir, relative to the data directory) of every row of the
  // queue, ended or not: folders of uploads/ that are jobs' inputs (work_folders.h).
  virtual StatusOr<std::vector<std::string>> WorkInputDirs() = 0;
  // Ended jobs whose input folder (stack_dir) may still be on the disk: whoever removes it then
  // forgets the row. A replica that dies between the two leaves the row for the next sweep.
  virtual StatusOr<std::vector<QueuedWork>> EndedWork() = 0;
  virtual Status ForgetWork(const std::string& job_id) = 0;
  // Type-1 gauge studies (StartStudy), each stored whole when it ends (replaced when stored again
  // under its id). GetStudy: NOT_FOUND naming the id. ListStudies: newest first (finish time),
  // recipe_id empty = any, at most `limit`.
  virtual Status PutStudy(const v1::Study& study) = 0;
  virtual StatusOr<v1::Study> GetStudy(const std::string& study_id) = 0;
  virtual StatusOr<std::vector<v1::Study>> ListStudies(const std::string& recipe_id, int limit) = 0;
  // Instrument verification records (Verify), each stored whole when its job succeeds (replaced
  // when stored again under its id). ListVerifications: the records made under calibration_id
  // (empty = uncalibrated) of `mode` (UNSPECIFIED = any), newest first (finish time), at most `limit`.
  virtual Status PutVerification(const v1::VerificationRecord& record) = 0;
  virtual StatusOr<std::vector<v1::VerificationRecord>> ListVerifications(const std::string& calibration_id,
                                                                          v1::VerificationMode mode, int limit) = 0;

  virtual Status SetSetting(const std::string& key, const std::string& value) = 0;
  virtual std::string GetSetting(const std::string& key) = 0;

 protected:
  explicit DataStore(std::filesystem::path dir) : data_dir_(std::move(dir)) {}
  // Creates the data directory's folders and, when this server is their only user, empties
  // its work areas (uploads/, tmp/).
  Status PrepareFolders(bool empty_work_areas);

 private:
  std::filesystem::path data_dir_;
  LiveWorkFolders live_work_folders_;
};

// Random id with a readable prefix, e.g. "job-5f3a9c0e1b2d4e6f".
std::string NewId(const std::string& prefix);

}  // namespace inspection
