// RunVerification: the material measures scanned one after another and evaluated with
// core/metrology/verification.h (ISO 25178-700 procedure, ISO 25178-600 characteristics).
#include "server/procedures/verification_procedure.h"
#include "server/procedures/work_folder.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace inspection {
namespace fs = std::filesystem;

namespace {

// Puts the rig's specimen back when the verification ends, however it ends.
class SpecimenReset {
 public:
  explicit SpecimenReset(SimulationControl* sim) : sim_(sim), name_(sim ? sim->specimen() : "") {}
  ~SpecimenReset() {
    if (sim_ == nullptr) return;
    const Status s = sim_->SetSpecimen(name_);
    if (!s.ok()) spdlog::warn("verification: specimen {} could not be put back: {}", name_, s.ToString());
  }
  SpecimenReset(const SpecimenReset&) = delete;
  SpecimenReset& operator=(const SpecimenReset&) = delete;

 private:
  SimulationControl* sim_;
  std::string name_;
};

std::string Fmt(const char* f, double a, double b) {
  char text[128];
  std::snprintf(text, sizeof text, f, a, b);
  return text;
}

}  // namespace

std::string VerificationModeName(VerificationMode mode) { return mode == VerificationMode::kFull ? "full" : "interim"; }

Status VerificationPlan::Validate() const {
  if (!(z_step_um > 0.0 && z_step_um <= 50.0)) return Status::InvalidArgument("z_step_um must be in (0, 50]");
  if (!(margin_um >= 0.0 && margin_um <= 500.0)) return Status::InvalidArgument("margin_um must be in [0, 500]");
  if (sff.window_px < 3 || sff.window_px > 31 || sff.window_px % 2 == 0) {
    return Status::InvalidArgument("sff.window_px must be odd, 3..31");
  }
  if (!(interim_step_um > 0.0)) return Status::InvalidArgument("interim_step_um must be > 0");
  return Status::Ok();
}

