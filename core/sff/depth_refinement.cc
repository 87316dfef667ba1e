// Guided, confidence-weighted depth refinement (core/sff/depth_refinement.h): weighted median with a
// tabulated similarity kernel, and He et al.'s guided filter with confidence-weighted box sums.
#include "core/sff/depth_refinement.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace inspection {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// exp(-t) for t = d^2 / (2 sigma^2) in [0, kLutRange), tabulated: the weighted median evaluates
// it (2r + 1)^2 times per pixel.
constexpr int kLutSize = 1024;
constexpr float kLutRange = 16.f;  // e^-16 ~ 1e-7: beyond, the neighbour does not count

cv::Mat Weights(const cv::Mat& depth_um, const cv::Mat& confidence) {
  cv::Mat w(depth_um.size(), CV_32F);
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    const float* c = confidence.empty() ? nullptr : confidence.ptr<float>(y);
    float* o = w.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      const float cw = c ? c[x] : 1.f;
      o[x] = (std::isfinite(d[x]) && cw > 0.f) ? std::min(cw, 1.f) : 0.f;  // NaN confidence: 0
    }
  }
  return w;
}

template <int CN>
void WeightedMedianRows(const cv::Range& rows, const cv::Mat& depth, const cv::Mat& weight, const cv::Mat& guide, int r,
                        int step, const std::vector<float>& lut, float lut_scale, cv::Mat* out) {
  std::vector<std::pair<float, float>> samples;
  samples.reserve(size_t(2 * r / step + 1) * (2 * r / step + 1));
  for (int y = rows.start; y < rows.end; ++y) {
    const float* d0 = depth.ptr<float>(y);
    float* o = out->ptr<float>(y);
    // Sample offsets are multiples of step from the pixel itself, so it always votes.
    const int y_lo = y - (std::min(r, y) / step) * step, y_hi = std::min(depth.rows - 1, y + r);
    for (int x = 0; x < depth.cols; ++x) {
      if (!std::isfinite(d0[x])) {
        o[x] = kNaN;
        continue;
      }
      const float* gp = guide.ptr<float>(y) + CN * x;
      const int x_lo = x - (std::min(r, x) / step) * step, x_hi = std::min(depth.cols - 1, x + r);
      samples.clear();
      float total = 0.f;
      for (int qy = y_lo; qy <= y_hi; qy += step) {
        const float* dq = depth.ptr<float>(qy);
        const float* wq = weight.ptr<float>(qy);
        const float* gq = guide.ptr<float>(qy);
        for (int qx = x_lo; qx <= x_hi; qx += step) {
          if (wq[qx] <= 0.f) continue;
          float dist2 = 0.f;
          for (int c = 0; c < CN; ++c) {
            const float diff = gp[c] - gq[CN * qx + c];
            dist2 += diff * diff;
          }
          const float t = dist2 * lut_scale;
          if (t >= float(kLutSize - 1)) continue;
          const float w = wq[qx] * lut[size_t(t)];
          samples.emplace_back(dq[qx], w);
          total += w;
        }
      }
      if (!(total > 0.f)) {
        o[x] = d0[x];
        continue;
      }
      std::sort(samples.begin(), samples.end());
      const float half = 0.5f * total;
      float acc = 0.f;
      float med = samples.back().first;
      for (const auto& s : samples) {
        acc += s.second;
        if (acc >= half) {
          med = s.first;
          break;
        }
      }
      o[x] = med;
    }
  }
}

