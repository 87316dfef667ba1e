// The rig's verification records and state (rig_verification.h).
#include "server/jobs/rig_verification.h"

#include <google/protobuf/util/time_util.h>

#include <cmath>
#include <cstdio>

namespace inspection {

namespace {

void AddCharacteristic(v1::VerificationRecord* out, const char* name, const char* unit, const CharacteristicEstimate& e) {
  v1::VerificationCharacteristic* c = out->add_characteristics();
  c->set_name(name);
  c->set_unit(unit);
  c->set_value(e.value);
  c->set_standard_uncertainty(e.standard_uncertainty);
  c->set_expanded_uncertainty(2.0 * e.standard_uncertainty);
}

CharacteristicEstimate EstimateOf(const v1::VerificationRecord& r, const std::string& name) {
  CharacteristicEstimate e;
  if (const v1::VerificationCharacteristic* c = FindCharacteristic(r, name)) {
    e.value = c->value();
    e.standard_uncertainty = c->standard_uncertainty();
  }
  return e;
}

int64_t Nanos(const google::protobuf::Timestamp& t) { return t.seconds() * 1000000000LL + t.nanos(); }

std::string Fixed(double v, int digits) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", digits, v);
  return text;
}

}  // namespace

double FullIntervalDays(const v1::VerificationRecord& full) {
  if (!full.has_next_full_due()) return kFullVerificationIntervalDays;  // a record of an older inspectd
  return DaysBetween(full.finish_time(), full.next_full_due());
}

