// Request mapping: the one place where API requests (proto) are validated and become domain
// values (JobWork, engine options, queries). Errors are INVALID_ARGUMENT naming the request field
// ("reconstruction.window_px", "steps[2]", "start.upload.total_bytes"), or FAILED_PRECONDITION
// naming the calibration step a mode lacks. No gRPC types and no server state beyond what the
// caller passes in, so every rule is unit-testable (tests/server/api/request_mapping_test.cc).
// Also holds the default-illumination policy (thesis 5.3, 6.2.3).
//
// Extending: a new request field gets a Map* helper for its message (or a line in the one that
// owns it), called from the request's Map*Request function in field order, with its field path
// in every error.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/calibration/calibration_bundle.h"
#include "core/sff/depth_postprocess.h"
#include "core/sff/halo_suppression.h"
#include "core/sff/sff_engine.h"
#include "core/util/status.h"
#include "devices/rig.h"
#include "inspection/v1/inspection.pb.h"
#include "server/jobs/job_work.h"

namespace inspection {

// ---------------------------------------------------------------------------------------------
// Shared messages

// ReconstructionOptions -> engine options and the extra exports. `field` is the options' path
// in the request ("reconstruction" in ScanRequest, "options" in ReconstructStart).
// The method and its threshold are checked here (INVALID_ARGUMENT "<field>.isff_fast_threshold
// must be in (0, 1]", a threshold without ISFF_FAST, a focus measure with an integral method);
// what a method needs from the rig and calibration is checked by the job's request.
struct ReconstructionSettings {
  SffOptions sff;
  ReconstructionMethodSettings method;
  std::vector<DepthExportKind> extra_exports;
  // nullopt = FRAME_ALIGNMENT_UNSPECIFIED: the job's default (scan: CALIBRATED when the active
  // calibration holds the model, else NONE; reconstruct: ESTIMATE, NONE when it cannot register).
  // With an integral method only NONE is accepted (INVALID_ARGUMENT "<field>.alignment ...").
  std::optional<FrameAlignment> alignment;
  // SFF only (the integral methods refuse the fields): consistency, refinement, fill; the jobs
  // threshold at sff.min_confidence and run the engine with min_confidence 0.
  DepthPostProcessOptions postprocess;
  // SFF only: halo suppression between the engine and the post-processing (halo_suppression = true).
  std::optional<HaloSuppressionOptions> halo;
};
StatusOr<ReconstructionSettings> MapReconstructionOptions(const v1::ReconstructionOptions& options,
                                                          const std::string& field);

// nullopt for ILLUMINATION_MODE_UNSPECIFIED (the server picks, see DefaultIlluminationMode).
StatusOr<std::optional<IlluminationMode>> MapIlluminationMode(v1::IlluminationMode mode);
// Unset fields keep IlluminationParams' defaults; errors name "illumination_parameters.<field>".
StatusOr<IlluminationParams> MapIlluminationParameters(const v1::IlluminationParameters& parameters);

// Default illumination when a scan names none, for an unknown specimen: AUTO (a probe capture
// decides between HF+ADAPT, ADAPT, TEXTURE and STD, server/procedures/illumination_auto.h) when
// `calibration` allows TEXTURE (a checkerboard period fitting the focus window, eq. 5.15) or the
// ADAPT family; else STD. `calibration` may be null (uncalibrated rig: STD).
IlluminationMode DefaultIlluminationMode(const CalibrationBundle* calibration, int window_px);

// ---------------------------------------------------------------------------------------------
// Job requests

// What a scan request is checked against: the rig's defaults and travel, and the active
// calibration (may be null).
struct ScanContext {
  ScanDefaults defaults;
  const Stage* stage = nullptr;
  const CalibrationBundle* calibration = nullptr;
};
// Checks, in order: illumination, illumination_parameters, illumination against an integral
// reconstruction.method (thesis 5.4, 6.4: STD only, and their default; another mode is
// INVALID_ARGUMENT), the mode's calibration models, exposure_us, the z range (z_start_um,
// z_end_um, z_step_um), reconstruction, for the checkerboard modes the focus window against the
// texture period, and for ISFF and ISFF_FAST the integral_psf calibration step
// (FAILED_PRECONDITION). reconstruction.alignment: ESTIMATE is INVALID_ARGUMENT (a scan warps each
// frame as it arrives, before the stack exists: it uses the calibrated model; reconstruct the
// stored scan to estimate), CALIBRATED without the focus_breathing step FAILED_PRECONDITION. ISFF_GT's simulated rig is
// checked when the scan starts (RunScan).
StatusOr<ScanWork> MapScanRequest(const v1::ScanRequest& request, const ScanContext& context);

StatusOr<CalibrateWork> MapCalibrateRequest(const v1::CalibrateRequest& request);

// mode: UNSPECIFIED = FULL; another value is INVALID_ARGUMENT naming `mode`.
StatusOr<VerifyWork> MapVerifyRequest(const v1::VerifyRequest& request);

// Where a Reconstruct request's stack comes from, checked before any byte is received.
struct ReconstructSource {
  std::string scan_id;             // a stored scan (an id NewId could have made), or
  bool upload = false;             // the stack follows as file chunks
  int64_t upload_total_bytes = 0;  // 0 = not announced
  int upload_file_count = 0;       // 0 = not announced
};
// Also checks start.options, so bad options and ISFF_GT (FAILED_PRECONDITION: a stored stack has
// no ground-truth texture) are refused before an upload is received. ISFF's calibration step is
// checked when the job runs, against the calibration active then.
StatusOr<ReconstructSource> MapReconstructSource(const v1::ReconstructStart& start, int64_t max_upload_bytes);
// One chunk of an uploaded stack on its own (path relative and plain, data at most
// kMaxChunkBytes); the order of chunks is the receiver's to check.
inline constexpr int64_t kMaxChunkBytes = 1 << 20;  // 1 MiB: far below gRPC's 4 MiB message limit
Status CheckUploadChunk(const v1::StackFileChunk& chunk);
// The work for a stack folder that is in place and validated; `upload` owns it when uploaded.
StatusOr<ReconstructWork> MapReconstructStart(const v1::ReconstructStart& start, const std::filesystem::path& stack_dir,
                                              std::shared_ptr<OwnedFolder> upload);

// ---------------------------------------------------------------------------------------------
// Other requests

// An id that becomes a folder name: what NewId produces (letters, digits, '-', '_').
bool IsSafeId(const std::string& id);
// GetJob, WatchJob, CancelJob.
Status CheckJobId(const std::string& job_id);

struct JobListQuery {
  v1::JobKind kind = v1::JOB_KIND_UNSPECIFIED;     // UNSPECIFIED = all
  v1::JobState state = v1::JOB_STATE_UNSPECIFIED;  // UNSPECIFIED = all
  int limit = 50;
  int64_t before_create_ns = 0;  // 0 = from the newest
};
StatusOr<JobListQuery> MapListJobsRequest(const v1::ListJobsRequest& request);
// The page token of a page that ends with the job created at `last_create_time`.
std::string NextPageToken(const google::protobuf::Timestamp& last_create_time);

struct ArtifactRange {
  std::string artifact_id;
  int64_t offset = 0;
  int64_t limit = 0;  // 0 = to the end
};
StatusOr<ArtifactRange> MapDownloadRequest(const v1::DownloadArtifactRequest& request);

Status CheckSpecimenName(const std::string& specimen);

// Free text a caller can make the server keep, list or log (label, request_id, ids, paths,
// names, page tokens) is bounded: every string field of `request`, nested messages and
// repeated fields included, holds at most kMaxRequestTextBytes bytes. INVALID_ARGUMENT names
// the field path ("start.label is 3145728 bytes; at most 256"). Bytes fields (file data) are
// not text and are not checked here.
inline constexpr size_t kMaxRequestTextBytes = 256;
Status CheckRequestTextLimits(const google::protobuf::Message& request);

}  // namespace inspection