StatusOr<VerificationRecord> RunVerification(
    Rig& rig, const VerificationPlan& plan, const fs::path& work_dir,
    const std::function<void(const ScanFrameEvent&, const VerificationProgress&)>& on_frame,
    const std::function<void(const VerificationProgress&)>& on_measure, const std::atomic<bool>& cancel) {
  INSPECT_RETURN_IF_ERROR(plan.Validate());
  SimulationControl* sim = rig.simulation();
  const std::vector<MaterialMeasure> measures = sim != nullptr ? sim->material_measures() : std::vector<MaterialMeasure>{};
  if (measures.empty()) {
    return Status::FailedPrecondition(
        "material_measures: the rig offers no ISO 25178-70 material measures (AFL, PGR, ASG, ACG) to verify with");
  }
  const MaterialMeasure* flat = nullptr;
  const MaterialMeasure* grating = nullptr;
  std::vector<const MaterialMeasure*> steps, sinusoids;
  for (const MaterialMeasure& m : measures) {
    switch (m.type) {
      case MaterialMeasureType::kAfl:
        if (flat == nullptr) flat = &m;
        break;
      case MaterialMeasureType::kPgr:
        steps.push_back(&m);
        break;
      case MaterialMeasureType::kAsg:
        sinusoids.push_back(&m);
        break;
      case MaterialMeasureType::kAcg:
        if (grating == nullptr) grating = &m;
        break;
    }
  }
  const bool full = plan.mode == VerificationMode::kFull;
  if (flat == nullptr) return Status::FailedPrecondition("material_measures: no optical flat (AFL)");
  if (steps.size() < (full ? 2u : 1u)) {
    return Status::FailedPrecondition(std::string("material_measures: ") + (full ? "fewer than two" : "no") +
                                      " step-height measures (PGR)");
  }
  if (full && grating == nullptr) return Status::FailedPrecondition("material_measures: no cross grating (ACG)");
  if (full && sinusoids.size() < 2) {
    return Status::FailedPrecondition("material_measures: fewer than two sinusoidal measures (ASG)");
  }
  if (!full) {
    const double want = plan.interim_step_um;
    const MaterialMeasure* nearest = *std::min_element(steps.begin(), steps.end(), [&](auto* a, auto* b) {
      return std::abs(a->height_um - want) < std::abs(b->height_um - want);
    });
    steps = {nearest};
    sinusoids.clear();
    grating = nullptr;
  }

  // The scan list: the flat twice, then the steps, the grating, the sinusoids.
  std::vector<const MaterialMeasure*> order = {flat, flat};
  order.insert(order.end(), steps.begin(), steps.end());
  if (grating != nullptr) order.push_back(grating);
  order.insert(order.end(), sinusoids.begin(), sinusoids.end());

  SpecimenReset reset(sim);
  WorkFolder work_folder(work_dir);
  INSPECT_RETURN_IF_ERROR(work_folder.Create());

  const int window = plan.sff.window_px;
  const double px_um = rig.pixel_size_um();
  VerificationRecord record;
  record.mode = plan.mode;
  cv::Mat flat_maps[2];
  std::vector<ResponsePoint> response;
  std::vector<TransferPoint> transfer;
  const int count = int(order.size());
  for (int i = 0; i < count; ++i) {
    const MaterialMeasure& m = *order[i];
    if (cancel.load()) return Status::Cancelled("verification cancelled before scan " + std::to_string(i + 1));
    const std::string where = "material measure " + m.specimen + ": ";
    if (Status s = sim->SetSpecimen(m.specimen); !s.ok()) {
      return Status::FailedPrecondition(where + "cannot be put under the objective: " + s.message());
    }
    const ScanDefaults d = rig.scan_defaults();
    // The measure's heights are the defaults' range without its 4-step margin.
    const double lo = d.z_start_um + 4.0 * d.z_step_um, hi = d.z_end_um - 4.0 * d.z_step_um;
    INSPECT_ASSIGN_OR_RETURN(
        ScanPlan scan, MakeScanPlan(std::max(0.0, std::floor(lo - plan.margin_um)), hi + plan.margin_um, plan.z_step_um,
                                    d.exposure_us, rig.stage()));
    scan.sff = plan.sff;
    const VerificationProgress progress{i, count, m.specimen, ""};
    const fs::path dir = work_dir / ("scan-" + std::to_string(i + 1));
    StatusOr<ScanOutcome> scanned = RunScan(
        rig, scan, dir, [&](const ScanFrameEvent& e) { if (on_frame) on_frame(e, progress); }, cancel);
    std::error_code ec;
    fs::remove_all(dir, ec);  // the scan's frames are not kept: only its evaluation is
    if (!scanned.ok()) {
      if (scanned.status().code() == StatusCode::kCancelled) return scanned.status();
      return Status(scanned.status().code(), where + scanned.status().message());
    }
    ++record.scans;
    const cv::Mat& z = scanned->depth.depth_um;
    std::string message;
    switch (m.type) {
      case MaterialMeasureType::kAfl:
        flat_maps[i] = z.clone();
        message = "flat, repeat " + std::to_string(i + 1);
        break;
      case MaterialMeasureType::kPgr: {
        StatusOr<CharacteristicEstimate> depth = GrooveDepth(z, window);
        if (!depth.ok()) return Status(depth.status().code(), where + depth.status().message());
        // GrooveDepth's u is the maps' noise only. Every frame's z is also off by up to +-r
        // (the stage's repeatability, uniform), and the groove's bottom and its lands peak in
        // different frames: each height takes its own frames' errors through the three-point
        // interpolation (rms sensitivity ~0.7, core/metrology/depth_noise_model.h component 3),
        // so the step carries sqrt(2) 0.7 r / sqrt(3) ~ r / sqrt(3) more, common to all its
        // pixels (on the simulated rig, r = 0.1 um: 0.058 um, the scatter repeated scans of one
        // step show; without it an interim check on an unchanged rig failed at 0.13 um).
        const double u_stage = rig.stage().repeatability_um() / std::sqrt(3.0);
        ResponsePoint p{m.height_um, m.height_u_um, depth->value, std::hypot(depth->standard_uncertainty, u_stage)};
        record.steps.push_back({m.specimen, p});
        response.push_back(p);
        message = Fmt("step %.4g um measured %.5g um", m.height_um, depth->value);
        break;
      }
      case MaterialMeasureType::kAcg: {
        StatusOr<CharacteristicEstimate> ax = LateralAmplification(z, px_um, m.period_um, 0);
        StatusOr<CharacteristicEstimate> ay = LateralAmplification(z, px_um, m.period_um, 1);
        if (!ax.ok()) return Status(ax.status().code(), where + "x: " + ax.status().message());
        if (!ay.ok()) return Status(ay.status().code(), where + "y: " + ay.status().message());
        // The certificate's pitch uncertainty adds relatively.
        const double rel = m.period_u_um / m.period_um;
        record.alpha_x = {ax->value, std::hypot(ax->standard_uncertainty, ax->value * rel)};
        record.alpha_y = {ay->value, std::hypot(ay->standard_uncertainty, ay->value * rel)};
        message = Fmt("grating: alpha_x %.5f, alpha_y %.5f", ax->value, ay->value);
        break;
      }
      case MaterialMeasureType::kAsg: {
        StatusOr<CharacteristicEstimate> a = SinusoidFundamentalAlongX(z, px_um, m.period_um, window);
        if (!a.ok()) return Status(a.status().code(), where + a.status().message());
        TransferPoint p{m.period_um, m.height_um, a->value, a->standard_uncertainty};
        record.sinusoids.push_back({m.specimen, p});
        transfer.push_back(p);
        message = Fmt("sinusoid period %.4g um: amplitude transfer %.3f", m.period_um, a->value / m.height_um);
        break;
      }
    }
    if (i == 1) {
      INSPECT_ASSIGN_OR_RETURN(record.noise_um, MeasurementNoise(flat_maps[0], flat_maps[1], window));
      INSPECT_ASSIGN_OR_RETURN(record.flatness_um, FlatnessDeviation(flat_maps[0], flat_maps[1], window));
      message = Fmt("flat: N_M %.4g um, z_FLT %.4g um", record.noise_um.value, record.flatness_um.value);
    }
    if (on_measure) on_measure({i, count, m.specimen, message});
  }

  if (full) {
    INSPECT_ASSIGN_OR_RETURN(AmplificationLinearity al, AmplificationAndLinearity(response));
    record.alpha_z = al.alpha_z;
    record.l_z_um = al.l_z_um;
    StatusOr<CharacteristicEstimate> wr = TopographicSpatialResolution(transfer);
    if (!wr.ok()) return Status(wr.status().code(), "material_measures (ASG): " + wr.status().message());
    record.w_r_um = *wr;
  } else {
    // One step: its measured / certified height (the offset of the response line unknown).
    const ResponsePoint& p = response.front();
    const double a = p.measured_um / p.certified_um;
    record.alpha_z = {a, std::hypot(p.measured_u_um, a * p.certified_u_um) / p.certified_um};
  }
  return record;
}

