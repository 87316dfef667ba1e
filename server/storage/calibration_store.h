// CalibrationStore: the calibration bundles of this server (thesis ch. 4 models), storage only.
// Bundles live under <data dir>/calibrations/<id>/ and are never overwritten (scans refer to
// them by id); their records are in the DataStore. One bundle is active: loaded at start-up,
// replaced when a calibration job activates a new one, handed to scans.
// Thread-safe.
#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/calibration/calibration_bundle.h"
#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/storage/data_store.h"

namespace inspection {

class CalibrationStore {
 public:
  explicit CalibrationStore(DataStore* store) : store_(store) {}

  // Loads the active bundle named in the store, if any. A bundle that fails to load is logged
  // and left inactive (the rig still scans; calibration-dependent modes will refuse).
  Status LoadActive();
  // The active bundle; null when none is loaded.
  std::shared_ptr<const CalibrationBundle> active() const;
  // The id recorded as active (also when its bundle failed to load); empty when none.
  std::string active_id() const;

  // Stores `bundle` under a new id (set in bundle->id) with its record, which names the job
  // that produced it. The bundle is not active yet.
  StatusOr<v1::Calibration> Save(CalibrationBundle* bundle, const std::string& job_id);
  // Makes a stored bundle the active one, now and after a restart.
  Status Activate(std::shared_ptr<const CalibrationBundle> bundle);

  // Records with their `active` flag: one by id (empty = the active one), or all.
  StatusOr<v1::Calibration> Get(const std::string& calibration_id) const;
  StatusOr<std::vector<v1::Calibration>> List() const;

 private:
  DataStore* store_;
  mutable std::mutex mu_;  // guards active_
  std::shared_ptr<const CalibrationBundle> active_;
};

// Flattens a bundle's reports into the API's figure map ("<step>.<figure>").
v1::CalibrationSummary SummariseBundle(const CalibrationBundle& bundle);

}  // namespace inspection
