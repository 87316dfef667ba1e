// ProcedureRunner: scan, calibrate and reconstruct jobs through server/procedures, with their
// progress events and their results published into the data store.
#include "server/jobs/procedure_runner.h"

#include <google/protobuf/util/time_util.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "core/io/depth_export.h"
#include "core/io/stack.h"
#include "core/sff/stack_halo.h"
#include "server/jobs/result_proto.h"
#include "server/procedures/z_range_search.h"
#include "server/results/inspection_report.h"
#include "server/results/result_publisher.h"
#include "server/storage/owned_folder.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};

// Runs a rig job holding the rig exclusively, with the rig Busy meanwhile; the job's status
// then moves the rig back to Ready, or to Error on a device failure.
template <typename Job>
StatusOr<v1::JobResult> OnRig(RigController* rig, Job&& job) {
  auto rig_lock = rig->Acquire();
  rig->SetBusy(true);
  StatusOr<v1::JobResult> result = job();
  rig->ReportJobStatus(result.ok() ? Status::Ok() : result.status());
  return result;
}

// A per-frame progress event: frame i of n with its statistics; the frames make up 90 % of a
// job, the remaining time is extrapolated from the frame rate so far.
void FillFrameEvent(v1::JobPhase phase, int index, int count, double z_um, double exposure_us,
                    const FrameStatistics& st, v1::JobEvent* e) {
  e->set_phase(phase);
  v1::FrameProgress* fp = e->mutable_frame();
  fp->set_frame_index(index);
  fp->set_frame_count(count);
  fp->set_z_um(z_um);
  fp->set_exposure_us(exposure_us);
  fp->set_acquisition_index(index);  // scans with extra captures overwrite both
  fp->set_stack_frame(true);
  fp->mutable_statistics()->set_mean_grey(st.mean_grey);
  fp->mutable_statistics()->set_stddev_grey(st.stddev_grey);
  fp->mutable_statistics()->set_saturated_percent(st.saturated_percent);
  fp->mutable_statistics()->set_underexposed_percent(st.underexposed_percent);
  const double done = index + 1;
  e->set_progress(0.9 * done / count);
  e->set_remaining_seconds(e->elapsed_seconds() / done * (count - done));
}

}  // namespace

void FillFrameProgress(const ScanFrameEvent& f, v1::FrameProgress* fp) {
  fp->set_frame_index(f.index);
  fp->set_frame_count(f.count);
  fp->set_z_um(f.z_um);
  fp->set_exposure_us(f.exposure_us);
  fp->set_acquisition_index(f.acquisition);
  fp->set_stack_frame(f.stack_frame);
  fp->mutable_statistics()->set_mean_grey(f.statistics.mean_grey);
  fp->mutable_statistics()->set_stddev_grey(f.statistics.stddev_grey);
  fp->mutable_statistics()->set_saturated_percent(f.statistics.saturated_percent);
  fp->mutable_statistics()->set_underexposed_percent(f.statistics.underexposed_percent);
}

namespace {

// Frames of a scan with an automatic z range, for its progress (RunScan below).
struct ProgressFrames {
  int coarse_planned = 0;  // the sweep's frames over the whole window (known from its first event)
  int coarse_taken = 0;    // those it took: fewer when it stopped early (the field had settled)
  int fine_estimate = 0;   // the fine scan's frames until its first event tells
};

void EmitPhase(const JobContext& context, v1::JobPhase phase, double progress = 0.0, const std::string& message = "") {
  context.emit([&](v1::JobEvent& e) {
    e.set_phase(phase);
    if (progress > 0.0) e.set_progress(progress);
    if (!message.empty()) e.set_message(message);
  });
}

double SecondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

// Queue wait from the stored job's submission time (wall clock), the scan from the job's start.
void FillTimings(DataStore* store, const std::string& job_id, std::chrono::steady_clock::time_point started_at,
                 std::chrono::steady_clock::time_point scanned_at, double engine_seconds,
                 v1::InspectionResult* inspection) {
  using google::protobuf::util::TimeUtil;
  v1::InspectionTimings* t = inspection->mutable_timings();
  StatusOr<v1::Job> job = store->GetJob(job_id);
  if (job.ok() && job->has_create_time()) {
    const double since_submit_s =
        double(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
                   .count() -
               TimeUtil::TimestampToNanoseconds(job->create_time())) *
        1e-9;
    t->set_queue_seconds(std::max(0.0, since_submit_s - SecondsSince(started_at)));
  }
  t->set_scan_seconds(std::chrono::duration<double>(scanned_at - started_at).count());
  t->set_engine_seconds(engine_seconds);
}

// The HTML report of an inspection (server/results/inspection_report.h), as an artifact of the job.
Status WriteReport(const RecipeRun& run, const v1::JobResult& result, const DepthResult& depth,
                   ResultPublisher* publisher) {
  InspectionReportInput input;
  input.inspection = result.inspection();
  input.depth = result.depth();
  input.recipe_description = run.recipe.description();
  input.depth_um = depth.depth_um;
  input.all_in_focus = depth.all_in_focus;
  INSPECT_ASSIGN_OR_RETURN(std::string html, RenderInspectionReport(input));
  return publisher->WriteBytes(v1::ARTIFACT_KIND_REPORT_HTML, "report.html", html);
}

}  // namespace

