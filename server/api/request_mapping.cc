// Request mapping: proto requests -> validated domain values; errors name the request field.
#include "server/api/request_mapping.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <optional>
#include <string>

#include "core/illumination/texture_pattern.h"
#include "core/io/stack.h"
#include "server/procedures/illumination_auto.h"
#include "server/procedures/z_range_search.h"

namespace inspection {
namespace fs = std::filesystem;

namespace {

StatusOr<FocusMeasure> MapFocusMeasure(v1::FocusMeasure m) {
  switch (m) {
    case v1::FOCUS_MEASURE_UNSPECIFIED:
    case v1::FOCUS_MEASURE_TENENGRAD:
      return FocusMeasure::kTenengrad;
    case v1::FOCUS_MEASURE_MODIFIED_LAPLACIAN:
      return FocusMeasure::kModifiedLaplacian;
    case v1::FOCUS_MEASURE_SUM_MODIFIED_LAPLACIAN:
      return FocusMeasure::kSumModifiedLaplacian;
    case v1::FOCUS_MEASURE_GREY_LEVEL_VARIANCE:
      return FocusMeasure::kGreyLevelVariance;
    case v1::FOCUS_MEASURE_HELMLI_MEAN:
      return FocusMeasure::kHelmliMean;
    case v1::FOCUS_MEASURE_CHEBYSHEV_MOMENTS:
      return FocusMeasure::kChebyshevMoments;
    case v1::FOCUS_MEASURE_GREY_LEVEL_LOCAL_VARIANCE:
      return FocusMeasure::kGreyLevelLocalVariance;
    default:
      return Status::InvalidArgument("focus_measure " + std::to_string(int(m)) + " is unknown");
  }
}

StatusOr<DepthInterpolation> MapInterpolation(v1::DepthInterpolation i, const std::string& field) {
  switch (i) {
    case v1::DEPTH_INTERPOLATION_GAUSSIAN:
      return DepthInterpolation::kGaussian;
    case v1::DEPTH_INTERPOLATION_MAXIMUM:
      return DepthInterpolation::kMaximum;
    case v1::DEPTH_INTERPOLATION_LINE_FIT:
      return DepthInterpolation::kLineFit;
    case v1::DEPTH_INTERPOLATION_UNSPECIFIED:
    case v1::DEPTH_INTERPOLATION_DEFOCUS_PARABOLA:
      return DepthInterpolation::kDefocusParabola;
    default:
      return Status::InvalidArgument(field + ".interpolation " + std::to_string(int(i)) + " is unknown");
  }
}

StatusOr<DepthExportKind> MapExtraExport(int kind, const std::string& field) {
  switch (kind) {
    case v1::ARTIFACT_KIND_DEPTH_PNG16:
      return DepthExportKind::kDepthPng16;
    case v1::ARTIFACT_KIND_DEPTH_PLY:
      return DepthExportKind::kDepthPly;
    case v1::ARTIFACT_KIND_DEPTH_X3P:
      return DepthExportKind::kDepthX3p;
    default:
      return Status::InvalidArgument(field + " must be ARTIFACT_KIND_DEPTH_PNG16, _PLY or _X3P");
  }
}

StatusOr<CalibrationStep> MapCalibrationStep(int step, const std::string& field) {
  switch (step) {
    case v1::CALIBRATION_STEP_CAMERA_RESPONSE:
      return CalibrationStep::kCameraResponse;
    case v1::CALIBRATION_STEP_PROJECTOR_RESPONSE:
      return CalibrationStep::kProjectorResponse;
    case v1::CALIBRATION_STEP_GEOMETRY:
      return CalibrationStep::kGeometry;
    case v1::CALIBRATION_STEP_PSF:
      return CalibrationStep::kPsf;
    case v1::CALIBRATION_STEP_SCATTER_MATRIX:
      return CalibrationStep::kScatterMatrix;
    case v1::CALIBRATION_STEP_INTEGRAL_PSF:
      return CalibrationStep::kIntegralPsf;
    case v1::CALIBRATION_STEP_FOCUS_BREATHING:
      return CalibrationStep::kFocusBreathing;
    case v1::CALIBRATION_STEP_Z_LINEARITY:
      return CalibrationStep::kZLinearity;
    default:
      return Status::InvalidArgument(field + " is not a calibration step");
  }
}

StatusOr<ReconstructionMethod> MapReconstructionMethod(v1::ReconstructionMethod m, const std::string& field) {
  switch (m) {
    case v1::RECONSTRUCTION_METHOD_UNSPECIFIED:
    case v1::RECONSTRUCTION_METHOD_SFF:
      return ReconstructionMethod::kSff;
    case v1::RECONSTRUCTION_METHOD_ISFF:
      return ReconstructionMethod::kIsff;
    case v1::RECONSTRUCTION_METHOD_ISFF_GT:
      return ReconstructionMethod::kIsffGroundTruth;
    case v1::RECONSTRUCTION_METHOD_ISFF_FAST:
      return ReconstructionMethod::kIsffFast;
    default:
      return Status::InvalidArgument(field + ".method " + std::to_string(int(m)) + " is unknown");
  }
}

bool IsCheckerboardMode(IlluminationMode mode) {
  return mode == IlluminationMode::kTexture || mode == IlluminationMode::kHfAdapt ||
         mode == IlluminationMode::kAdaptedHf;
}

// The checkerboard period of eq. 5.15 for this bundle and focus window; the bundle must hold
// psf and geometry.
StatusOr<TexturePeriod> CheckerboardPeriod(const CalibrationBundle& calibration, int window_px) {
  return ChooseTexturePeriod(calibration.psf->influence_radius_px, calibration.geometry->camera_px_per_projector_px,
                             window_px);
}

StatusOr<std::optional<FrameAlignment>> MapFrameAlignment(v1::FrameAlignment a, const std::string& field) {
  switch (a) {
    case v1::FRAME_ALIGNMENT_UNSPECIFIED:
      return std::optional<FrameAlignment>();
    case v1::FRAME_ALIGNMENT_NONE:
      return std::optional(FrameAlignment::kNone);
    case v1::FRAME_ALIGNMENT_ESTIMATE:
      return std::optional(FrameAlignment::kEstimate);
    case v1::FRAME_ALIGNMENT_CALIBRATED:
      return std::optional(FrameAlignment::kCalibrated);
    default:
      return Status::InvalidArgument(field + ".alignment " + std::to_string(int(a)) + " is unknown");
  }
}

// Scans warp each frame as it arrives: only a model known before the first frame will do.
Status CheckScanAlignment(const std::optional<FrameAlignment>& a, const CalibrationBundle* calibration) {
  if (a == FrameAlignment::kEstimate) {
    return Status::InvalidArgument(
        "reconstruction.alignment FRAME_ALIGNMENT_ESTIMATE needs the whole stack; a scan aligns each frame as it "
        "arrives with the calibrated model (FRAME_ALIGNMENT_CALIBRATED). Reconstruct the stored scan to estimate");
  }
  if (a == FrameAlignment::kCalibrated && (calibration == nullptr || !calibration->focus_breathing)) {
    return Status::FailedPrecondition(
        std::string("reconstruction.alignment FRAME_ALIGNMENT_CALIBRATED needs the calibration step focus_breathing") +
        (calibration == nullptr ? " (no active calibration)" : " (missing in the active calibration)"));
  }
  return Status::Ok();
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Shared messages

StatusOr<ReconstructionSettings> MapReconstructionOptions(const v1::ReconstructionOptions& o,
                                                          const std::string& field) {
  ReconstructionSettings out;
  SffOptions& s = out.sff;
  auto fm = MapFocusMeasure(o.focus_measure());
  if (!fm.ok()) return fm.status().WithContext(field);
  s.focus_measure = *fm;
  if (o.window_px() != 0) s.window_px = o.window_px();
  INSPECT_ASSIGN_OR_RETURN(s.interpolation, MapInterpolation(o.interpolation(), field));
  if (o.has_min_confidence()) s.min_confidence = o.min_confidence();
  s.illumination_invariant = o.illumination_invariant();
  INSPECT_RETURN_IF_ERROR(s.Validate().WithContext(field));
  ReconstructionMethodSettings& m = out.method;
  INSPECT_ASSIGN_OR_RETURN(m.method, MapReconstructionMethod(o.method(), field));
  const std::string method_name = ReconstructionMethodName(m.method);
  if (m.integral() && o.focus_measure() != v1::FOCUS_MEASURE_UNSPECIFIED) {
    return Status::InvalidArgument(field + ".focus_measure must be unset with method " + method_name +
                                   " (it correlates with a focused template, thesis eq. 5.24-5.26)");
  }
  if (o.has_isff_fast_threshold()) {
    if (m.method != ReconstructionMethod::kIsffFast) {
      return Status::InvalidArgument(
          field + ".isff_fast_threshold applies to RECONSTRUCTION_METHOD_ISFF_FAST only (method " + method_name + ")");
    }
    m.isff_fast_threshold = o.isff_fast_threshold();
  }
  // Validate's message starts with the field name ("isff_fast_threshold must be in (0, 1] ...").
  if (Status v = m.Validate(); !v.ok()) return Status::InvalidArgument(field + "." + v.message());
  INSPECT_ASSIGN_OR_RETURN(out.alignment, MapFrameAlignment(o.alignment(), field));
  if (m.integral() && out.alignment && *out.alignment != FrameAlignment::kNone) {
    return Status::InvalidArgument(field + ".alignment " + v1::FrameAlignment_Name(o.alignment()) +
                                   " applies to SFF only (method " + method_name + " reads the stack as acquired)");
  }
  DepthPostProcessOptions& post = out.postprocess;
  post.min_confidence = s.min_confidence;  // the jobs take it from sff; kept equal for Validate
  post.consistency = o.has_depth_consistency() ? o.depth_consistency() : true;
  switch (o.refinement()) {
    case v1::DEPTH_REFINEMENT_METHOD_UNSPECIFIED:
    case v1::DEPTH_REFINEMENT_METHOD_NONE:
      post.refinement.method = DepthRefinement::kNone;
      break;
    case v1::DEPTH_REFINEMENT_METHOD_WEIGHTED_MEDIAN:
      post.refinement.method = DepthRefinement::kWeightedMedian;
      break;
    case v1::DEPTH_REFINEMENT_METHOD_GUIDED_FILTER:
      post.refinement.method = DepthRefinement::kGuidedFilter;
      break;
    default:
      return Status::InvalidArgument(field + ".refinement: unknown value " + std::to_string(int(o.refinement())));
  }
  post.fill_low_confidence = o.fill_low_confidence();
  post.dense = o.has_dense_depth() && o.dense_depth();  // unset: the reconstruct job's default (dense for imports)
  if (m.integral()) {
    // The integral methods threshold their own correlation peak; nothing here applies to them.
    post.consistency = false;
    if (o.has_depth_consistency()) {
      return Status::InvalidArgument(field + ".depth_consistency applies to SFF only (method " + method_name + ")");
    }
    if (post.refinement.method != DepthRefinement::kNone) {
      return Status::InvalidArgument(field + ".refinement applies to SFF only (method " + method_name + ")");
    }
    if (post.fill_low_confidence) {
      return Status::InvalidArgument(field + ".fill_low_confidence applies to SFF only (method " + method_name + ")");
    }
    if (post.dense) {
      return Status::InvalidArgument(field + ".dense_depth applies to SFF only (method " + method_name + ")");
    }
    if (o.halo_suppression()) {
      return Status::InvalidArgument(field + ".halo_suppression applies to SFF only (method " + method_name + ")");
    }
    if (s.illumination_invariant) {
      return Status::InvalidArgument(field + ".illumination_invariant applies to SFF only (method " + method_name +
                                     ")");
    }
  }
  INSPECT_RETURN_IF_ERROR(post.Validate().WithContext(field));
  if (o.halo_suppression()) out.halo = HaloSuppressionOptions{};
  for (int i = 0; i < o.extra_exports_size(); ++i) {
    INSPECT_ASSIGN_OR_RETURN(DepthExportKind k,
                             MapExtraExport(o.extra_exports(i), field + ".extra_exports[" + std::to_string(i) + "]"));
    out.extra_exports.push_back(k);
  }
  return out;
}

StatusOr<std::optional<IlluminationMode>> MapIlluminationMode(v1::IlluminationMode mode) {
  switch (mode) {
    case v1::ILLUMINATION_MODE_UNSPECIFIED:
      return std::optional<IlluminationMode>();
    case v1::ILLUMINATION_MODE_STD:
      return std::optional(IlluminationMode::kStd);
    case v1::ILLUMINATION_MODE_HDR:
      return std::optional(IlluminationMode::kHdr);
    case v1::ILLUMINATION_MODE_ADAPT_IT:
      return std::optional(IlluminationMode::kAdaptIterative);
    case v1::ILLUMINATION_MODE_ADAPT:
      return std::optional(IlluminationMode::kAdapt);
    case v1::ILLUMINATION_MODE_TEXTURE:
      return std::optional(IlluminationMode::kTexture);
    case v1::ILLUMINATION_MODE_HF_ADAPT:
      return std::optional(IlluminationMode::kHfAdapt);
    case v1::ILLUMINATION_MODE_ADAPTED_HF:
      return std::optional(IlluminationMode::kAdaptedHf);
    case v1::ILLUMINATION_MODE_AUTO:
      return std::optional(IlluminationMode::kAuto);
    default:
      return Status::InvalidArgument("illumination " + std::to_string(int(mode)) + " is unknown");
  }
}

StatusOr<IlluminationParams> MapIlluminationParameters(const v1::IlluminationParameters& ip) {
  IlluminationParams params;
  if (ip.has_hdr_exposures()) params.hdr_exposures = ip.hdr_exposures();
  if (ip.has_lambda()) params.lambda = ip.lambda();
  if (ip.has_gamma()) params.gamma = ip.gamma();
  if (ip.has_psi()) params.psi = ip.psi();
  if (ip.has_max_iterations()) params.max_iterations = ip.max_iterations();
  if (ip.has_target_grey()) params.target_grey = ip.target_grey();
  // Validate's messages start with the field name ("lambda must be in [0, 2]").
  Status v = params.Validate();
  if (!v.ok()) return Status::InvalidArgument("illumination_parameters." + v.message());
  return params;
}

IlluminationMode DefaultIlluminationMode(const CalibrationBundle* calibration, int window_px) {
  // AUTO's probe only pays when it has a choice to make: TEXTURE or the ADAPT family available.
  const IlluminationAvailability a = AvailableIlluminationModes(calibration, window_px);
  return a.texture || a.adapt ? IlluminationMode::kAuto : IlluminationMode::kStd;
}

// ---------------------------------------------------------------------------------------------
// Job requests

// ScanRequest.z_range_search: nullopt when not asked for. Fields are named "z_range_search.<f>".
static StatusOr<std::optional<ZRangeSearchSettings>> MapZRangeSearch(const v1::ScanRequest& req, double fine_step_um,
                                                                     const ScanDefaults& defaults, const Stage& stage) {
  if (!req.has_z_range_search()) return std::optional<ZRangeSearchSettings>();
  const v1::ZRangeSearch& z = req.z_range_search();
  const bool any_field =
      z.has_window_start_um() || z.has_window_end_um() || z.has_coarse_step_um() || z.has_margin_um();
  if (!z.enabled()) {
    if (any_field) return Status::InvalidArgument("z_range_search.enabled is false but its other fields are set");
    return std::optional<ZRangeSearchSettings>();
  }
  // An explicit range and a search for one contradict each other: the window restricts a search.
  if (req.z_start_um() != 0.0 || req.z_end_um() != 0.0) {
    return Status::InvalidArgument(std::string(req.z_start_um() != 0.0 ? "z_start_um" : "z_end_um") +
                                   " cannot be combined with z_range_search (give z_range_search.window_start_um "
                                   "and window_end_um instead)");
  }
  if (z.has_window_start_um() != z.has_window_end_um()) {
    return Status::InvalidArgument(std::string("z_range_search.") +
                                   (z.has_window_start_um() ? "window_end_um" : "window_start_um") +
                                   " is missing (give both ends of the search window or neither)");
  }
  if (z.has_coarse_step_um() && !(z.coarse_step_um() > 0.0)) {
    return Status::InvalidArgument("z_range_search.coarse_step_um must be > 0 (got " +
                                   std::to_string(z.coarse_step_um()) + ")");
  }
  if (z.has_margin_um() && (!(z.margin_um() >= 0.0) || !std::isfinite(z.margin_um()))) {
    return Status::InvalidArgument("z_range_search.margin_um must be >= 0 (got " + std::to_string(z.margin_um()) + ")");
  }
  if (!(fine_step_um > 0.0) || !std::isfinite(fine_step_um)) {
    return Status::InvalidArgument("z_step_um must be > 0 (got " + std::to_string(fine_step_um) + ")");
  }
  ZRangeSearchSettings s;
  if (z.has_window_start_um()) {
    s.window_start_um = z.window_start_um();
    s.window_end_um = z.window_end_um();
    // 0 .. 0 would read as "unset" below; as a window it is empty.
    if (s.window_start_um == s.window_end_um) {
      return Status::InvalidArgument("z_range_search.window_start_um and window_end_um must differ");
    }
  }
  if (z.has_coarse_step_um()) s.coarse_step_um = z.coarse_step_um();
  // A requested margin of 0 is kept as a tiny one: 0 means "default" in ZRangeSearchSettings.
  if (z.has_margin_um()) s.margin_um = std::max(z.margin_um(), 1e-9);
  INSPECT_ASSIGN_OR_RETURN(ZRangeSearchSettings resolved, ResolveZRangeSearch(s, fine_step_um, defaults, stage));
  return std::optional<ZRangeSearchSettings>(resolved);
}

StatusOr<ScanWork> MapScanRequest(const v1::ScanRequest& req, const ScanContext& context) {
  INSPECT_ASSIGN_OR_RETURN(std::optional<IlluminationMode> requested, MapIlluminationMode(req.illumination()));
  INSPECT_ASSIGN_OR_RETURN(IlluminationParams params, MapIlluminationParameters(req.illumination_parameters()));
  // A contradiction in the request comes before what the calibration lacks.
  const v1::ReconstructionMethod method = req.reconstruction().method();
  const bool integral = method != v1::RECONSTRUCTION_METHOD_UNSPECIFIED && method != v1::RECONSTRUCTION_METHOD_SFF;
  if (integral && requested && *requested != IlluminationMode::kStd) {
    // The integral image of eq. 5.19 is the blur of one fixed texture: uniform illumination.
    return Status::InvalidArgument(
        "illumination " + IlluminationModeName(*requested) + " cannot be used with reconstruction.method " +
        v1::ReconstructionMethod_Name(method) + ": integral SFF needs illumination STD (thesis 5.4.1)");
  }
  if (requested) INSPECT_RETURN_IF_ERROR(CheckCalibrationFor(*requested, context.calibration));

  // Range unset (both ends zero) = the rig's default range; step zero = the rig's default step.
  const ScanDefaults& defaults = context.defaults;
  const bool default_range = req.z_start_um() == 0.0 && req.z_end_um() == 0.0;
  const double z0 = default_range ? defaults.z_start_um : req.z_start_um();
  const double z1 = default_range ? defaults.z_end_um : req.z_end_um();
  const double dz = req.z_step_um() == 0.0 ? defaults.z_step_um : req.z_step_um();
  if (req.exposure_us() < 0) return Status::InvalidArgument("exposure_us must be >= 0 (0 = rig default)");
  const double exposure = req.exposure_us() > 0 ? req.exposure_us() : defaults.exposure_us;

  ScanWork work;
  INSPECT_ASSIGN_OR_RETURN(std::optional<ZRangeSearchSettings> search,
                           MapZRangeSearch(req, dz, defaults, *context.stage));
  if (search) {
    // The range comes from the search: a plan without z positions yet (z_range_search.h).
    if (!(exposure > 0.0) || !std::isfinite(exposure)) return Status::InvalidArgument("exposure_us must be > 0");
    if (!(dz > 0.0) || !std::isfinite(dz)) return Status::InvalidArgument("z_step_um must be > 0");
    work.plan.exposure_us = exposure;
    work.plan.z_step_um = dz;
    work.plan.z_range_search = *search;
  } else {
    INSPECT_ASSIGN_OR_RETURN(work.plan, MakeScanPlan(z0, z1, dz, exposure, *context.stage));
  }
  INSPECT_ASSIGN_OR_RETURN(ReconstructionSettings rec,
                           MapReconstructionOptions(req.reconstruction(), "reconstruction"));
  work.plan.sff = rec.sff;
  work.plan.reconstruction = rec.method;
  work.extra_exports = std::move(rec.extra_exports);
  INSPECT_RETURN_IF_ERROR(CheckScanAlignment(rec.alignment, context.calibration));
  work.plan.alignment = rec.alignment;
  work.plan.postprocess = rec.postprocess;
  work.plan.halo = rec.halo;

  const int window_px = work.plan.sff.window_px;
  IlluminationMode mode = requested ? *requested : DefaultIlluminationMode(context.calibration, window_px);
  if (rec.method.integral()) {
    mode = IlluminationMode::kStd;  // the only one it takes (checked above)
    if (rec.method.method != ReconstructionMethod::kIsffGroundTruth) {
      INSPECT_RETURN_IF_ERROR(CheckIntegralPsfFor(context.calibration));
    }
  }
  if (requested && IsCheckerboardMode(mode)) {
    auto period = CheckerboardPeriod(*context.calibration, window_px);
    if (!period.ok()) return period.status().WithContext("reconstruction.window_px " + std::to_string(window_px));
  }
  work.plan.mode = mode;
  work.plan.params = params;
  return work;
}

StatusOr<CalibrateWork> MapCalibrateRequest(const v1::CalibrateRequest& req) {
  CalibrateWork work;
  for (int i = 0; i < req.steps_size(); ++i) {
    INSPECT_ASSIGN_OR_RETURN(CalibrationStep step,
                             MapCalibrationStep(req.steps(i), "steps[" + std::to_string(i) + "]"));
    work.options.steps.push_back(step);
  }
  return work;
}

StatusOr<VerifyWork> MapVerifyRequest(const v1::VerifyRequest& req) {
  VerifyWork work;
  switch (req.mode()) {
    case v1::VERIFICATION_MODE_UNSPECIFIED:
    case v1::VERIFICATION_MODE_FULL:
      work.mode = VerificationMode::kFull;
      return work;
    case v1::VERIFICATION_MODE_INTERIM:
      work.mode = VerificationMode::kInterim;
      return work;
    default:
      return Status::InvalidArgument("mode " + std::to_string(int(req.mode())) + " is not a VerificationMode (FULL or INTERIM)");
  }
}

StatusOr<ReconstructSource> MapReconstructSource(const v1::ReconstructStart& start, int64_t max_upload_bytes) {
  INSPECT_ASSIGN_OR_RETURN(ReconstructionSettings rec, MapReconstructionOptions(start.options(), "options"));
  if (rec.method.method == ReconstructionMethod::kIsffGroundTruth) {
    INSPECT_RETURN_IF_ERROR(CheckStackFolderMethod(rec.method, nullptr));
  }
  ReconstructSource source;
  if (start.has_scan_id()) {
    if (!IsSafeId(start.scan_id())) {
      return Status::InvalidArgument("start.scan_id '" + start.scan_id() + "' is malformed");
    }
    source.scan_id = start.scan_id();
    return source;
  }
  if (!start.has_upload()) return Status::InvalidArgument("start.source must be scan_id or upload");
  const v1::StackUpload& upload = start.upload();
  if (upload.total_bytes() < 0 || upload.total_bytes() > max_upload_bytes) {
    return Status::InvalidArgument("start.upload.total_bytes must be between 0 and " +
                                   std::to_string(max_upload_bytes));
  }
  if (upload.file_count() < 0) return Status::InvalidArgument("start.upload.file_count must be >= 0");
  source.upload = true;
  source.upload_total_bytes = upload.total_bytes();
  source.upload_file_count = upload.file_count();
  return source;
}

Status CheckUploadChunk(const v1::StackFileChunk& chunk) {
  const std::string& path = chunk.path();
  if (path.empty()) return Status::InvalidArgument("file_chunk.path is empty");
  const fs::path p(path);
  if (p.is_absolute()) return Status::InvalidArgument("file_chunk.path '" + path + "' must be relative");
  for (const auto& part : p) {
    if (part == ".." || part == ".") {
      return Status::InvalidArgument("file_chunk.path '" + path + "' must not contain '.' or '..'");
    }
  }
  if (int64_t(chunk.data().size()) > kMaxChunkBytes) {
    return Status::InvalidArgument("file_chunk.data of '" + path + "' exceeds 1 MiB");
  }
  return Status::Ok();
}

StatusOr<ReconstructWork> MapReconstructStart(const v1::ReconstructStart& start, const fs::path& stack_dir,
                                              std::shared_ptr<OwnedFolder> upload) {
  ReconstructWork work;
  INSPECT_ASSIGN_OR_RETURN(ReconstructionSettings rec, MapReconstructionOptions(start.options(), "options"));
  work.stack_dir = stack_dir;
  work.source_scan_id = start.has_scan_id() ? start.scan_id() : std::string();
  work.upload = std::move(upload);
  work.sff = rec.sff;
  work.method = rec.method;
  work.extra_exports = std::move(rec.extra_exports);
  work.alignment = rec.alignment;
  work.postprocess = rec.postprocess;
  work.halo = rec.halo;
  // Unset: the job decides once it has read the stack's manifest (dense for an imported stack,
  // ReconstructWork::dense_requested).
  if (start.options().has_dense_depth()) work.dense_requested = start.options().dense_depth();
  return work;
}

// ---------------------------------------------------------------------------------------------
// Other requests

bool IsSafeId(const std::string& id) {
  if (id.empty() || id.size() > 128) return false;
  for (char c : id) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_')) return false;
  }
  return true;
}

Status CheckJobId(const std::string& job_id) {
  if (job_id.empty()) return Status::InvalidArgument("job_id is empty");
  return Status::Ok();
}

StatusOr<JobListQuery> MapListJobsRequest(const v1::ListJobsRequest& req) {
  if (req.page_size() < 0) return Status::InvalidArgument("page_size must be >= 0");
  JobListQuery q;
  q.kind = req.kind();
  q.state = req.state();
  q.limit = req.page_size() == 0 ? 50 : std::min(req.page_size(), 500);
  if (!req.page_token().empty()) {
    try {
      q.before_create_ns = std::stoll(req.page_token());
    } catch (...) {
      return Status::InvalidArgument("page_token is malformed");
    }
  }
  return q;
}

std::string NextPageToken(const google::protobuf::Timestamp& t) {
  return std::to_string(t.seconds() * 1000000000LL + t.nanos());
}

StatusOr<ArtifactRange> MapDownloadRequest(const v1::DownloadArtifactRequest& req) {
  if (req.artifact_id().empty()) return Status::InvalidArgument("artifact_id is empty");
  if (req.offset() < 0) return Status::InvalidArgument("offset must be >= 0");
  if (req.limit() < 0) return Status::InvalidArgument("limit must be >= 0 (0 = to the end)");
  return ArtifactRange{req.artifact_id(), req.offset(), req.limit()};
}

Status CheckSpecimenName(const std::string& specimen) {
  if (specimen.empty()) return Status::InvalidArgument("specimen is empty");
  return Status::Ok();
}

namespace {
Status CheckTextFields(const google::protobuf::Message& message, const std::string& prefix, int depth) {
  using google::protobuf::FieldDescriptor;
  if (depth > 8) return Status::InvalidArgument(prefix + " nests too deep");  // no request nests this far
  const google::protobuf::Reflection* reflection = message.GetReflection();
  std::vector<const FieldDescriptor*> fields;
  reflection->ListFields(message, &fields);  // only fields that are set: unset text is empty
  for (const FieldDescriptor* f : fields) {
    const std::string path = prefix.empty() ? f->name() : prefix + "." + f->name();
    const int count = f->is_repeated() ? reflection->FieldSize(message, f) : 1;
    for (int i = 0; i < count; ++i) {
      const std::string item = f->is_repeated() ? path + "[" + std::to_string(i) + "]" : path;
      if (f->type() == FieldDescriptor::TYPE_STRING) {
        std::string scratch;
        const std::string& text = f->is_repeated() ? reflection->GetRepeatedStringReference(message, f, i, &scratch)
                                                   : reflection->GetStringReference(message, f, &scratch);
        if (text.size() > kMaxRequestTextBytes) {
          return Status::InvalidArgument(item + " is " + std::to_string(text.size()) + " bytes; at most " +
                                         std::to_string(kMaxRequestTextBytes));
        }
      } else if (f->cpp_type() == FieldDescriptor::CPPTYPE_MESSAGE) {
        const google::protobuf::Message& nested =
            f->is_repeated() ? reflection->GetRepeatedMessage(message, f, i) : reflection->GetMessage(message, f);
        INSPECT_RETURN_IF_ERROR(CheckTextFields(nested, item, depth + 1));
      }
    }
  }
  return Status::Ok();
}
}  // namespace

Status CheckRequestTextLimits(const google::protobuf::Message& request) { return CheckTextFields(request, "", 0); }

}  // namespace inspection