cv::Mat WeightedMedian(const cv::Mat& depth, const cv::Mat& weight, const cv::Mat& guide,
                       const DepthRefinementOptions& o) {
  std::vector<float> lut(kLutSize);
  for (int i = 0; i < kLutSize; ++i) lut[size_t(i)] = std::exp(-kLutRange * float(i) / kLutSize);
  // t = dist2 / (2 sigma^2) in LUT steps.
  const float lut_scale = float(kLutSize / kLutRange / (2.0 * o.guide_sigma * o.guide_sigma));
  cv::Mat out(depth.size(), CV_32F);
  const int cn = guide.channels();
  const int step = o.sample_step_px > 0 ? o.sample_step_px : std::max(1, o.radius_px / 4);
  cv::parallel_for_(
      cv::Range(0, depth.rows),
      [&](const cv::Range& rows) {
        if (cn == 3)
          WeightedMedianRows<3>(rows, depth, weight, guide, o.radius_px, step, lut, lut_scale, &out);
        else
          WeightedMedianRows<1>(rows, depth, weight, guide, o.radius_px, step, lut, lut_scale, &out);
      },
      o.threads > 0 ? o.threads : -1);
  return out;
}

cv::Mat BoxMean(const cv::Mat& m, int r) {
  cv::Mat out;
  cv::boxFilter(m, out, CV_32F, cv::Size(2 * r + 1, 2 * r + 1), cv::Point(-1, -1), true, cv::BORDER_REFLECT_101);
  return out;
}

cv::Mat GuidedFilter(const cv::Mat& depth, const cv::Mat& weight, const cv::Mat& guide,
                     const DepthRefinementOptions& o) {
  cv::Mat lum;
  if (guide.channels() == 3) {
    cv::transform(guide, lum, cv::Matx13f(0.0722f, 0.7152f, 0.2126f));  // BGR -> BT.709 luminance
  } else {
    lum = guide;
  }
  // Centre the depth: the covariances subtract nearly equal float sums otherwise.
  double sum = 0.0, wsum = 0.0;
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) {
      const float w = weight.at<float>(y, x);
      if (w > 0.f) {
        sum += w * depth.at<float>(y, x);
        wsum += w;
      }
    }
  const float centre = wsum > 0 ? float(sum / wsum) : 0.f;
  cv::Mat p(depth.size(), CV_32F);
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) {
      p.at<float>(y, x) = weight.at<float>(y, x) > 0.f ? depth.at<float>(y, x) - centre : 0.f;
    }
  const int r = o.radius_px;
  const cv::Mat wI = weight.mul(lum), wp = weight.mul(p);
  const cv::Mat W = BoxMean(weight, r);
  const cv::Mat sI = BoxMean(wI, r), sp = BoxMean(wp, r), sII = BoxMean(wI.mul(lum), r), sIp = BoxMean(wI.mul(p), r);
  cv::Mat a(depth.size(), CV_32F), b(depth.size(), CV_32F);
  const float eps = float(o.guided_filter_eps);
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) {
      const float w = W.at<float>(y, x);
      if (!(w > 1e-6f)) {
        a.at<float>(y, x) = b.at<float>(y, x) = 0.f;
        continue;
      }
      const float mI = sI.at<float>(y, x) / w, mp = sp.at<float>(y, x) / w;
      const float var = std::max(sII.at<float>(y, x) / w - mI * mI, 0.f);
      const float cov = sIp.at<float>(y, x) / w - mI * mp;
      const float ak = cov / (var + eps);
      a.at<float>(y, x) = ak;
      b.at<float>(y, x) = mp - ak * mI;
    }
  // Average the window fits covering each pixel, each weighted by its confidence mass.
  const cv::Mat Wa = BoxMean(W.mul(a), r), Wb = BoxMean(W.mul(b), r), WW = BoxMean(W, r);
  cv::Mat out(depth.size(), CV_32F);
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) {
      const float d = depth.at<float>(y, x);
      const float ww = WW.at<float>(y, x);
      if (!std::isfinite(d)) {
        out.at<float>(y, x) = kNaN;
      } else if (!(ww > 1e-6f)) {
        out.at<float>(y, x) = d;
      } else {
        out.at<float>(y, x) = (Wa.at<float>(y, x) * lum.at<float>(y, x) + Wb.at<float>(y, x)) / ww + centre;
      }
    }
  return out;
}

}  // namespace