bool ThreePointPeak(DepthInterpolation interpolation) {
  return interpolation == DepthInterpolation::kGaussian || interpolation == DepthInterpolation::kDefocusParabola;
}

StatusOr<v1::JobResult> ProcedureRunner::Run(const JobWork& work, const JobContext& context) {
  return std::visit(Overloaded{
                        [&](const ScanWork& w) { return OnRig(rig_, [&] { return RunScan(w, context); }); },
                        [&](const CalibrateWork& w) { return OnRig(rig_, [&] { return RunCalibrate(w, context); }); },
                        [&](const ReconstructWork& w) { return RunReconstruct(w, context); },
                        [&](const StudyWork& w) { return OnRig(rig_, [&] { return RunStudy(w, context); }); },
                        [&](const VerifyWork& w) { return OnRig(rig_, [&] { return RunVerify(w, context); }); },
                    },
                    work);
}

StatusOr<v1::JobResult> ProcedureRunner::RunScan(const ScanWork& work, const JobContext& context) {
  const std::string& job_id = context.job_id;
  const auto started_at = std::chrono::steady_clock::now();
  // The calibration is the one active now (a calibration may have finished since submission);
  // RunScan re-checks that it holds the mode's models.
  ScanPlan plan = work.plan;
  plan.calibration_id = calibrations_->active_id();
  const std::shared_ptr<const CalibrationBundle> bundle = calibrations_->active();
  const bool search = plan.z_range_search.has_value();
  EmitPhase(context, v1::JOB_PHASE_PREPARING, 0.0,
            search ? "scan with automatic z range" : "scan of " + std::to_string(plan.z_um.size()) + " frames");

  OwnedFolder stack(store_->tmp_dir() / (job_id + ".stack"));
  // Automatic z range: the sweep's frames come first (JOB_PHASE_FOCUS_SEARCH), then the scan's.
  // Progress and remaining time count both; until the fine range is known its frame count is
  // taken as the whole window's at the fine step (an upper bound, so progress never goes back).
  ProgressFrames frames;
  if (search) {
    const ZRangeSearchSettings& s = *plan.z_range_search;
    frames.fine_estimate = int(std::abs(s.window_end_um - s.window_start_um) / plan.z_step_um) + 1;
  }
  auto on_frame = [&](const ScanFrameEvent& f) {
    context.emit([&](v1::JobEvent& e) {
      const v1::JobPhase phase = f.z_range_search ? v1::JOB_PHASE_FOCUS_SEARCH : v1::JOB_PHASE_ACQUIRING;
      if (!search) {
        FillFrameEvent(phase, f.index, f.count, f.z_um, f.exposure_us, f.statistics, &e);
        e.mutable_frame()->set_acquisition_index(f.acquisition);
      } else {
        if (f.z_range_search) {
          frames.coarse_planned = f.count;
          frames.coarse_taken = f.index + 1;
        }
        // Never goes back: coarse_taken <= coarse_planned and the fine count <= its estimate.
        const int done = f.z_range_search ? f.index : frames.coarse_taken + f.index;
        const int total =
            f.z_range_search ? frames.coarse_planned + frames.fine_estimate : frames.coarse_taken + f.count;
        FillFrameEvent(phase, done, total, f.z_um, f.exposure_us, f.statistics, &e);
        e.mutable_frame()->set_frame_index(f.index);  // within its phase
        e.mutable_frame()->set_frame_count(f.count);
        e.mutable_frame()->set_acquisition_index(f.acquisition + (f.z_range_search ? 0 : frames.coarse_taken));
      }
      e.mutable_frame()->set_stack_frame(f.stack_frame);
    });
  };
  StatusOr<ScanOutcome> scanned =
      search ? RunScanWithZRangeSearch(rig_->rig(), plan, stack.path(), on_frame, *context.cancel, bundle.get())
             : inspection::RunScan(rig_->rig(), plan, stack.path(), on_frame, *context.cancel, bundle.get());
  INSPECT_ASSIGN_OR_RETURN(ScanOutcome outcome, std::move(scanned));
  EmitPhase(context, v1::JOB_PHASE_STORING, 0.92);

  INSPECT_ASSIGN_OR_RETURN(ResultPublisher publisher, ResultPublisher::Create(store_, job_id, artifact_threads()));
  DepthExportMeta meta;
  meta.pixel_size_um = outcome.manifest.pixel_size_um;
  meta.description = "depth (um) of scan " + job_id;
  INSPECT_RETURN_IF_ERROR(publisher.WriteDepth(outcome.depth, meta, work.extra_exports));
  if (!outcome.ground_truth_um.empty()) {
    INSPECT_RETURN_IF_ERROR(
        publisher.CopyFile(v1::ARTIFACT_KIND_GROUND_TRUTH_TIFF, stack.path() / kGroundTruthDepthName));
  }
  INSPECT_RETURN_IF_ERROR(publisher.Zip(v1::ARTIFACT_KIND_STACK_ZIP, stack.path(), "stack.zip"));
  if (context.cancel->load()) return Status::Cancelled("scan cancelled while storing");  // a cancel's last chance

  v1::JobResult result;
  result.set_scan_id(job_id);
  result.set_calibration_id(plan.calibration_id);
  DepthSummaryParts parts{outcome.depth, outcome.manifest.pixel_size_um, outcome.ground_truth_um, plan.sff.window_px};
  parts.engine_seconds = outcome.engine_finish_seconds;
  parts.method = &plan.reconstruction;
  parts.integral = &outcome.isff;
  parts.alignment = &outcome.alignment;
  parts.postprocess = &outcome.postprocess;
  parts.halo = outcome.halo ? &*outcome.halo : nullptr;
  parts.illumination = outcome.manifest.illumination;
  parts.illumination_decision = outcome.illumination_decision;
  parts.z_range_search = outcome.manifest.z_range_search ? &*outcome.manifest.z_range_search : nullptr;
  *result.mutable_depth() = DepthSummaryProto(parts);
  const auto scanned_at = std::chrono::steady_clock::now();
  if (work.recipe) {
    EmitPhase(context, v1::JOB_PHASE_STORING, 0.95, "measuring recipe " + work.recipe->recipe.recipe_id());
    DepthNoiseOptions noise;
    noise.window_px = plan.sff.window_px;
    for (const StackFrame& f : outcome.manifest.frames) noise.z_positions_um.push_back(f.z_um);  // auto range too
    noise.stage_repeatability_um = rig_->rig().stage().repeatability_um();
    // The rig's characterised z linearity (calibration step z_linearity) when the scan ran at
    // its step; otherwise the peak-locking bound (core/metrology/depth_noise_model.h decides).
    if (bundle && bundle->z_linearity) noise.linearity = *bundle->z_linearity;
    // The stage error reaches a depth through the interpolation's three samples or in full.
    noise.three_point_peak = ThreePointPeak(plan.sff.interpolation);
    // The last full verification's alpha_z and l_z replace worst-case bounds (rig_verification.h).
    const std::string verification_warning = ApplyVerification(&noise);
    v1::InspectionResult* inspection = result.mutable_inspection();
    *inspection =
        Inspect(*work.recipe, outcome.depth, outcome.manifest.pixel_size_um, noise, work.part_id, work.station);
    inspection->set_job_id(job_id);
    inspection->set_calibration_id(plan.calibration_id);
    inspection->set_verification_warning(verification_warning);
    ApplyStudyWarnings(inspection);
    FillTimings(store_, job_id, started_at, scanned_at, outcome.engine_finish_seconds, inspection);
    // Nanoseconds: TimeUtil::GetCurrentTime keeps whole seconds here, and results a second
    // apart must stay apart for time-range queries.
    *inspection->mutable_finish_time() = google::protobuf::util::TimeUtil::NanosecondsToTimestamp(
        std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
            .count());
    INSPECT_RETURN_IF_ERROR(WriteReport(*work.recipe, result, outcome.depth, &publisher));
  }
  // The stack is stored once, as stack.zip (server/storage/stored_stack.h): the folder in tmp/ goes
  // with `stack` whether or not publication succeeds.
  INSPECT_RETURN_IF_ERROR(publisher.Publish(&result));
  if (work.recipe) {
    // Stored, then announced: a WatchResults client that sees it can download the report.
    v1::InspectionResult* inspection = result.mutable_inspection();
    for (const v1::Artifact& a : result.artifacts()) {
      if (a.kind() == v1::ARTIFACT_KIND_REPORT_HTML) inspection->set_report_artifact_id(a.artifact_id());
    }
    inspection->mutable_timings()->set_measure_seconds(SecondsSince(scanned_at));
    INSPECT_ASSIGN_OR_RETURN(*inspection, results_->Append(*inspection));
  }
  return result;
}

