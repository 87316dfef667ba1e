// The SFF engine's front door (thesis 3.1, core/sff/sff_engine.h): SffEngine::Create picks the
// streaming engine for the options and frames, after the input checks all engines share.
#include "core/sff/sff_engine.h"

#include <cmath>
#include <string>

#include "core/sff/internal/sff_engine_internal.h"

namespace inspection {
namespace sff_internal {

Status CheckFrame(const cv::Mat& frame, int k, cv::Size size, int type) {
  if (frame.empty()) return Status::InvalidArgument("frame " + std::to_string(k) + ": empty image");
  if (frame.size() != size) {
    return Status::InvalidArgument("frame " + std::to_string(k) + ": size " + std::to_string(frame.cols) + "x" +
                                   std::to_string(frame.rows) + " differs from the stack's " +
                                   std::to_string(size.width) + "x" + std::to_string(size.height));
  }
  if (frame.type() != type) {
    return Status::InvalidArgument("frame " + std::to_string(k) + ": pixel type " + std::to_string(frame.type()) +
                                   " differs from the stack's " + std::to_string(type) +
                                   " (bit depth or channels mismatch)");
  }
  return Status::Ok();
}

// Checks of PushFrame for frame k = z.size(): the engine is open, the frame matches, z_um is
// finite and continues the strictly monotonic z, at most 65535 frames (16-bit frame index).
Status CheckPush(const cv::Mat& frame, double z_um, const std::vector<double>& z, bool finished, cv::Size size,
                 int type) {
  const int k = int(z.size());
  if (finished) return Status::FailedPrecondition("engine already finished");
  INSPECT_RETURN_IF_ERROR(CheckFrame(frame, k, size, type));
  if (!std::isfinite(z_um)) return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um is not finite");
  if (k >= 1) {
    const double dz = z_um - z.back();
    if (dz == 0.0 || (k >= 2 && (dz > 0) != (z[1] > z[0]))) {
      return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um " + std::to_string(z_um) +
                                     (dz == 0.0 ? " duplicates the previous frame's" : " is not strictly monotonic"));
    }
  }
  if (k >= 65535) return Status::ResourceExhausted("frame " + std::to_string(k) + ": more than 65535 frames");
  return Status::Ok();
}

Status CheckFinish(bool finished, int frame_count) {
  if (finished) return Status::FailedPrecondition("engine already finished");
  if (frame_count < 3) {
    return Status::InvalidArgument("stack has " + std::to_string(frame_count) + " frames; at least 3 are needed");
  }
  return Status::Ok();
}

Status CheckCreate(const SffOptions& options, cv::Size frame_size, int frame_type) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (frame_size.width < 3 || frame_size.height < 3) return Status::InvalidArgument("frame size must be at least 3x3");
  if (frame_type != CV_8UC1 && frame_type != CV_16UC1) {
    return Status::InvalidArgument("frames must be 8- or 16-bit single-channel");
  }
  return Status::Ok();
}

bool UseFused(const SffOptions& o, int frame_type) {
  return frame_type == CV_8UC1 && o.focus_measure == FocusMeasure::kTenengrad && !o.illumination_invariant;
}

bool UseCompact(const SffOptions& o, int frame_type) {
  return UseFused(o, frame_type) && o.interpolation != DepthInterpolation::kLineFit;
}

DepthResult MakeDepthResult(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& all_in_focus,
                            int frame_count, size_t valid) {
  DepthResult r;
  r.depth_um = depth_um;
  r.confidence = confidence;
  r.all_in_focus = all_in_focus;
  r.frame_count = frame_count;
  r.valid_fraction = double(valid) / double(depth_um.size().area());
  return r;
}

}  // namespace sff_internal

StatusOr<std::unique_ptr<SffEngine>> SffEngine::Create(const SffOptions& options, cv::Size frame_size, int frame_type) {
  INSPECT_RETURN_IF_ERROR(sff_internal::CheckCreate(options, frame_size, frame_type));
  if (sff_internal::UseCompact(options, frame_type)) return sff_internal::NewCompactEngine(options, frame_size);
  return sff_internal::NewExactEngine(options, frame_size, frame_type);
}

}  // namespace inspection
