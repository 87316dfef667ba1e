// CalibrationStore: load, save, activate and list calibration bundles (thesis ch. 4 models).
#include "server/storage/calibration_store.h"

#include <google/protobuf/util/time_util.h>
#include <spdlog/spdlog.h>

#include "server/storage/owned_folder.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {
constexpr const char* kActiveSetting = "active_calibration_id";
}  // namespace

v1::CalibrationSummary SummariseBundle(const CalibrationBundle& b) {
  v1::CalibrationSummary s;
  for (const CalibrationStepReport& r : b.reports) {
    const std::string step = CalibrationStepName(r.step);
    s.add_steps(step);
    (*s.mutable_figures())[step + ".duration_s"] = r.duration_s;
    (*s.mutable_figures())[step + ".frames_captured"] = r.frames_captured;
    for (const auto& [name, value] : r.figures) (*s.mutable_figures())[step + "." + name] = value;
  }
  return s;
}

Status CalibrationStore::LoadActive() {
  const std::string id = active_id();
  if (id.empty()) return Status::Ok();
  auto bundle = CalibrationBundle::Load(store_->calibrations_dir() / id);
  if (!bundle.ok()) {
    spdlog::error("active calibration {} cannot be loaded: {}", id, bundle.status().ToString());
    return bundle.status();
  }
  std::lock_guard<std::mutex> lock(mu_);
  active_ = std::make_shared<const CalibrationBundle>(std::move(*bundle));
  spdlog::info("active calibration {} loaded", id);
  return Status::Ok();
}

std::shared_ptr<const CalibrationBundle> CalibrationStore::active() const {
  std::lock_guard<std::mutex> lock(mu_);
  return active_;
}

std::string CalibrationStore::active_id() const { return store_->GetSetting(kActiveSetting); }

StatusOr<v1::Calibration> CalibrationStore::Save(CalibrationBundle* bundle, const std::string& job_id) {
  bundle->id = NewId("cal");
  // Written aside, then moved in one rename: a bundle folder is complete or absent.
  OwnedFolder tmp(store_->tmp_dir() / (bundle->id + ".bundle"));
  const fs::path dir = store_->calibrations_dir() / bundle->id;
  INSPECT_RETURN_IF_ERROR(bundle->Save(tmp.path()));
  std::error_code ec;
  fs::rename(tmp.path(), dir, ec);
  if (ec) return Status::Internal("cannot store calibration " + bundle->id + ": " + ec.message());
  tmp.Release();
  v1::Calibration record;
  record.set_calibration_id(bundle->id);
  *record.mutable_create_time() = google::protobuf::util::TimeUtil::GetCurrentTime();
  record.set_version(bundle->version);
  *record.mutable_summary() = SummariseBundle(*bundle);
  record.set_job_id(job_id);
  INSPECT_RETURN_IF_ERROR(store_->PutCalibration(record));
  return record;
}

Status CalibrationStore::Activate(std::shared_ptr<const CalibrationBundle> bundle) {
  INSPECT_RETURN_IF_ERROR(store_->SetSetting(kActiveSetting, bundle->id));
  spdlog::info("calibration {} stored and active", bundle->id);
  std::lock_guard<std::mutex> lock(mu_);
  active_ = std::move(bundle);
  return Status::Ok();
}

StatusOr<v1::Calibration> CalibrationStore::Get(const std::string& calibration_id) const {
  const std::string active = active_id();
  std::string id = calibration_id;
  if (id.empty()) {
    if (active.empty()) return Status::NotFound("no calibration is active; run Calibrate");
    id = active;
  }
  INSPECT_ASSIGN_OR_RETURN(v1::Calibration c, store_->GetCalibration(id));
  c.set_active(id == active);
  return c;
}

StatusOr<std::vector<v1::Calibration>> CalibrationStore::List() const {
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::Calibration> list, store_->ListCalibrations());
  const std::string active = active_id();
  for (v1::Calibration& c : list) c.set_active(c.calibration_id() == active);
  return list;
}

}  // namespace inspection