google::protobuf::Timestamp CurrentTimestamp() {
  return google::protobuf::util::TimeUtil::NanosecondsToTimestamp(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

double DaysBetween(const google::protobuf::Timestamp& a, const google::protobuf::Timestamp& b) {
  return double(Nanos(b) - Nanos(a)) * 1e-9 / 86400.0;
}

v1::VerificationRecord VerificationRecordProto(const VerificationRecord& r) {
  v1::VerificationRecord out;
  const bool full = r.mode == VerificationMode::kFull;
  out.set_mode(full ? v1::VERIFICATION_MODE_FULL : v1::VERIFICATION_MODE_INTERIM);
  out.set_scans(r.scans);
  AddCharacteristic(&out, "N_M", "um", r.noise_um);
  AddCharacteristic(&out, "z_FLT", "um", r.flatness_um);
  AddCharacteristic(&out, "alpha_z", "", r.alpha_z);
  if (full) {
    AddCharacteristic(&out, "l_z", "um", r.l_z_um);
    AddCharacteristic(&out, "alpha_x", "", r.alpha_x);
    AddCharacteristic(&out, "alpha_y", "", r.alpha_y);
    AddCharacteristic(&out, "W_R", "um", r.w_r_um);
  }
  for (const VerificationStep& s : r.steps) {
    v1::VerificationStepPoint* p = out.add_steps();
    p->set_specimen(s.specimen);
    p->set_certified_um(s.point.certified_um);
    p->set_certified_u_um(s.point.certified_u_um);
    p->set_measured_um(s.point.measured_um);
    p->set_measured_u_um(s.point.measured_u_um);
  }
  for (const VerificationSinusoid& s : r.sinusoids) {
    v1::VerificationSinusoidPoint* p = out.add_sinusoids();
    p->set_specimen(s.specimen);
    p->set_period_um(s.point.period_um);
    p->set_certified_amplitude_um(s.point.certified_amplitude_um);
    p->set_measured_amplitude_um(s.point.measured_amplitude_um);
    p->set_measured_amplitude_u_um(s.point.measured_amplitude_u_um);
  }
  return out;
}

VerificationRecord VerificationRecordFromProto(const v1::VerificationRecord& p) {
  VerificationRecord r;
  r.mode = p.mode() == v1::VERIFICATION_MODE_INTERIM ? VerificationMode::kInterim : VerificationMode::kFull;
  r.scans = p.scans();
  r.noise_um = EstimateOf(p, "N_M");
  r.flatness_um = EstimateOf(p, "z_FLT");
  r.alpha_z = EstimateOf(p, "alpha_z");
  r.l_z_um = EstimateOf(p, "l_z");
  r.alpha_x = EstimateOf(p, "alpha_x");
  r.alpha_y = EstimateOf(p, "alpha_y");
  r.w_r_um = EstimateOf(p, "W_R");
  for (const v1::VerificationStepPoint& s : p.steps()) {
    VerificationStep step;
    step.specimen = s.specimen();
    step.point.certified_um = s.certified_um();
    step.point.certified_u_um = s.certified_u_um();
    step.point.measured_um = s.measured_um();
    step.point.measured_u_um = s.measured_u_um();
    r.steps.push_back(std::move(step));
  }
  for (const v1::VerificationSinusoidPoint& s : p.sinusoids()) {
    VerificationSinusoid sin;
    sin.specimen = s.specimen();
    sin.point.period_um = s.period_um();
    sin.point.certified_amplitude_um = s.certified_amplitude_um();
    sin.point.measured_amplitude_um = s.measured_amplitude_um();
    sin.point.measured_amplitude_u_um = s.measured_amplitude_u_um();
    r.sinusoids.push_back(std::move(sin));
  }
  return r;
}

const v1::VerificationCharacteristic* FindCharacteristic(const v1::VerificationRecord& record,
                                                         const std::string& name) {
  for (const v1::VerificationCharacteristic& c : record.characteristics()) {
    if (c.name() == name) return &c;
  }
  return nullptr;
}

void JudgeInterim(const v1::VerificationRecord* full, v1::VerificationRecord* interim,
                  const google::protobuf::Timestamp& now) {
  const VerificationRecord check = VerificationRecordFromProto(*interim);
  InterimCheckResult result;
  if (full != nullptr) {
    const VerificationRecord limits = VerificationRecordFromProto(*full);
    result = EvaluateInterimCheck(&limits, check, DaysBetween(full->finish_time(), now), FullIntervalDays(*full));
    interim->set_full_verification_id(full->verification_id());
  } else {
    result = EvaluateInterimCheck(nullptr, check, 0.0, kFullVerificationIntervalDays);
  }
  switch (result.state) {
    case VerificationState::kVerified:
      interim->set_state(v1::VERIFICATION_STATE_VERIFIED);
      break;
    case VerificationState::kDue:
      interim->set_state(v1::VERIFICATION_STATE_DUE);
      break;
    case VerificationState::kFailed:
      interim->set_state(v1::VERIFICATION_STATE_FAILED);
      break;
  }
  interim->clear_findings();
  for (const std::string& f : result.findings) interim->add_findings(f);
}

StatusOr<RigVerification> ReadRigVerification(DataStore& store, const std::string& calibration_id,
                                              const google::protobuf::Timestamp& now) {
  RigVerification out;
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::VerificationRecord> full,
                           store.ListVerifications(calibration_id, v1::VERIFICATION_MODE_FULL, 1));
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::VerificationRecord> interim,
                           store.ListVerifications(calibration_id, v1::VERIFICATION_MODE_INTERIM, 1));
  if (!full.empty()) out.full = std::move(full.front());
  if (!interim.empty()) out.interim = std::move(interim.front());
  const std::string under = calibration_id.empty() ? "the uncalibrated rig" : "calibration " + calibration_id;
  if (!out.full) {
    out.state = v1::VERIFICATION_STATE_DUE;
    out.detail = "no full verification under " + under;
    return out;
  }
  const double age_days = DaysBetween(out.full->finish_time(), now);
  const double interval_days = FullIntervalDays(*out.full);
  if (age_days > interval_days) {
    out.state = v1::VERIFICATION_STATE_DUE;
    out.detail = "full verification " + out.full->verification_id() + " is " + Fixed(age_days, 1) +
                 " days old (interval " + Fixed(interval_days, interval_days < 10 ? 1 : 0) + " days)";
    return out;
  }
  // An interim check decides until the next full verification replaces its limits.
  if (out.interim && Nanos(out.interim->finish_time()) > Nanos(out.full->finish_time()) &&
      out.interim->state() != v1::VERIFICATION_STATE_VERIFIED) {
    out.state = out.interim->state();
    std::string findings;
    for (const std::string& f : out.interim->findings()) findings += (findings.empty() ? "" : "; ") + f;
    out.detail = "interim check " + out.interim->verification_id() + ": " + findings;
    return out;
  }
  out.state = v1::VERIFICATION_STATE_VERIFIED;
  return out;
}

VerifiedCharacteristics VerifiedFrom(const v1::VerificationRecord& full) {
  VerifiedCharacteristics v;
  const v1::VerificationCharacteristic* alpha = FindCharacteristic(full, "alpha_z");
  const v1::VerificationCharacteristic* lz = FindCharacteristic(full, "l_z");
  const v1::VerificationCharacteristic* nm = FindCharacteristic(full, "N_M");
  const v1::VerificationCharacteristic* flt = FindCharacteristic(full, "z_FLT");
  if (alpha) {
    v.amplification = alpha->value();
    v.amplification_u = alpha->standard_uncertainty();
  }
  if (lz) v.linearity_deviation_um = lz->value() + 2.0 * lz->standard_uncertainty();
  if (lz && full.z_step_um() > 0.0) v.linearity_step_um = full.z_step_um();
  if (nm) v.noise_um = nm->value();
  if (flt) v.flatness_um = flt->value();
  if (!v.Validate().ok()) return {};
  return v;
}

std::string VerificationWarning(const RigVerification& v) {
  switch (v.state) {
    case v1::VERIFICATION_STATE_DUE:
      return "verification due: " + v.detail;
    case v1::VERIFICATION_STATE_FAILED:
      return "verification failed: " + v.detail;
    default:
      return "";
  }
}

}  // namespace inspection
