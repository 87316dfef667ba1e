// RigController: owns the one rig of this server and its OPC 40100-style state (Initializing,
// Ready, Busy, Error). Rig jobs and simulation changes take the rig exclusively through it.
// Thread-safe.
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "core/util/status.h"
#include "devices/rig.h"
#include "inspection/v1/inspection.pb.h"

namespace inspection {

class RigController {
 public:
  // startup: OK, or why the rig came up degraded (then the state is Error until a Reset works).
  RigController(std::unique_ptr<Rig> rig, Status startup);

  v1::RigState state() const;
  std::string state_detail() const;
  Rig& rig() { return *rig_; }
  bool simulated() const { return rig_->simulation() != nullptr; }
  bool usable() const;  // Ready or Busy
  // OK when usable; else FAILED_PRECONDITION with the state and its cause (rig jobs are refused).
  Status CheckUsable() const;

  // Exclusive use of the rig. TryAcquire returns an unlocked lock when a job holds the rig.
  std::unique_lock<std::mutex> Acquire() { return std::unique_lock<std::mutex>(rig_mu_); }
  std::unique_lock<std::mutex> TryAcquire() { return std::unique_lock<std::mutex>(rig_mu_, std::try_to_lock); }

  void SetBusy(bool busy);
  // A rig job ended with this status: device failures (UNAVAILABLE, DEADLINE_EXCEEDED,
  // DATA_LOSS) move the rig to Error; anything else leaves it Ready.
  void ReportJobStatus(const Status& status);
  // Reconnects devices; Ready on success, Error with the reason otherwise. Caller holds the rig.
  Status Reset();

  // Called with true/false whenever usability changes (drives the gRPC health service).
  void SetHealthCallback(std::function<void(bool serving)> cb);

  // Devices, state, pixel size and scan defaults; the caller fills in job and calibration fields.
  void FillStatus(v1::RigStatus* status);

 private:
  void SetStateLocked(v1::RigState state, std::string detail);

  std::unique_ptr<Rig> rig_;
  std::mutex rig_mu_;  // held for the duration of a rig job
  mutable std::mutex mu_;
  v1::RigState state_ = v1::RIG_STATE_INITIALIZING;
  std::string detail_;
  std::function<void(bool)> health_cb_;
};

}  // namespace inspection
