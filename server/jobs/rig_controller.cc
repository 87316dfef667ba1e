#include "server/jobs/rig_controller.h"

#include <spdlog/spdlog.h>

namespace inspection {

RigController::RigController(std::unique_ptr<Rig> rig, Status startup) : rig_(std::move(rig)) {
  if (startup.ok()) startup = rig_->CheckDevices();
  if (startup.ok()) {
    state_ = v1::RIG_STATE_READY;
  } else {
    state_ = v1::RIG_STATE_ERROR;
    detail_ = startup.message();
  }
}

v1::RigState RigController::state() const {
  std::lock_guard<std::mutex> lock(mu_);
  return state_;
}

std::string RigController::state_detail() const {
  std::lock_guard<std::mutex> lock(mu_);
  return detail_;
}

bool RigController::usable() const {
  std::lock_guard<std::mutex> lock(mu_);
  return state_ == v1::RIG_STATE_READY || state_ == v1::RIG_STATE_BUSY;
}

Status RigController::CheckUsable() const {
  std::lock_guard<std::mutex> lock(mu_);
  if (state_ == v1::RIG_STATE_READY || state_ == v1::RIG_STATE_BUSY) return Status::Ok();
  return Status::FailedPrecondition("rig is not ready (state " + v1::RigState_Name(state_) + ": " + detail_ +
                                    "); fix the cause and call ResetRig");
}

void RigController::SetStateLocked(v1::RigState state, std::string detail) {
  const bool was_usable = state_ == v1::RIG_STATE_READY || state_ == v1::RIG_STATE_BUSY;
  const bool now_usable = state == v1::RIG_STATE_READY || state == v1::RIG_STATE_BUSY;
  if (state != state_)
    spdlog::info("rig state {} -> {} {}", v1::RigState_Name(state_), v1::RigState_Name(state), detail);
  state_ = state;
  detail_ = std::move(detail);
  if (was_usable != now_usable && health_cb_) health_cb_(now_usable);
}

void RigController::SetBusy(bool busy) {
  std::lock_guard<std::mutex> lock(mu_);
  if (state_ == v1::RIG_STATE_ERROR) return;
  SetStateLocked(busy ? v1::RIG_STATE_BUSY : v1::RIG_STATE_READY, "");
}

void RigController::ReportJobStatus(const Status& s) {
  std::lock_guard<std::mutex> lock(mu_);
  const bool device_failure = s.code() == StatusCode::kUnavailable || s.code() == StatusCode::kDeadlineExceeded ||
                              s.code() == StatusCode::kDataLoss;
  if (device_failure) {
    SetStateLocked(v1::RIG_STATE_ERROR, s.message());
  } else if (state_ == v1::RIG_STATE_BUSY) {
    SetStateLocked(v1::RIG_STATE_READY, "");
  }
}

Status RigController::Reset() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    SetStateLocked(v1::RIG_STATE_INITIALIZING, "reset requested");
  }
  Status s = rig_->Reset();
  std::lock_guard<std::mutex> lock(mu_);
  if (s.ok()) {
    SetStateLocked(v1::RIG_STATE_READY, "");
  } else {
    SetStateLocked(v1::RIG_STATE_ERROR, s.message());
  }
  return s;
}

void RigController::SetHealthCallback(std::function<void(bool)> cb) {
  std::lock_guard<std::mutex> lock(mu_);
  health_cb_ = std::move(cb);
  if (health_cb_) health_cb_(state_ == v1::RIG_STATE_READY || state_ == v1::RIG_STATE_BUSY);
}

void RigController::FillStatus(v1::RigStatus* st) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    st->set_state(state_);
    st->set_state_detail(detail_);
  }
  for (const DeviceInfo& d : {rig_->camera().info(), rig_->projector().info(), rig_->stage().info()}) {
    v1::DeviceStatus* ds = st->add_devices();
    ds->set_role(d.role);
    ds->set_driver(d.driver);
    ds->set_model(d.model);
    ds->set_serial(d.serial);
    ds->set_connected(d.connected);
    ds->set_detail(d.detail);
  }
  st->set_simulated(simulated());
  if (SimulationControl* sim = rig_->simulation()) st->set_specimen(sim->specimen());
  st->set_pixel_size_um(rig_->pixel_size_um());
  const ScanDefaults d = rig_->scan_defaults();
  st->mutable_scan_defaults()->set_z_start_um(d.z_start_um);
  st->mutable_scan_defaults()->set_z_end_um(d.z_end_um);
  st->mutable_scan_defaults()->set_z_step_um(d.z_step_um);
  st->mutable_scan_defaults()->set_exposure_us(d.exposure_us);
  st->mutable_scan_defaults()->set_focus_search_step_um(d.focus_search_step_um);
}

}  // namespace inspection
