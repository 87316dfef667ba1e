// Threshold, consistency, refinement, fill in one pass over the options (core/sff/depth_postprocess.h).
#include "core/sff/depth_postprocess.h"

#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace inspection {

Status DepthPostProcessOptions::Validate() const {
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) {
    return Status::InvalidArgument("min_confidence must be between 0 and 1");
  }
  if (dense_rank_radius_px < 0 || dense_rank_radius_px > 256) {
    return Status::InvalidArgument("dense_rank_radius_px must be between 0 and 256");
  }
  if (!(dense_rank_spread_z_steps >= 0.0 && std::isfinite(dense_rank_spread_z_steps))) {
    return Status::InvalidArgument("dense_rank_spread_z_steps must be >= 0");
  }
  if (consistency) INSPECT_RETURN_IF_ERROR(consistency_options.Validate());
  INSPECT_RETURN_IF_ERROR(refinement.Validate());
  if (fill_low_confidence) INSPECT_RETURN_IF_ERROR(fill_options.Validate());
  if (dense) INSPECT_RETURN_IF_ERROR(dense_options.Validate());
  return Status::Ok();
}

StatusOr<DepthResult> PostProcessDepth(const DepthResult& raw, const std::vector<double>& z_um, int focus_window_px,
                                       const DepthPostProcessOptions& o, DepthPostProcessFigures* figures) {
  INSPECT_RETURN_IF_ERROR(o.Validate());
  if (raw.depth_um.empty() || raw.depth_um.type() != CV_32FC1 || raw.confidence.type() != CV_32FC1 ||
      raw.confidence.size() != raw.depth_um.size()) {
    return Status::InvalidArgument("depth result must carry CV_32FC1 depth and confidence of one size");
  }
  DepthResult out = raw;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // The threshold as cv::compare of the CV_32F confidence with a scalar does it (the scalar
  // rounded to float), in one parallel pass instead of a clone, a mask and a masked set.
  const float min_confidence = float(o.min_confidence);
  out.depth_um = cv::Mat(raw.depth_um.size(), CV_32FC1);  // a new buffer: out's header shares raw's pixels
  out.confidence = raw.confidence.clone();
  cv::parallel_for_(cv::Range(0, raw.depth_um.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const float* d = raw.depth_um.ptr<float>(y);
      const float* c = raw.confidence.ptr<float>(y);
      float* t = out.depth_um.ptr<float>(y);
      for (int x = 0; x < raw.depth_um.cols; ++x) t[x] = c[x] < min_confidence ? nan : d[x];
    }
  });
  if (o.consistency) {
    const double z_step = MedianZStep(z_um);
    if (!(z_step > 0.0)) return Status::InvalidArgument("z_um must hold at least two distinct positions");
    INSPECT_ASSIGN_OR_RETURN(cv::Mat kept, RejectInconsistentDepth(out.depth_um, raw.depth_um, z_step, focus_window_px,
                                                                   o.consistency_options, raw.all_in_focus));
    // Rejected here (finite before, NaN now): not measured, whatever the curve's own confidence.
    std::atomic<int64_t> rejected{0};
    cv::parallel_for_(cv::Range(0, kept.rows), [&](const cv::Range& rows) {
      int64_t count = 0;
      for (int y = rows.start; y < rows.end; ++y) {
        const float* before = out.depth_um.ptr<float>(y);
        const float* after = kept.ptr<float>(y);
        float* c = out.confidence.ptr<float>(y);
        for (int x = 0; x < kept.cols; ++x) {
          if (before[x] == before[x] && !(after[x] == after[x])) {
            c[x] = 0.f;
            ++count;
          }
        }
      }
      rejected += count;
    });
    if (figures) figures->consistency_rejected_fraction = double(rejected.load()) / double(kept.total());
    out.depth_um = kept;
  }
  if (o.refinement.method != DepthRefinement::kNone) {
    INSPECT_ASSIGN_OR_RETURN(out.depth_um, RefineDepth(out.depth_um, out.confidence, raw.all_in_focus, o.refinement));
  }
  if (o.dense || o.fill_low_confidence) {
    const int before = cv::countNonZero(out.depth_um == out.depth_um);
    if (o.dense) {
      INSPECT_ASSIGN_OR_RETURN(DenseDepth d,
                               DensifyDepthWithSupport(out.depth_um, out.confidence, raw.all_in_focus, o.dense_options));
      // Inferred: below min_confidence whatever the ranking (the documented encoding).
      const float below = std::nextafter(min_confidence, 0.f);
      // The measured share around each pixel (the rank's local factor).
      cv::Mat share;
      if (o.dense_confidence && o.dense_rank_radius_px > 0) {
        share = cv::Mat(d.inferred.size(), CV_32FC1);
        cv::parallel_for_(cv::Range(0, share.rows), [&](const cv::Range& rows) {
          for (int y = rows.start; y < rows.end; ++y) {
            const uint8_t* inferred = d.inferred.ptr<uint8_t>(y);
            float* s = share.ptr<float>(y);
            for (int x = 0; x < share.cols; ++x) s[x] = inferred[x] ? 0.f : 1.f;
          }
        });
        const int k = 2 * o.dense_rank_radius_px + 1;
        cv::boxFilter(share, share, -1, cv::Size(k, k), cv::Point(-1, -1), true, cv::BORDER_REFLECT);
      }
      // The spread's scale in depth units (0: the spread is not used).
      float inv_spread = 0.f;
      if (o.dense_confidence && o.dense_rank_spread_z_steps > 0.0) {
        const double z_step = MedianZStep(z_um);
        if (!(z_step > 0.0)) return Status::InvalidArgument("z_um must hold at least two distinct positions");
        inv_spread = float(1.0 / (o.dense_rank_spread_z_steps * z_step));
      }
      cv::parallel_for_(cv::Range(0, d.depth_um.rows), [&](const cv::Range& rows) {
        for (int y = rows.start; y < rows.end; ++y) {
          const uint8_t* inferred = d.inferred.ptr<uint8_t>(y);
          const float* support = d.support.ptr<float>(y);
          const float* agreement = d.agreement.ptr<float>(y);
          const float* spread = d.spread_um.ptr<float>(y);
          const float* measured = out.depth_um.ptr<float>(y);
          float* c = out.confidence.ptr<float>(y);
          for (int x = 0; x < d.depth_um.cols; ++x) {
            const float q = spread[x] * inv_spread, spread_factor = 1.f / (1.f + q * q);
            if (inferred[x]) {
              // A rejected measurement ranks by its agreement with the fit as well.
              float rank = measured[x] == measured[x] ? support[x] * agreement[x] : support[x];
              if (!share.empty()) rank *= std::sqrt(std::max(share.at<float>(y, x), 0.f));
              rank *= spread_factor;
              c[x] = o.dense_confidence ? std::min(below, min_confidence * rank) : std::min(c[x], below);
            } else if (o.dense_confidence) {
              c[x] = min_confidence + (c[x] - min_confidence) * agreement[x] *
                                          (o.dense_rank_spread_measured ? spread_factor : 1.f);
            }
          }
        }
      });
      out.depth_um = d.depth_um;
    } else {
      INSPECT_ASSIGN_OR_RETURN(out.depth_um, FillDepth(out.depth_um, out.confidence, raw.all_in_focus, o.fill_options));
    }
    if (figures) {
      figures->filled_fraction =
          double(cv::countNonZero(out.depth_um == out.depth_um) - before) / double(out.depth_um.total());
    }
  }
  out.valid_fraction = double(cv::countNonZero(out.depth_um == out.depth_um)) / double(out.depth_um.total());
  return out;
}

}  // namespace inspection