const char* DepthRefinementName(DepthRefinement r) {
  switch (r) {
    case DepthRefinement::kNone:
      return "none";
    case DepthRefinement::kWeightedMedian:
      return "weighted-median";
    case DepthRefinement::kGuidedFilter:
      return "guided-filter";
  }
  return "unknown";
}

StatusOr<DepthRefinement> ParseDepthRefinement(const std::string& name) {
  for (DepthRefinement r : {DepthRefinement::kNone, DepthRefinement::kWeightedMedian, DepthRefinement::kGuidedFilter}) {
    if (name == DepthRefinementName(r)) return r;
  }
  return Status::InvalidArgument("refinement '" + name + "' is unknown (none, weighted-median, guided-filter)");
}

Status DepthRefinementOptions::Validate() const {
  if (radius_px < 1 || radius_px > 31) {
    return Status::InvalidArgument("refinement radius_px " + std::to_string(radius_px) + " must be 1..31");
  }
  if (sample_step_px < 0 || sample_step_px > radius_px) {
    return Status::InvalidArgument("refinement sample_step_px must be 0 (auto) .. radius_px");
  }
  if (iterations < 1 || iterations > 5) return Status::InvalidArgument("refinement iterations must be 1..5");
  if (!(guide_sigma > 0.0) || !std::isfinite(guide_sigma)) {
    return Status::InvalidArgument("refinement guide_sigma must be > 0");
  }
  if (!(guided_filter_eps > 0.0) || !std::isfinite(guided_filter_eps)) {
    return Status::InvalidArgument("refinement guided_filter_eps must be > 0");
  }
  if (threads < 0) return Status::InvalidArgument("refinement threads must be >= 0");
  switch (method) {
    case DepthRefinement::kNone:
    case DepthRefinement::kWeightedMedian:
    case DepthRefinement::kGuidedFilter:
      break;
    default:
      return Status::InvalidArgument("refinement method is unknown");
  }
  return Status::Ok();
}

StatusOr<cv::Mat> NormalisedGuide(const cv::Mat& guide, cv::Size expected_size) {
  if (guide.size() != expected_size) {
    return Status::InvalidArgument("guide (all-in-focus image) must be " + std::to_string(expected_size.width) + "x" +
                                   std::to_string(expected_size.height));
  }
  if ((guide.depth() != CV_8U && guide.depth() != CV_16U) || (guide.channels() != 1 && guide.channels() != 3)) {
    return Status::InvalidArgument("guide must be 8- or 16-bit with 1 or 3 channels, not " +
                                   cv::typeToString(guide.type()));
  }
  cv::Mat out;
  guide.convertTo(out, CV_32F, guide.depth() == CV_8U ? 1.0 / 255.0 : 1.0 / 65535.0);
  return out;
}

StatusOr<cv::Mat> RefineDepth(const cv::Mat& depth_um, const cv::Mat& confidence, const cv::Mat& guide,
                              const DepthRefinementOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.empty() || depth_um.type() != CV_32FC1) return Status::InvalidArgument("depth_um must be CV_32FC1");
  if (!confidence.empty() && (confidence.type() != CV_32FC1 || confidence.size() != depth_um.size())) {
    return Status::InvalidArgument("confidence must be CV_32FC1 of the depth map's size");
  }
  INSPECT_ASSIGN_OR_RETURN(cv::Mat g, NormalisedGuide(guide, depth_um.size()));
  if (options.method == DepthRefinement::kNone) return depth_um.clone();
  const cv::Mat weight = Weights(depth_um, confidence);
  try {
    cv::Mat d = depth_um;
    for (int i = 0; i < options.iterations; ++i) {
      d = options.method == DepthRefinement::kWeightedMedian ? WeightedMedian(d, weight, g, options)
                                                             : GuidedFilter(d, weight, g, options);
    }
    return d;
  } catch (const cv::Exception& e) {
    return Status::Internal(std::string("depth refinement failed: ") + e.what());
  }
}

}  // namespace inspection
