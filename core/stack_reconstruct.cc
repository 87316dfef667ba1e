// The stack folder -> SFF engine loop (core/stack_reconstruct.h): decode, push, report, per frame.
#include "core/stack_reconstruct.h"

#include <memory>
#include <string>

namespace inspection {

StatusOr<DepthResult> ReconstructStackFolder(const std::filesystem::path& dir, const StackManifest& manifest,
                                             const SffOptions& options, const StackFrameCallback& on_frame,
                                             const std::atomic<bool>& cancel) {
  std::unique_ptr<SffEngine> engine;
  const int count = int(manifest.frames.size());
  for (int i = 0; i < count; ++i) {
    if (cancel.load()) return Status::Cancelled("reconstruction cancelled at frame " + std::to_string(i));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, LoadStackFrame(dir, manifest, size_t(i)));
    if (!engine) {
      INSPECT_ASSIGN_OR_RETURN(engine, SffEngine::Create(options, frame.size(), frame.type()));
    }
    const std::string name = "frame " + std::to_string(i) + " (" + manifest.frames[i].file + ")";
    INSPECT_RETURN_IF_ERROR(engine->PushFrame(frame, manifest.frames[i].z_um).WithContext(name));
    if (on_frame) on_frame(i, count, manifest.frames[i].z_um, ComputeFrameStatistics(frame, manifest.bit_depth));
  }
  if (!engine) return Status::InvalidArgument("stack has no frames");
  return engine->Finish();
}

}  // namespace inspection
