// JobWork helpers: the job kind of a work item, what its queued job shows, its log line.
#include "server/jobs/job_work.h"

#include <sstream>

namespace inspection {

namespace {
template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
}  // namespace

v1::JobKind KindOf(const JobWork& work) {
  return std::visit(Overloaded{[](const ScanWork&) { return v1::JOB_KIND_SCAN; },
                               [](const CalibrateWork&) { return v1::JOB_KIND_CALIBRATE; },
                               [](const ReconstructWork&) { return v1::JOB_KIND_RECONSTRUCT; },
                               [](const StudyWork&) { return v1::JOB_KIND_STUDY; },
                               [](const VerifyWork&) { return v1::JOB_KIND_VERIFY; }},
                    work);
}

void FillQueuedJob(const JobWork& work, v1::Job* job) {
  if (const auto* w = std::get_if<ScanWork>(&work)) {
    job->set_part_id(w->part_id);
    job->set_station(w->station);
    if (w->recipe) {
      job->set_recipe_id(w->recipe->recipe.recipe_id());
      job->set_recipe_version(w->recipe->recipe.version());
    }
  }
  if (const auto* w = std::get_if<StudyWork>(&work); w && w->scan.recipe) {
    job->set_part_id(w->scan.part_id);
    job->set_recipe_id(w->scan.recipe->recipe.recipe_id());
    job->set_recipe_version(w->scan.recipe->recipe.version());
  }
  if (const auto* w = std::get_if<ReconstructWork>(&work); w && !w->source_scan_id.empty()) {
    job->mutable_result()->set_scan_id(w->source_scan_id);
  }
}

std::string DescribeWork(const JobWork& work) {
  std::ostringstream s;
  std::visit(Overloaded{[&](const ScanWork& w) {
                          if (const auto& z = w.plan.z_range_search) {
                            s << "scan with automatic z range (window " << z->window_start_um << ".."
                              << z->window_end_um << " um, coarse step " << z->coarse_step_um << " um, step "
                              << w.plan.z_step_um << " um)";
                          } else {
                            s << "scan of " << w.plan.z_um.size() << " frames";
                          }
                          if (!w.plan.z_um.empty()) {
                            s << ", z " << w.plan.z_um.front() << ".." << w.plan.z_um.back() << " um";
                          }
                          s << ", " << IlluminationModeName(w.plan.mode, w.plan.params.hdr_exposures);
                          if (w.recipe) {
                            s << ", recipe " << w.recipe->recipe.recipe_id() << " v" << w.recipe->recipe.version();
                          }
                          if (!w.part_id.empty()) s << ", part " << w.part_id;
                        },
                        [&](const CalibrateWork& w) {
                          s << "calibration of ";
                          if (w.options.steps.empty()) s << "all steps";
                          for (size_t i = 0; i < w.options.steps.size(); ++i) {
                            s << (i ? ", " : "") << CalibrationStepName(w.options.steps[i]);
                          }
                        },
                        [&](const ReconstructWork& w) {
                          s << "reconstruction of "
                            << (w.source_scan_id.empty() ? "an uploaded stack" : "scan " + w.source_scan_id);
                        },
                        [&](const StudyWork& w) {
                          s << "type-1 study of " << w.repeats << " repeats";
                          if (w.scan.recipe) {
                            s << ", recipe " << w.scan.recipe->recipe.recipe_id() << " v"
                              << w.scan.recipe->recipe.version();
                          }
                        },
                        [&](const VerifyWork& w) { s << VerificationModeName(w.mode) << " verification"; }},
             work);
  return s.str();
}

}  // namespace inspection
