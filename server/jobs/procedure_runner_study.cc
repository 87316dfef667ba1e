// ProcedureRunner: Type-1 gauge studies (server/procedures/type1_study_procedure.h) and the
// capability warnings they put on later verdicts. A study stores its record only when every
// repeat has been measured and its report published: a cancelled or failed study leaves no study
// row and no artifact (the publisher's work folder goes with it).
#include <google/protobuf/util/time_util.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "server/jobs/procedure_runner.h"
#include "server/procedures/type1_study_procedure.h"
#include "server/results/inspection_result.h"
#include "server/results/result_publisher.h"
#include "server/results/study_report.h"
#include "server/results/study_result.h"

namespace inspection {

namespace {

google::protobuf::Timestamp NowTimestamp() {
  return google::protobuf::util::TimeUtil::NanosecondsToTimestamp(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

}  // namespace

void ProcedureRunner::ApplyStudyWarnings(v1::InspectionResult* inspection) {
  StatusOr<std::vector<v1::Study>> studies = store_->ListStudies(inspection->recipe_id(), 50);
  if (!studies.ok()) {
    spdlog::warn("recipe {}: studies not read, verdicts without capability check: {}", inspection->recipe_id(),
                 studies.status().ToString());
    return;
  }
  for (const v1::Study& s : *studies) {  // newest first
    if (s.recipe_version() != inspection->recipe_version()) continue;
    ApplyCapabilityWarnings(s, inspection);
    return;
  }
}

StatusOr<v1::JobResult> ProcedureRunner::RunStudy(const StudyWork& work, const JobContext& context) {
  const std::string& job_id = context.job_id;
  const RecipeRun& run = *work.scan.recipe;
  Type1StudyPlan plan;
  plan.scan = work.scan.plan;
  plan.scan.calibration_id = calibrations_->active_id();
  const std::shared_ptr<const CalibrationBundle> bundle = calibrations_->active();
  plan.repeats = work.repeats;
  plan.reposition_xy_um = work.reposition_xy_um;
  plan.reposition_z_um = work.reposition_z_um;
  plan.seed = work.seed;
  context.emit([&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_PREPARING);
    e.set_message("type-1 study: " + std::to_string(work.repeats) + " scans of recipe " + run.recipe.recipe_id() +
                  " v" + std::to_string(run.recipe.version()));
  });

  std::vector<v1::InspectionResult> repeats;
  // The rig's last full verification, read once for every repeat (rig_verification.h).
  DepthNoiseOptions verified;
  const std::string verification_warning = ApplyVerification(&verified);
  auto measure = [&](int, const ScanOutcome& o) -> Status {
    DepthNoiseOptions noise;
    noise.window_px = plan.scan.sff.window_px;
    for (const StackFrame& f : o.manifest.frames) noise.z_positions_um.push_back(f.z_um);
    noise.stage_repeatability_um = rig_->rig().stage().repeatability_um();
    if (bundle && bundle->z_linearity) noise.linearity = *bundle->z_linearity;
    noise.three_point_peak = ThreePointPeak(plan.scan.sff.interpolation);
    noise.verified = verified.verified;
    repeats.push_back(Inspect(run, o.depth, o.manifest.pixel_size_um, noise, work.scan.part_id, work.scan.station));
    return Status::Ok();
  };
  auto on_frame = [&](const ScanFrameEvent& f, int repeat) {
    context.emit([&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_ACQUIRING);
      FillFrameProgress(f, e.mutable_frame());
      const double done = repeat + (f.index + 1.0) / std::max(1, f.count);
      e.set_progress(0.95 * done / plan.repeats);
      e.set_remaining_seconds(e.elapsed_seconds() / done * (plan.repeats - done));
      e.set_message("repeat " + std::to_string(repeat + 1) + " of " + std::to_string(plan.repeats));
    });
  };
  auto on_repeat = [&](const Type1StudyProgress& p) {
    std::string values;
    for (const v1::MeasurementResult& m : repeats.back().measurements()) {
      char one[160];
      std::snprintf(one, sizeof one, "%s%s %.6g %s", values.empty() ? "" : ", ", m.name().c_str(), m.value(),
                    m.unit().c_str());
      values += one;
    }
    context.emit([&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_RECONSTRUCTING);
      e.set_progress(0.95 * (p.repeat + 1.0) / p.repeats);
      e.set_message(p.message + ": " + values);
    });
  };
  INSPECT_ASSIGN_OR_RETURN(Type1StudyScans scans,
                           RunType1StudyScans(rig_->rig(), plan, store_->tmp_dir() / (job_id + ".study"), on_frame,
                                              on_repeat, measure, *context.cancel, bundle.get()));
  context.emit([&](v1::JobEvent& e) {
    e.set_phase(v1::JOB_PHASE_STORING);
    e.set_progress(0.96);
    e.set_message("capability figures and the study report");
  });

  google::protobuf::Map<std::string, double> references(work.reference_values.begin(), work.reference_values.end());
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::MeasurementCapability> capabilities,
                           StudyCapabilities(run.recipe, references, repeats));
  v1::Study study;
  study.set_study_id(job_id);
  study.set_recipe_id(run.recipe.recipe_id());
  study.set_recipe_version(run.recipe.version());
  study.set_part_id(work.scan.part_id);
  study.set_repeats(plan.repeats);
  study.set_calibration_id(plan.scan.calibration_id);
  bool capable = true;
  for (v1::MeasurementCapability& c : capabilities) {
    capable = capable && c.capable();
    *study.add_measurements() = std::move(c);
  }
  study.set_capable(capable);
  study.set_repositioning(scans.repositioning + work.repositioning_note);
  study.set_verification_warning(verification_warning);
  if (StatusOr<v1::Job> job = store_->GetJob(job_id); job.ok()) study.set_owner(job->owner());
  *study.mutable_finish_time() = NowTimestamp();

  INSPECT_ASSIGN_OR_RETURN(ResultPublisher publisher, ResultPublisher::Create(store_, job_id, artifact_threads()));
  INSPECT_ASSIGN_OR_RETURN(std::string html, RenderStudyReport(study, run.recipe.description()));
  INSPECT_RETURN_IF_ERROR(publisher.WriteBytes(v1::ARTIFACT_KIND_REPORT_HTML, "study_report.html", html));
  if (context.cancel->load()) return Status::Cancelled("study cancelled while storing");  // a cancel's last chance
  v1::JobResult result;
  result.set_calibration_id(plan.scan.calibration_id);
  INSPECT_RETURN_IF_ERROR(publisher.Publish(&result));
  for (const v1::Artifact& a : result.artifacts()) {
    if (a.kind() == v1::ARTIFACT_KIND_REPORT_HTML) study.set_report_artifact_id(a.artifact_id());
  }
  INSPECT_RETURN_IF_ERROR(store_->PutStudy(study));
  *result.mutable_study() = study;
  spdlog::info("job {}: type-1 study of recipe {} v{}: {}", job_id, study.recipe_id(), study.recipe_version(),
               capable ? "capable" : "not capable");
  return result;
}

}  // namespace inspection
