// JobWork: what one job does, as validated domain values (no proto beyond the job kind). The
// request mapping (request_mapping.h) builds it from a request, the JobManager queues it, and a
// JobRunner (job_runner.h) runs it. One alternative per job kind.
#pragma once

#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "core/sff/depth_postprocess.h"
#include "core/sff/halo_suppression.h"
#include "core/sff/sff_engine.h"
#include "core/io/stack_frame_decoder.h"
#include "core/registration/stack_alignment.h"
#include "inspection/v1/inspection.pb.h"
#include "server/results/inspection_result.h"
#include "server/storage/owned_folder.h"
#include "server/procedures/calibration_procedure.h"
#include "server/results/depth_artifacts.h"
#include "server/procedures/scan_procedure.h"
#include "server/procedures/verification_procedure.h"

namespace inspection {

// Acquire a stack through focus on the rig and reconstruct it (thesis 3.1.2, 5, 6.2).
struct ScanWork {
  ScanPlan plan;  // calibration_id is filled in when the scan starts (the bundle active then)
  std::vector<DepthExportKind> extra_exports;
  std::string part_id;  // the MES context of the request (ScanRequest.part_id, station)
  std::string station;
  // Set when the request named a recipe (server/api/recipe_scan.h): measured and judged on the depth
  // map (server/results/inspection_result.h).
  std::shared_ptr<const RecipeRun> recipe;
};

// Run calibration steps on the rig (thesis 4.3, 5.4.1).
struct CalibrateWork {
  CalibrationOptions options;
};

// How a reconstruction reads its frames and writes its artifacts.
struct ReconstructPipelineOptions {
  // Frames decode on this many threads while the upload arrives (or the stored scan is read);
  // 0 = all hardware threads.
  int decode_threads = 0;
  // Decoded frames kept per reconstruction for the engine; beyond it the job decodes again.
  int64_t max_decoded_bytes = StackFrameDecoderOptions{}.max_kept_bytes;
  int artifact_threads = 0;  // artifact files written (and hashed) at once; 0 = all hardware threads
  // The sequential path, the end-to-end benchmark's baseline: every frame decoded after
  // the upload to check it and again in the job, one after another; artifacts one at a time.
  bool sequential = false;
  // Threads of the SFF engine and the frame alignment per reconstruction; 0 = all hardware
  // threads. Replicas sharing a host set their share, so they do not oversubscribe its cores.
  int engine_threads = 0;
};

// Reconstruct a stack (core/io/stack.h format) that has already been validated.
struct ReconstructWork {
  std::filesystem::path stack_dir;
  std::string source_scan_id;  // the stored scan read; empty for an upload
  // The request it was built from (a serialised v1::ReconstructStart, the upload's bytes aside):
  // the stored input from which another pool replica builds the same work again.
  std::string pool_input;
  // Set for an uploaded stack or a stored scan's private folder (server/storage/stored_stack.h): the
  // folder goes when the last copy of the work does (the job ended, was cancelled while queued,
  // or never got queued).
  std::shared_ptr<OwnedFolder> upload;
  // The stack's frames, decoded (and checked) while the request was received, from stack_dir or
  // from a stored scan's archive (then stack_dir holds no frames); null = the job decodes them
  // from stack_dir (the sequential path). Declared after `upload`: destroyed (its threads
  // joined) before the folder goes.
  std::shared_ptr<StackFrameDecoder> decoded;
  SffOptions sff;
  ReconstructionMethodSettings method;  // SFF with sff, or an integral method (thesis 5.4, 6.4)
  std::vector<DepthExportKind> extra_exports;
  // Lateral alignment (core/registration/stack_alignment.h); nullopt = ESTIMATE, unaligned when the frames do
  // not register.
  std::optional<FrameAlignment> alignment;
  DepthPostProcessOptions postprocess;  // SFF only
  std::optional<HaloSuppressionOptions> halo;  // SFF only: run it before the post-processing
  // ReconstructionOptions.dense_depth as requested; nullopt = the default: dense for an imported
  // stack (an upload whose stack.json records no rig scan: no illumination mode, calibration or
  // alignment record), measured pixels only (NaN
  // elsewhere) for a rig scan, whose depth is metrology. postprocess.dense follows it at run time.
  std::optional<bool> dense_requested;
};

// A Type-1 gauge study (server/procedures/type1_study_procedure.h): the recipe's scan repeated
// on one reference part, measured and judged for capability (server/results/study_result.h).
struct StudyWork {
  ScanWork scan;  // the recipe's scan; scan.recipe is set
  int repeats = 0;
  std::map<std::string, double> reference_values;  // by measurement name (checked against the recipe)
  double reposition_xy_um = 0.0;                   // simulated rig: sigma of the placement per repeat
  double reposition_z_um = 0.0;
  std::string repositioning_note;  // e.g. "(default)" when the request left them unset
  uint64_t seed = 1;               // of the simulated placements
};

// Instrument verification on the rig's material measures (server/procedures/verification_procedure.h),
// stored with the calibration active as it runs.
struct VerifyWork {
  VerificationMode mode = VerificationMode::kFull;
  // A full verification's validity (inspectd verification_interval_days): its record's
  // next_full_due is its finish time plus this.
  double interval_days = 30.0;
};

using JobWork = std::variant<ScanWork, CalibrateWork, ReconstructWork, StudyWork, VerifyWork>;

v1::JobKind KindOf(const JobWork& work);

// What a job shows while it waits, beyond its kind and ids: a reconstruction of a stored scan
// names that scan in its result from the start.
void FillQueuedJob(const JobWork& work, v1::Job* job);

// One line for the log, e.g. "scan of 41 frames, z 0..200 um, HF+ADAPT".
std::string DescribeWork(const JobWork& work);

}  // namespace inspection
