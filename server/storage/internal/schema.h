// The metadata schema's version, shared by the SQLite and PostgreSQL backends: each keeps a
// schema_version table and one migration per version. A database whose stored version is newer
// than this binary knows was written by a newer inspectd: refusing it is the only safe answer
// (its rows may mean what this binary cannot read or would overwrite).
#pragma once

#include <cstdint>
#include <string>

#include "core/util/status.h"

namespace inspection {

// Version 1: jobs, events, artifacts, calibrations, settings, pins, recipes, results.
// Version 2: results forwarded by rigs to a site store (results.rig_id, results.rig_sequence).
// Version 3: the reconstruct pool's work queue (work_queue: stored input, lease, heartbeat).
// Version 4: Type-1 gauge studies (studies).
// Version 5: instrument verification records (verifications).
inline constexpr int64_t kStoreSchemaVersion = 5;

inline Status CheckSchemaVersion(int64_t stored, const std::string& where) {
  if (stored > kStoreSchemaVersion) {
    return Status::FailedPrecondition("database " + where + " has schema version " + std::to_string(stored) +
                                      ", newer than this inspectd knows (" + std::to_string(kStoreSchemaVersion) +
                                      "): run the inspectd that wrote it, or a newer one");
  }
  return Status::Ok();
}

}  // namespace inspection
