#include "server/calibration_store.h"

#include <google/protobuf/util/time_util.h>
#include <spdlog/spdlog.h>

#include "server/procedures/calibration_procedure.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {
CalibrationStep FromProto(v1::CalibrationStep s) {
  switch (s) {
    case v1::CALIBRATION_STEP_PROJECTOR_RESPONSE: return CalibrationStep::kProjectorResponse;
    case v1::CALIBRATION_STEP_GEOMETRY: return CalibrationStep::kGeometry;
    case v1::CALIBRATION_STEP_PSF: return CalibrationStep::kPsf;
    case v1::CALIBRATION_STEP_SCATTER_MATRIX: return CalibrationStep::kScatterMatrix;
    case v1::CALIBRATION_STEP_INTEGRAL_PSF: return CalibrationStep::kIntegralPsf;
    default: return CalibrationStep::kCameraResponse;
  }
}
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
  const std::string id = store_->GetSetting("active_calibration_id");
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

StatusOr<v1::Calibration> CalibrationStore::Run(const CalibrationContext& ctx) {
  CalibrationOptions options;
  for (int s : ctx.request->steps()) options.steps.push_back(FromProto(v1::CalibrationStep(s)));
  std::shared_ptr<const CalibrationBundle> previous = active();
  // A bundle from a camera or projector of another size cannot be extended: start afresh.
  if (previous && (previous->camera_size != ctx.rig->camera().frame_size() ||
                   previous->projector_size != ctx.rig->projector().resolution())) {
    previous.reset();
  }
  auto on_progress = [&](const CalibrationProgress& p) {
    const double per_step = 1.0 / std::max(1, p.step_count);
    const double within = p.item_count > 0 ? double(p.item) / p.item_count : 0.0;
    ctx.progress(p.step, per_step * (p.step_index + within), p.message);
  };
  INSPECT_ASSIGN_OR_RETURN(CalibrationBundle bundle,
                           RunCalibration(*ctx.rig, options, previous.get(), on_progress, *ctx.cancel));
  bundle.id = NewId("cal");
  const fs::path tmp = store_->tmp_dir() / (bundle.id + ".bundle");
  const fs::path dir = store_->calibrations_dir() / bundle.id;
  Status saved = bundle.Save(tmp);
  std::error_code ec;
  if (saved.ok()) {
    fs::rename(tmp, dir, ec);
    if (ec) saved = Status::Internal("cannot store calibration " + bundle.id + ": " + ec.message());
  }
  if (!saved.ok()) {
    fs::remove_all(tmp, ec);
    return saved;
  }
  v1::Calibration record;
  record.set_calibration_id(bundle.id);
  *record.mutable_create_time() = google::protobuf::util::TimeUtil::GetCurrentTime();
  record.set_version(bundle.version);
  *record.mutable_summary() = SummariseBundle(bundle);
  record.set_job_id(ctx.job_id);
  INSPECT_RETURN_IF_ERROR(store_->PutCalibration(record));
  INSPECT_RETURN_IF_ERROR(store_->SetSetting("active_calibration_id", bundle.id));
  {
    std::lock_guard<std::mutex> lock(mu_);
    active_ = std::make_shared<const CalibrationBundle>(std::move(bundle));
  }
  spdlog::info("calibration {} stored and active", record.calibration_id());
  return record;
}

}  // namespace inspection