StatusOr<v1::JobResult> ProcedureRunner::RunCalibrate(const CalibrateWork& work, const JobContext& context) {
  Rig& rig = rig_->rig();
  std::shared_ptr<const CalibrationBundle> previous = calibrations_->active();
  // A bundle from a camera or projector of another size cannot be extended: start afresh.
  if (previous && (previous->camera_size != rig.camera().frame_size() ||
                   previous->projector_size != rig.projector().resolution())) {
    previous.reset();
  }
  auto on_progress = [&](const CalibrationProgress& p) {
    const double per_step = 1.0 / std::max(1, p.step_count);
    const double within = p.item_count > 0 ? double(p.item) / p.item_count : 0.0;
    context.emit([&](v1::JobEvent& e) {
      e.set_phase(v1::JOB_PHASE_CALIBRATING);
      e.set_step(p.step);
      e.set_progress(per_step * (p.step_index + within));
      e.set_message(p.message);
    });
  };
  INSPECT_ASSIGN_OR_RETURN(CalibrationBundle bundle,
                           RunCalibration(rig, work.options, previous.get(), on_progress, *context.cancel));
  INSPECT_ASSIGN_OR_RETURN(v1::Calibration record, calibrations_->Save(&bundle, context.job_id));
  INSPECT_RETURN_IF_ERROR(calibrations_->Activate(std::make_shared<const CalibrationBundle>(std::move(bundle))));
  v1::JobResult result;
  result.set_calibration_id(record.calibration_id());
  *result.mutable_calibration() = record.summary();
  return result;
}

