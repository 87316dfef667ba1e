// Fusion of depth maps of one stack measured with several focus measures or windows (thesis
// 3.1.3 compares the operators; none wins everywhere: small windows keep depth edges and fine
// texture, large ones carry weak texture, derivative and statistical operators fail on
// different surfaces). The confidence of core/sff/depth_interpolation.h is a signal-to-noise ratio
// of each pixel's focus curve, comparable between operators and windows, so per pixel the most
// confident map can be trusted most.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/util/status.h"

namespace inspection {

enum class DepthFusionRule {
  kMostConfident,       // per pixel, the depth of the map with the highest confidence
  kConfidenceWeighted,  // per pixel, the confidence-weighted mean depth; confidence = the highest
  kFirstConfident,      // per pixel, the first map (in the order given) whose confidence reaches
                        // min_confidence: list small windows first to keep depth edges where the
                        // small window suffices, larger ones carry the weak texture
};

struct FusedDepth {
  cv::Mat depth_um;    // CV_32FC1; NaN where the fused confidence is below min_confidence or no
                       // input has a finite depth with confidence > 0
  cv::Mat confidence;  // CV_32FC1: the highest confidence among the inputs
};

// depth_um[i], confidence[i]: CV_32FC1 maps of one size, depth measured with no threshold
// (min_confidence 0, so every pixel has a depth; NaN depths are skipped). At least one map.
StatusOr<FusedDepth> FuseDepthMaps(const std::vector<cv::Mat>& depth_um, const std::vector<cv::Mat>& confidence,
                                   DepthFusionRule rule, double min_confidence);

}  // namespace inspection
