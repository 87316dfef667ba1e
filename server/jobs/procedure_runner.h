// ProcedureRunner: the server's JobRunner. Runs a job's work through server/procedures and
// publishes what it produced:
//  - scan: holds the rig, RunScan with the active calibration (thesis 3.1.2, 5, 6.2), stores
//    the stack as stack.zip and publishes the depth artifacts and ground truth; a scan that ran
//    a recipe also measures, judges, writes the HTML report and appends to the result feed;
//  - calibrate: holds the rig, RunCalibration carrying over the active bundle's other models
//    (thesis 4.3, 5.4.1), saves the new bundle and activates it;
//  - reconstruct: no rig; replays a stack folder through the SFF engine and publishes.
// Rig jobs move the rig Busy while they run and report their status to the RigController
// (device errors put it into Error). Called by the JobManager's workers; the JobManager runs
// one rig job at a time.
#pragma once

#include "server/storage/calibration_store.h"
#include "server/storage/data_store.h"
#include "server/jobs/job_runner.h"
#include "server/results/result_feed.h"
#include "server/jobs/rig_controller.h"
#include "core/metrology/depth_noise_model.h"
#include "core/sff/sff_options.h"

namespace inspection {

struct ScanFrameEvent;  // server/procedures/scan_procedure.h

// The FrameProgress of one frame a scan took (index, z, exposure, statistics), as every rig job
// that scans reports it; the job sets the phase, progress and message around it.
void FillFrameProgress(const ScanFrameEvent& f, v1::FrameProgress* fp);

// Whether a depth is interpolated through three focus samples (Gaussian, defocus parabola), so a
// frame's stage error reaches it through the three-point sensitivities, or taken from the
// maximum's frame (maximum, line fit) with that frame's error in full (DepthNoiseOptions).
bool ThreePointPeak(DepthInterpolation interpolation);

class ProcedureRunner final : public JobRunner {
 public:
  // `results` receives the inspection result of every scan that ran a recipe.
  // pipeline: how reconstructions write their artifacts (artifact_threads, sequential).
  ProcedureRunner(DataStore* store, RigController* rig, CalibrationStore* calibrations, ResultFeed* results,
                  const ReconstructPipelineOptions& pipeline = {})
      : store_(store), rig_(rig), calibrations_(calibrations), results_(results), pipeline_(pipeline) {}

  StatusOr<v1::JobResult> Run(const JobWork& work, const JobContext& context) override;

 private:
  StatusOr<v1::JobResult> RunScan(const ScanWork& work, const JobContext& context);
  StatusOr<v1::JobResult> RunCalibrate(const CalibrateWork& work, const JobContext& context);
  StatusOr<v1::JobResult> RunReconstruct(const ReconstructWork& work, const JobContext& context);
  StatusOr<v1::JobResult> RunStudy(const StudyWork& work, const JobContext& context);  // procedure_runner_study.cc
  // The newest Type-1 study of the inspection's recipe version marks its measurements that were
  // found not capable (MeasurementResult.capability_warning).
  void ApplyStudyWarnings(v1::InspectionResult* inspection);
  // procedure_runner_verification.cc: a verification on the material measures, its record stored
  // with the active calibration when it succeeds.
  StatusOr<v1::JobResult> RunVerify(const VerifyWork& work, const JobContext& context);
  // The rig's verification under the active calibration (rig_verification.h): the last full
  // verification's characteristics into `noise` (the uncertainty model's verified terms), and
  // the warning a result made now carries (empty while verified). Never fatal: a store that
  // cannot be read leaves the worst-case bounds and the warning says so.
  std::string ApplyVerification(DepthNoiseOptions* noise);

  DataStore* store_;
  RigController* rig_;
  CalibrationStore* calibrations_;
  ResultFeed* results_;
  ReconstructPipelineOptions pipeline_;
  int artifact_threads() const { return pipeline_.sequential ? 1 : pipeline_.artifact_threads; }
};

}  // namespace inspection
