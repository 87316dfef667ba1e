// ProcedureRunner: instrument verification (server/procedures/verification_procedure.h) and what
// the rig's verification state does to later scans. A verification stores its record only when
// every measure has been scanned and evaluated: a cancelled or failed one stores nothing (the
// procedure removes its work folder and puts the specimen back however it ends).
#include <spdlog/spdlog.h>

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <cmath>

#include "server/jobs/procedure_runner.h"
#include "server/jobs/rig_verification.h"

namespace inspection {

std::string ProcedureRunner::ApplyVerification(DepthNoiseOptions* noise) {
  StatusOr<RigVerification> v = ReadRigVerification(*store_, calibrations_->active_id(), CurrentTimestamp());
  if (!v.ok()) {
    spdlog::warn("verification records not read, uncertainties with worst-case bounds: {}", v.status().ToString());
    return "verification unknown: " + v.status().message();
  }
  // The last full verification's characteristics apply while it is on record, also when an
  // interim check has since failed: the result then says so.
  if (v->full) noise->verified = VerifiedFrom(*v->full);
  return VerificationWarning(*v);
}

StatusOr<v1::JobResult> ProcedureRunner::RunVerify(const VerifyWork& work, const JobContext& context) {
  const std::string& job_id = context.job_id;
  VerificationPlan plan;
  plan.mode = work.mode;
  const std::string calibration_id = calibrations_->active_id();
  context.emit([&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_PREPARING);
    e.set_message(VerificationModeName(work.mode) + " verification on the material measures" +
                  (calibration_id.empty() ? " (uncalibrated)" : ", calibration " + calibration_id));
  });
  auto on_frame = [&](const ScanFrameEvent& f, const VerificationProgress& p) {
    context.emit([&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_ACQUIRING);
      FillFrameProgress(f, e.mutable_frame());
      const double done = p.index + (f.index + 1.0) / std::max(1, f.count);
      e.set_progress(0.95 * done / std::max(1, p.count));
      e.set_remaining_seconds(e.elapsed_seconds() / done * (p.count - done));
      e.set_message("measure " + std::to_string(p.index + 1) + " of " + std::to_string(p.count) + ": " + p.specimen);
    });
  };
  auto on_measure = [&](const VerificationProgress& p) {
    context.emit([&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_RECONSTRUCTING);
      e.set_progress(0.95 * (p.index + 1.0) / std::max(1, p.count));
      e.set_message(p.specimen + ": " + p.message);
    });
  };
  INSPECT_ASSIGN_OR_RETURN(VerificationRecord evaluated,
                           RunVerification(rig_->rig(), plan, store_->tmp_dir() / (job_id + ".verify"), on_frame,
                                           on_measure, *context.cancel));
  context.emit([&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_STORING);
    e.set_progress(0.97);
    e.set_message("verification record");
  });
  v1::VerificationRecord record = VerificationRecordProto(evaluated);
  record.set_verification_id(job_id);
  record.set_z_step_um(plan.z_step_um);
  record.set_calibration_id(calibration_id);
  *record.mutable_finish_time() = CurrentTimestamp();
  if (StatusOr<v1::Job> job = store_->GetJob(job_id); job.ok()) record.set_owner(job->owner());
  if (work.mode == VerificationMode::kInterim) {
    INSPECT_ASSIGN_OR_RETURN(std::vector<v1::VerificationRecord> full,
                             store_->ListVerifications(calibration_id, v1::VERIFICATION_MODE_FULL, 1));
    JudgeInterim(full.empty() ? nullptr : &full.front(), &record, record.finish_time());
  } else {
    record.set_state(v1::VERIFICATION_STATE_VERIFIED);
    using google::protobuf::util::TimeUtil;
    *record.mutable_next_full_due() =
        record.finish_time() + TimeUtil::SecondsToDuration(std::llround(work.interval_days * 86400.0));
  }
  if (context.cancel->load()) return Status::Cancelled("verification cancelled while storing");  // a cancel's last chance
  INSPECT_RETURN_IF_ERROR(store_->PutVerification(record));
  v1::JobResult result;
  result.set_calibration_id(calibration_id);
  *result.mutable_verification() = record;
  spdlog::info("job {}: {} verification: {}", job_id, VerificationModeName(work.mode),
               v1::VerificationState_Name(record.state()));
  return result;
}

}  // namespace inspection