StatusOr<v1::JobResult> ProcedureRunner::RunReconstruct(const ReconstructWork& work, const JobContext& context) {
  EmitPhase(context, v1::JOB_PHASE_PREPARING);
  // The manifest the request was checked against: a stored scan's folder holds no frames (they
  // are read from its archive), so only the sequential path reads the folder's.
  INSPECT_ASSIGN_OR_RETURN(StackManifest m, work.decoded ? StatusOr<StackManifest>(work.decoded->manifest())
                                                         : ReadStackManifest(work.stack_dir));
  auto on_frame = [&](int i, int n, double z, const FrameStatistics& st) {
    context.emit([&](v1::JobEvent& e) {
      FillFrameEvent(v1::JOB_PHASE_RECONSTRUCTING, i, n, z, m.frames[i].exposure_us, st, &e);
    });
  };
  const auto t0 = std::chrono::steady_clock::now();
  DepthResult depth;
  IntegralSffFigures isff;
  AlignmentFigures alignment;
  DepthPostProcessFigures postprocess;
  std::optional<HaloSuppressionFigures> halo;
  bool dense = false;
  std::string dense_decision;
  double inferred_below = 0.0;
  if (work.method.integral()) {
    // The calibration active now; two passes over the frames without per-frame events (and
    // without a cancellation point inside them: ~1 s for 23 frames of 1024 x 768).
    const std::shared_ptr<const CalibrationBundle> bundle = calibrations_->active();
    if (context.cancel->load()) return Status::Cancelled("reconstruction cancelled before it started");
    EmitPhase(context, v1::JOB_PHASE_RECONSTRUCTING, 0.05,
              std::string(ReconstructionMethodName(work.method.method)) + " over " + std::to_string(m.frames.size()) +
                  " frames: integral image, restoration, correlation");
    // Decoded frames come from memory (both passes; pass 2 frees each); the sequential path reads
    // the folder.
    StatusOr<IsffResult> integral = Status::Internal("not run");
    if (work.decoded) {
      StackFrameSource source{
          [&](int i) { return work.decoded->Frame(i); }, [&](int i) { work.decoded->Release(i); }, {}};
      integral = ReconstructStackIntegralSff(m, source, work.method, work.sff, bundle.get());
      work.decoded->ReleaseAll();  // what a failure left
    } else {
      integral = ReconstructStackFolderIntegralSff(work.stack_dir, work.method, work.sff, bundle.get());
    }
    INSPECT_ASSIGN_OR_RETURN(IsffResult r, std::move(integral));
    depth = std::move(r.depth);
    isff = FiguresOf(r);
  } else {
    // Imported stacks align by default: estimated from the frames, unaligned when they do not
    // register (a featureless stack); an explicit request fails instead.
    StackFolderAlignment a;
    a.alignment = work.alignment.value_or(FrameAlignment::kEstimate);
    a.fall_back_to_none = !work.alignment.has_value();
    const std::shared_ptr<const CalibrationBundle> bundle = calibrations_->active();
    if (a.alignment == FrameAlignment::kCalibrated && bundle && bundle->focus_breathing) {
      a.calibrated = &*bundle->focus_breathing;
    }
    // Unthresholded engine, then the post-processing (core/sff/depth_postprocess.h) thresholds.
    SffOptions unthresholded = work.sff;
    unthresholded.min_confidence = 0.0;
    // A pool replica sharing its cores with others runs its engine on its share of them.
    if (pipeline_.engine_threads > 0) unthresholded.threads = pipeline_.engine_threads;
    // Frames decoded while the request arrived come from memory, in z order, each freed once
    // the engine has it; without them (the sequential path) the folder is read here.
    StatusOr<DepthResult> r = Status::Internal("not run");
    if (work.decoded) {
      // Frames in memory, Frame thread-safe: neighbour pairs register concurrently.
      a.options.threads = pipeline_.engine_threads;
      StackFrameSource source{[&](int i) { return work.decoded->Frame(i); }, [&](int i) { work.decoded->Release(i); },
                              [&](int i) { return work.decoded->Statistics(i); }};
      r = ReconstructStackFrames(m, source, unthresholded, on_frame, *context.cancel, a, &alignment);
      work.decoded->ReleaseAll();  // what a failure left
    } else {
      r = ReconstructStackFolder(work.stack_dir, m, unthresholded, on_frame, *context.cancel, a, &alignment);
    }
    if (!r.ok()) {
      const bool alignment_error = r.status().message().rfind("alignment", 0) == 0;
      return alignment_error ? r.status().WithContext("options.alignment") : r.status();
    }
    if (work.halo) {
      // Two more passes over the frames, aligned as the engine saw them: the decoder decodes
      // released frames again (or the folder is read, on the sequential path).
      if (context.cancel->load()) return Status::Cancelled("reconstruction cancelled before halo suppression");
      EmitPhase(context, v1::JOB_PHASE_RECONSTRUCTING, 0.85, "halo suppression: two more passes over the frames");
      StackFrameSource frames;
      if (work.decoded) {
        frames = {[&](int i) { return work.decoded->Frame(i); }, [&](int i) { work.decoded->Release(i); }, {}};
      } else {
        frames = {[&](int i) { return DecodeStackFrame(work.stack_dir, m, size_t(i)); }, {}, {}};
      }
      HaloSuppressionFigures figures;
      StatusOr<DepthResult> fixed = SuppressStackHalos(*r, m, frames, alignment, unthresholded, *work.halo, &figures);
      if (work.decoded) work.decoded->ReleaseAll();
      if (!fixed.ok()) return fixed.status().WithContext("options.halo_suppression");
      r = std::move(fixed);
      halo = figures;
    }
    DepthPostProcessOptions post = work.postprocess;
    post.min_confidence = work.sff.min_confidence;
    // Dense depth by default for an imported stack (a value at every pixel, as photography
    // expects), not for a rig scan (metrology: NaN where nothing was measured). A rig's
    // stack.json records its acquisition (illumination mode, calibration, alignment), also when
    // its folder comes back as an upload.
    const bool imported = work.source_scan_id.empty() && m.calibration_id.empty() && m.illumination.empty() &&
                          !m.alignment.has_value();
    post.dense = work.dense_requested.value_or(imported);
    dense_decision = work.dense_requested ? (*work.dense_requested ? "requested" : "off as requested")
                     : imported ? "default for an imported stack (stack.json records no rig scan)"
                                : "off by default for a rig scan (NaN where nothing was measured)";
    dense = post.dense;
    inferred_below = post.dense || post.fill_low_confidence ? post.min_confidence : 0.0;
    std::vector<double> z_um;
    for (const StackFrame& f : m.frames) z_um.push_back(f.z_um);
    INSPECT_ASSIGN_OR_RETURN(depth, PostProcessDepth(*r, z_um, work.sff.window_px, post, &postprocess));
  }
  const double engine_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EmitPhase(context, v1::JOB_PHASE_STORING, 0.92);

  INSPECT_ASSIGN_OR_RETURN(ResultPublisher publisher,
                           ResultPublisher::Create(store_, context.job_id, artifact_threads()));
  DepthExportMeta meta;
  meta.pixel_size_um = m.pixel_size_um;
  meta.description = "depth (um) from reconstruct job " + context.job_id;
  meta.inferred_below_confidence = inferred_below;
  if (dense) {
    char note[96];
    std::snprintf(note, sizeof note, "; dense: depth with confidence below %.2f is inferred, not measured",
                  inferred_below);
    meta.description += note;
  }
  const auto t_write = std::chrono::steady_clock::now();
  INSPECT_RETURN_IF_ERROR(publisher.WriteDepth(depth, meta, work.extra_exports));
  const double write_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_write).count();
  // Ground truth travels with simulated stacks; without it (or unreadable) the summary has no
  // error figures, and the depth result stands on its own.
  cv::Mat truth;
  const fs::path truth_path = work.stack_dir / kGroundTruthDepthName;
  if (fs::exists(truth_path)) {
    auto t = ReadDepthTiff(truth_path);
    if (t.ok()) {
      truth = *t;
    } else {
      spdlog::warn("job {}: ground truth not used: {}", context.job_id, t.status().ToString());
    }
  }
  if (context.cancel->load()) return Status::Cancelled("reconstruction cancelled while storing");
  v1::JobResult result;
  result.set_scan_id(work.source_scan_id);
  DepthSummaryParts parts{depth, m.pixel_size_um, truth, work.sff.window_px};
  parts.engine_seconds = engine_seconds;
  parts.method = &work.method;
  parts.integral = &isff;
  parts.alignment = &alignment;
  parts.postprocess = &postprocess;
  parts.halo = halo ? &*halo : nullptr;
  *result.mutable_depth() = DepthSummaryProto(parts);
  if (!work.method.integral()) {
    result.mutable_depth()->set_dense_depth(dense);
    result.mutable_depth()->set_dense_depth_decision(dense_decision);
  }
  const auto t_publish = std::chrono::steady_clock::now();
  INSPECT_RETURN_IF_ERROR(publisher.Publish(&result));
  spdlog::debug("job {}: reconstruction {:.3f} s, artifacts written {:.3f} s, hashed and published {:.3f} s",
                context.job_id, engine_seconds, write_seconds,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t_publish).count());
  return result;
}

}  // namespace inspection
