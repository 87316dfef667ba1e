// CalibrationStore: the calibration bundles of this server (thesis ch. 4 models) - the active
// one loaded at start-up and handed to scans, new ones produced by Calibrate jobs and stored
// under <data dir>/calibrations/<id>/ (never overwritten: scans refer to them by id).
// Thread-safe.
#pragma once

#include <memory>
#include <mutex>
#include <string>

#include "core/calibration_bundle.h"
#include "server/data_store.h"
#include "server/job_manager.h"

namespace inspection {

class CalibrationStore {
 public:
  explicit CalibrationStore(DataStore* store) : store_(store) {}

  // Loads the active bundle named in the store, if any. A bundle that fails to load is logged
  // and left inactive (the rig still scans; calibration-dependent modes will refuse).
  Status LoadActive();
  std::shared_ptr<const CalibrationBundle> active() const;

  // The job hook: runs the requested steps on the rig (carrying over the rest from the active
  // bundle), stores the new bundle, makes it active and returns its record.
  StatusOr<v1::Calibration> Run(const CalibrationContext& ctx);

 private:
  DataStore* store_;
  mutable std::mutex mu_;
  std::shared_ptr<const CalibrationBundle> active_;
};

// Flattens a bundle's reports into the API's figure map ("<step>.<figure>").
v1::CalibrationSummary SummariseBundle(const CalibrationBundle& bundle);

}  // namespace inspection
