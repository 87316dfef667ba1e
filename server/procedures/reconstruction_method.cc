// Reconstruction methods (thesis 3.1, 5.4, 6.4): names, the integral methods' options and
// preconditions, and ISFF / ISFF-FAST over a stored stack folder.
#include "server/procedures/reconstruction_method.h"

#include <opencv2/core.hpp>

#include "core/io/stack.h"

namespace inspection {

const char* ReconstructionMethodName(ReconstructionMethod method) {
  switch (method) {
    case ReconstructionMethod::kSff:
      return "SFF";
    case ReconstructionMethod::kIsff:
      return "ISFF";
    case ReconstructionMethod::kIsffGroundTruth:
      return "ISFF-GT";
    case ReconstructionMethod::kIsffFast:
      return "ISFF-FAST";
  }
  return "?";
}

Status ReconstructionMethodSettings::Validate() const {
  if (!(isff_fast_threshold > 0.0 && isff_fast_threshold <= 1.0)) {
    return Status::InvalidArgument("isff_fast_threshold must be in (0, 1] (a normalised correlation), got " +
                                   std::to_string(isff_fast_threshold));
  }
  return Status::Ok();
}

IsffOptions IsffOptionsFor(const ReconstructionMethodSettings& settings, const SffOptions& sff) {
  IsffOptions o;
  o.ncc.correlation_window_px = sff.window_px;
  o.ncc.summation_window_px = sff.window_px;
  o.ncc.interpolation = sff.interpolation;
  o.ncc.linefit_half_width = sff.linefit_half_width;
  o.ncc.min_confidence = sff.min_confidence;
  o.ncc.threads = sff.threads;
  o.ncc.stop_at_first_maximum = settings.method == ReconstructionMethod::kIsffFast;
  o.ncc.stop_threshold = settings.isff_fast_threshold;
  return o;
}

IntegralSffFigures FiguresOf(const IsffResult& result) {
  IntegralSffFigures f;
  f.frame_noise_sigma = result.frame_noise_sigma;
  const int frames = result.depth.frame_count;
  if (frames > 0 && !result.frames_searched.empty()) {
    f.frames_searched_fraction = cv::mean(result.frames_searched)[0] / double(frames);
  }
  return f;
}

Status CheckIntegralIllumination(const std::string& illumination) {
  if (illumination.empty() || illumination == "STD") return Status::Ok();
  return Status::FailedPrecondition(
      "integral SFF needs a stack under uniform illumination (STD): the integral "
      "image of thesis eq. 5.19 assumes one fixed illumination, and this stack's "
      "illumination is " +
      illumination);
}

Status CheckStackFolderMethod(const ReconstructionMethodSettings& settings, const CalibrationBundle* bundle) {
  switch (settings.method) {
    case ReconstructionMethod::kSff:
      return Status::Ok();
    case ReconstructionMethod::kIsffGroundTruth:
      return Status::FailedPrecondition(
          "ISFF-GT needs the simulated rig's ground-truth texture, which exists only while a scan runs on the "
          "simulated rig; use Scan with RECONSTRUCTION_METHOD_ISFF_GT there, or ISFF here");
    case ReconstructionMethod::kIsff:
    case ReconstructionMethod::kIsffFast:
      return CheckIntegralPsfFor(bundle);
  }
  return Status::Internal("unknown reconstruction method");
}

StatusOr<IsffResult> ReconstructStackFolderIntegralSff(const std::filesystem::path& dir,
                                                       const ReconstructionMethodSettings& settings,
                                                       const SffOptions& sff, const CalibrationBundle* bundle) {
  if (!settings.integral()) return Status::Internal("ReconstructStackFolderIntegralSff called for SFF");
  INSPECT_RETURN_IF_ERROR(settings.Validate());
  INSPECT_RETURN_IF_ERROR(CheckStackFolderMethod(settings, bundle));
  INSPECT_ASSIGN_OR_RETURN(StackManifest manifest, ReadStackManifest(dir));
  // The frames version on the folder's frames (it repeats the checks above, which cost nothing;
  // they come first here so a bad request is named before the folder is read).
  const StackFrameSource folder{[&](int i) { return DecodeStackFrame(dir, manifest, size_t(i)); }, {}, {}};
  return ReconstructStackIntegralSff(manifest, folder, settings, sff, bundle);
}

StatusOr<IsffResult> ReconstructStackIntegralSff(const StackManifest& manifest, const StackFrameSource& source,
                                                 const ReconstructionMethodSettings& settings, const SffOptions& sff,
                                                 const CalibrationBundle* bundle) {
  if (!settings.integral()) return Status::Internal("ReconstructStackIntegralSff called for SFF");
  INSPECT_RETURN_IF_ERROR(settings.Validate());
  INSPECT_RETURN_IF_ERROR(CheckStackFolderMethod(settings, bundle));
  INSPECT_RETURN_IF_ERROR(CheckIntegralIllumination(manifest.illumination));
  return ReconstructIntegralSffFrames(manifest, source, &*bundle->integral_psf, IsffOptionsFor(settings, sff));
}

}  // namespace inspection