std::string VerificationStateName(VerificationState state) {
  switch (state) {
    case VerificationState::kVerified:
      return "verified";
    case VerificationState::kDue:
      return "verification due";
    case VerificationState::kFailed:
      return "verification failed";
  }
  return "verification due";
}

InterimCheckResult EvaluateInterimCheck(const VerificationRecord* full, const VerificationRecord& interim,
                                        double full_age_days, double full_interval_days) {
  InterimCheckResult out;
  if (full == nullptr || full->mode != VerificationMode::kFull) {
    out.state = VerificationState::kDue;
    out.findings.push_back("no full verification on record");
    return out;
  }
  auto limit = [](const CharacteristicEstimate& a, const CharacteristicEstimate& b) {
    return 2.0 * std::hypot(a.standard_uncertainty, b.standard_uncertainty);
  };
  auto above = [&](const char* name, const CharacteristicEstimate& now, const CharacteristicEstimate& then) {
    const double l = limit(now, then);
    if (now.value > then.value + l) {
      char text[200];
      std::snprintf(text, sizeof text, "%s %.4g um exceeds the full verification's %.4g um by more than U %.3g um",
                    name, now.value, then.value, l);
      out.findings.push_back(text);
    }
  };
  above("N_M", interim.noise_um, full->noise_um);
  above("z_FLT", interim.flatness_um, full->flatness_um);
  for (const VerificationStep& step : interim.steps) {
    const VerificationStep* then = nullptr;
    for (const VerificationStep& f : full->steps) {
      if (f.specimen == step.specimen) then = &f;
    }
    if (then == nullptr) {
      out.findings.push_back("step " + step.specimen + ": not in the full verification");
      continue;
    }
    const double l = 2.0 * std::hypot(step.point.measured_u_um, then->point.measured_u_um);
    const double d = step.point.measured_um - then->point.measured_um;
    if (std::abs(d) > l) {
      char text[200];
      std::snprintf(text, sizeof text, "step %s: %.5g um, %+.3g um from the full verification's (U %.3g um)",
                    step.specimen.c_str(), step.point.measured_um, d, l);
      out.findings.push_back(text);
    }
  }
  if (!out.findings.empty()) {
    out.state = VerificationState::kFailed;
  } else if (full_interval_days > 0.0 && full_age_days > full_interval_days) {
    out.state = VerificationState::kDue;
    out.findings.push_back("the last full verification is older than its interval");
  }
  return out;
}

}  // namespace inspection
