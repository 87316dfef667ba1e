// What the SFF engine's files share (core/sff/sff_engine.cc, sff_exact_engine.cc,
// sff_compact_engine.cc, sff_batch.cc): input checks whose messages name the frame, which state
// layout a case uses, the result's assembly and the streaming engines' factories. Internal.
#pragma once

#include <cstddef>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "core/sff/sff_engine.h"

namespace inspection::sff_internal {

// INVALID_ARGUMENT naming frame k unless it is non-empty and of the stack's size and type.
Status CheckFrame(const cv::Mat& frame, int k, cv::Size size, int type);

// Checks of PushFrame for frame k = z.size(): the engine is open, the frame matches, z_um is
// finite and continues the strictly monotonic z, at most 65535 frames (16-bit frame index).
Status CheckPush(const cv::Mat& frame, double z_um, const std::vector<double>& z, bool finished, cv::Size size,
                 int type);

// Checks of Finish: the engine is open and has at least 3 frames.
Status CheckFinish(bool finished, int frame_count);

// Checks of Create: valid options, frames of at least 3 x 3 pixels, CV_8UC1 or CV_16UC1.
Status CheckCreate(const SffOptions& options, cv::Size frame_size, int frame_type);

// 8-bit frames with Tenengrad run through the fused kernel (core/sff/internal/tenengrad_kernel.h) ...
bool UseFused(const SffOptions& o, int frame_type);
// ... and, with maximum or Gaussian interpolation, over the compact state (core/sff/sff_state.h).
bool UseCompact(const SffOptions& o, int frame_type);

// The result from its three images (of one size); valid: the pixels with finite depth.
DepthResult MakeDepthResult(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& all_in_focus,
                            int frame_count, size_t valid);

// The streaming engines, for options and frames that passed CheckCreate: exact state
// (sff_exact_engine.cc) for every case but UseCompact, compact state (sff_compact_engine.cc).
std::unique_ptr<SffEngine> NewExactEngine(const SffOptions& options, cv::Size frame_size, int frame_type);
std::unique_ptr<SffEngine> NewCompactEngine(const SffOptions& options, cv::Size frame_size);

}  // namespace inspection::sff_internal
