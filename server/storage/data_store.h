// DataStore: the server's durable state under --data-dir, so scans, jobs and their results
// survive a restart. Metadata lives in SQLite (inspection.db, WAL); bulk data in folders:
//   artifacts/<job_id>/      result files of a succeeded job; a scan's stack only as stack.zip
//   scans/<scan_id>/         stack folders of the earlier layout (read in place, deleted)
//   calibrations/<id>/       calibration bundles
//   uploads/, tmp/           work areas, emptied at start-up
// Thread-safe: one connection guarded by a mutex (writes are small; bulk I/O is outside).
#pragma once

#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"

struct sqlite3;

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

class DataStore {
 public:
  static StatusOr<std::unique_ptr<DataStore>> Open(const std::filesystem::path& data_dir);
  ~DataStore();

  const std::filesystem::path& data_dir() const { return data_dir_; }
  std::filesystem::path scans_dir() const { return data_dir_ / "scans"; }
  std::filesystem::path artifacts_dir() const { return data_dir_ / "artifacts"; }
  std::filesystem::path calibrations_dir() const { return data_dir_ / "calibrations"; }
  std::filesystem::path uploads_dir() const { return data_dir_ / "uploads"; }
  std::filesystem::path tmp_dir() const { return data_dir_ / "tmp"; }

  // Inserts or replaces the job row (the Job message is the whole record).
  Status PutJob(const v1::Job& job);
  StatusOr<v1::Job> GetJob(const std::string& job_id);
  // Job id of an earlier job of this kind with this request id, if any.
  std::optional<std::string> FindJobByRequestId(v1::JobKind kind, const std::string& request_id);
  // Newest first; kind/state UNSPECIFIED = any. `before_ns` pages (0 = from newest).
  StatusOr<std::vector<v1::Job>> ListJobs(v1::JobKind kind, v1::JobState state, int limit, int64_t before_create_ns);
  // Jobs that were queued or running when the server stopped.
  StatusOr<std::vector<v1::Job>> UnfinishedJobs();

  Status AppendEvent(const v1::JobEvent& event);
  StatusOr<std::vector<v1::JobEvent>> Events(const std::string& job_id);

  Status PutArtifact(const StoredArtifact& artifact);
  StatusOr<StoredArtifact> GetArtifact(const std::string& artifact_id);

  Status PutCalibration(const v1::Calibration& calibration);
  StatusOr<v1::Calibration> GetCalibration(const std::string& calibration_id);
  StatusOr<std::vector<v1::Calibration>> ListCalibrations();

  // Data lifecycle. Pinned jobs are kept by the retention sweeper.
  Status SetPinned(const std::string& job_id, bool pinned);
  StatusOr<std::vector<std::string>> PinnedJobs();
  // Jobs that ended (SUCCEEDED, FAILED, CANCELLED), in no particular order.
  StatusOr<std::vector<v1::Job>> FinishedJobs();
  // Removes a job's rows (job, events, artifacts, pin) in one transaction; its files are the
  // caller's to remove afterwards (nothing is served from files without a row).
  Status DeleteJobRecords(const std::string& job_id);
  // Removes the job's artifacts of `kind`: their rows and their entries in the stored
  // Job.result, in one transaction. Returns the removed artifacts (paths for the caller).
  StatusOr<std::vector<StoredArtifact>> DeleteArtifactsOfKind(const std::string& job_id, v1::ArtifactKind kind);

  // Recipes. Every version is kept (results name the version they ran); deleting a recipe hides
  // all its versions, and a recipe created again under the same id continues the numbering, so a
  // (recipe_id, version) pair always means one document.
  // create: the id must not be in use (ALREADY_EXISTS); the stored version is 1 + the highest
  // ever stored. update: the id must be in use (NOT_FOUND); expected_version > 0 must be the
  // current version (ABORTED otherwise: someone else updated it first). Returns the stored recipe.
  StatusOr<v1::Recipe> StoreRecipe(v1::Recipe recipe, bool create, int expected_version);
  // version 0 = the current one. NOT_FOUND naming the id (and version).
  StatusOr<v1::Recipe> GetRecipe(const std::string& recipe_id, int version);
  // The current version of every recipe in use, by id.
  StatusOr<std::vector<v1::Recipe>> ListRecipes();
  // Hides every version; NOT_FOUND when the id is not in use. Returns the versions hidden.
  StatusOr<int> DeleteRecipe(const std::string& recipe_id);

  // Inspection results (the result feed). Stores `result` under the next sequence number
  // (increasing, never reused, also after deletions) and returns it with the number set.
  // ALREADY_EXISTS when the job already has a result.
  StatusOr<v1::InspectionResult> AppendResult(v1::InspectionResult result);
  // Newest first, matching `query`; at most query.limit.
  StatusOr<std::vector<v1::InspectionResult>> ListResults(const ResultQuery& query);
  // Oldest first: the results with a sequence number > after_sequence, at most `limit`.
  StatusOr<std::vector<v1::InspectionResult>> ResultsAfter(int64_t after_sequence, int limit);
  // The highest sequence number stored (0 = none).
  StatusOr<int64_t> LastResultSequence();

  Status SetSetting(const std::string& key, const std::string& value);
  std::string GetSetting(const std::string& key);

 private:
  explicit DataStore(std::filesystem::path dir) : data_dir_(std::move(dir)) {}
  Status Exec(const char* sql);

  std::filesystem::path data_dir_;
  std::mutex mu_;
  sqlite3* db_ = nullptr;
};

// Random id with a readable prefix, e.g. "job-5f3a9c0e1b2d4e6f".
std::string NewId(const std::string& prefix);

}  // namespace inspection
