// Per-pixel confidence-based fusion of depth maps (core/sff/depth_fusion.h).
#include "core/sff/depth_fusion.h"

#include <cmath>
#include <limits>

namespace inspection {

StatusOr<FusedDepth> FuseDepthMaps(const std::vector<cv::Mat>& depth_um, const std::vector<cv::Mat>& confidence,
                                   DepthFusionRule rule, double min_confidence) {
  if (depth_um.empty() || depth_um.size() != confidence.size()) {
    return Status::InvalidArgument("fusion needs one confidence map per depth map, at least one");
  }
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) {
    return Status::InvalidArgument("min_confidence must be between 0 and 1");
  }
  const cv::Size size = depth_um[0].size();
  for (size_t i = 0; i < depth_um.size(); ++i) {
    if (depth_um[i].type() != CV_32FC1 || confidence[i].type() != CV_32FC1 || depth_um[i].size() != size ||
        confidence[i].size() != size) {
      return Status::InvalidArgument("depth_um[" + std::to_string(i) + "] and confidence[" + std::to_string(i) +
                                     "] must be CV_32FC1 of one size");
    }
  }
  FusedDepth out;
  out.depth_um.create(size, CV_32FC1);
  out.confidence.create(size, CV_32FC1);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int y = 0; y < size.height; ++y) {
    float* od = out.depth_um.ptr<float>(y);
    float* oc = out.confidence.ptr<float>(y);
    for (int x = 0; x < size.width; ++x) {
      float best_c = 0.f, best_d = nan, first_c = 0.f, first_d = nan;
      double sw = 0.0, swd = 0.0;
      for (size_t i = 0; i < depth_um.size(); ++i) {
        const float d = depth_um[i].ptr<float>(y)[x], c = confidence[i].ptr<float>(y)[x];
        if (!std::isfinite(d) || !(c > 0.f)) continue;
        if (c > best_c) {
          best_c = c;
          best_d = d;
        }
        if (std::isnan(first_d) && c >= float(min_confidence)) {
          first_c = c;
          first_d = d;
        }
        sw += c;
        swd += double(c) * d;
      }
      float d = best_d, c = best_c;
      if (rule == DepthFusionRule::kConfidenceWeighted) d = sw > 0 ? float(swd / sw) : nan;
      if (rule == DepthFusionRule::kFirstConfident && !std::isnan(first_d)) {
        d = first_d;
        c = first_c;
      }
      oc[x] = c;
      od[x] = c >= float(min_confidence) && c > 0.f ? d : nan;
    }
  }
  return out;
}

}  // namespace inspection
