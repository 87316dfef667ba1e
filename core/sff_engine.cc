// First streaming SFF: Tenengrad (eq. 3.14) + three-point Gaussian interpolation (eq. 3.30-3.34),
// generalised to non-uniform z steps. Per-pixel state: best focus value, its neighbours, the
// running mean of the focus curve (for confidence) and the all-in-focus grey value.
#include "core/sff_engine.h"

#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace inspection {

const char* FocusMeasureName(FocusMeasure m) {
  switch (m) {
    case FocusMeasure::kModifiedLaplacian: return "ml";
    case FocusMeasure::kSumModifiedLaplacian: return "sml";
    case FocusMeasure::kTenengrad: return "tenengrad";
    case FocusMeasure::kGreyLevelVariance: return "variance";
    case FocusMeasure::kHelmliMean: return "helmli-mean";
    case FocusMeasure::kChebyshevMoments: return "chebyshev";
    case FocusMeasure::kGreyLevelLocalVariance: return "glvm";
  }
  return "unknown";
}

StatusOr<FocusMeasure> ParseFocusMeasure(const std::string& name) {
  for (FocusMeasure m : {FocusMeasure::kModifiedLaplacian, FocusMeasure::kSumModifiedLaplacian,
                         FocusMeasure::kTenengrad, FocusMeasure::kGreyLevelVariance, FocusMeasure::kHelmliMean,
                         FocusMeasure::kChebyshevMoments, FocusMeasure::kGreyLevelLocalVariance}) {
    if (name == FocusMeasureName(m)) return m;
  }
  return Status::InvalidArgument("focus_measure '" + name +
                                 "' is unknown (ml, sml, tenengrad, variance, helmli-mean, chebyshev, glvm)");
}

const char* DepthInterpolationName(DepthInterpolation i) {
  switch (i) {
    case DepthInterpolation::kMaximum: return "maximum";
    case DepthInterpolation::kLineFit: return "linefit";
    case DepthInterpolation::kGaussian: return "gaussian";
  }
  return "unknown";
}

StatusOr<DepthInterpolation> ParseDepthInterpolation(const std::string& name) {
  for (DepthInterpolation i : {DepthInterpolation::kMaximum, DepthInterpolation::kLineFit, DepthInterpolation::kGaussian}) {
    if (name == DepthInterpolationName(i)) return i;
  }
  return Status::InvalidArgument("interpolation '" + name + "' is unknown (maximum, linefit, gaussian)");
}

Status SffOptions::Validate() const {
  if (window_px < 3 || window_px > 31 || window_px % 2 == 0) {
    return Status::InvalidArgument("window_px " + std::to_string(window_px) + " must be odd and between 3 and 31");
  }
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) {
    return Status::InvalidArgument("min_confidence must be between 0 and 1");
  }
  if (threads < 0) return Status::InvalidArgument("threads must be >= 0");
  return Status::Ok();
}

namespace {

class TenengradGaussianEngine final : public SffEngine {
 public:
  TenengradGaussianEngine(const SffOptions& o, cv::Size size, int type) : options_(o), size_(size), type_(type) {
    best_.create(size, CV_32F);
    best_.setTo(-1.f);
    prev_.create(size, CV_32F);
    prev_.setTo(0.f);
    next_.create(size, CV_32F);
    next_.setTo(-1.f);
    last_.create(size, CV_32F);
    last_.setTo(0.f);
    sum_.create(size, CV_32F);
    sum_.setTo(0.f);
    index_.create(size, CV_16U);
    index_.setTo(0);
    aif_.create(size, type);
    aif_.setTo(0);
  }

  Status PushFrame(const cv::Mat& frame, double z_um) override {
    const int k = int(z_.size());
    if (finished_) return Status::FailedPrecondition("engine already finished");
    if (frame.size() != size_) {
      return Status::InvalidArgument("frame " + std::to_string(k) + ": size " + std::to_string(frame.cols) + "x" +
                                     std::to_string(frame.rows) + " differs from the stack's " +
                                     std::to_string(size_.width) + "x" + std::to_string(size_.height));
    }
    if (frame.type() != type_) {
      return Status::InvalidArgument("frame " + std::to_string(k) + ": pixel type differs from frame 0");
    }
    if (!std::isfinite(z_um)) return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um is not finite");
    if (k >= 1) {
      const double dz = z_um - z_.back();
      if (dz == 0.0 || (k >= 2 && (dz > 0) != (z_[1] > z_[0]))) {
        return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um " + std::to_string(z_um) +
                                       " is not strictly monotonic");
      }
    }
    if (k >= 65535) return Status::ResourceExhausted("more than 65535 frames");
    z_.push_back(z_um);

    cv::Mat f32, gx, gy, fm;
    frame.convertTo(f32, CV_32F, frame.depth() == CV_16U ? 1.0 / 257.0 : 1.0);
    cv::Sobel(f32, gx, CV_32F, 1, 0, 3, 1, 0, cv::BORDER_REFLECT101);
    cv::Sobel(f32, gy, CV_32F, 0, 1, 3, 1, 0, cv::BORDER_REFLECT101);
    fm = gx.mul(gx) + gy.mul(gy);
    cv::boxFilter(fm, fm, CV_32F, cv::Size(options_.window_px, options_.window_px), cv::Point(-1, -1),
                  /*normalize=*/true, cv::BORDER_REFLECT101);

    for (int y = 0; y < size_.height; ++y) {
      const float* f = fm.ptr<float>(y);
      float* best = best_.ptr<float>(y);
      float* prev = prev_.ptr<float>(y);
      float* next = next_.ptr<float>(y);
      float* last = last_.ptr<float>(y);
      float* sum = sum_.ptr<float>(y);
      uint16_t* idx = index_.ptr<uint16_t>(y);
      for (int x = 0; x < size_.width; ++x) {
        const float v = f[x];
        if (v > best[x]) {
          prev[x] = last[x];
          best[x] = v;
          next[x] = -1.f;
          idx[x] = uint16_t(k);
          if (type_ == CV_8UC1) aif_.ptr<uint8_t>(y)[x] = frame.ptr<uint8_t>(y)[x];
          else aif_.ptr<uint16_t>(y)[x] = frame.ptr<uint16_t>(y)[x];
        } else if (int(idx[x]) == k - 1) {
          next[x] = v;
        }
        last[x] = v;
        sum[x] += v;
      }
    }
    return Status::Ok();
  }

  StatusOr<DepthResult> Finish() override {
    const int n = int(z_.size());
    if (n < 3) return Status::InvalidArgument("stack has " + std::to_string(n) + " frames; at least 3 are needed");
    finished_ = true;
    DepthResult r;
    r.frame_count = n;
    r.depth_um.create(size_, CV_32F);
    r.confidence.create(size_, CV_32F);
    r.all_in_focus = aif_;
    size_t valid = 0;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (int y = 0; y < size_.height; ++y) {
      const float* best = best_.ptr<float>(y);
      const float* prev = prev_.ptr<float>(y);
      const float* next = next_.ptr<float>(y);
      const float* sum = sum_.ptr<float>(y);
      const uint16_t* idx = index_.ptr<uint16_t>(y);
      float* depth = r.depth_um.ptr<float>(y);
      float* conf = r.confidence.ptr<float>(y);
      for (int x = 0; x < size_.width; ++x) {
        const int m = idx[x];
        double z = z_[m];
        const float mean = sum[x] / float(n);
        float c = best[x] > 0 ? (best[x] - mean) / best[x] : 0.f;
        if (options_.interpolation == DepthInterpolation::kGaussian && m > 0 && m < n - 1 && prev[x] > 0 &&
            next[x] > 0) {
          const double l1 = std::log(double(prev[x])), l2 = std::log(double(best[x])), l3 = std::log(double(next[x]));
          const double z1 = z_[m - 1], z2 = z_[m], z3 = z_[m + 1];
          const double a = (z2 - z1) * (l2 - l3), b = (z2 - z3) * (l2 - l1);
          const double den = a - b;
          if (den != 0.0) {
            const double num = (z2 - z1) * a - (z2 - z3) * b;
            const double zp = z2 - 0.5 * num / den;
            if (std::isfinite(zp) && std::abs(zp - z2) <= std::max(std::abs(z3 - z2), std::abs(z2 - z1))) z = zp;
          }
        } else if (m == 0 || m == n - 1) {
          c *= 0.5f;  // the peak lies at or beyond the end of the stack
        }
        conf[x] = std::clamp(c, 0.f, 1.f);
        if (conf[x] >= options_.min_confidence) {
          depth[x] = float(z);
          ++valid;
        } else {
          depth[x] = nan;
        }
      }
    }
    r.valid_fraction = double(valid) / double(size_.area());
    return r;
  }

  int frames_pushed() const override { return int(z_.size()); }

 private:
  SffOptions options_;
  cv::Size size_;
  int type_;
  bool finished_ = false;
  std::vector<double> z_;
  cv::Mat best_, prev_, next_, last_, sum_, index_, aif_;
};

}  // namespace

StatusOr<std::unique_ptr<SffEngine>> SffEngine::Create(const SffOptions& options, cv::Size frame_size,
                                                       int frame_type) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (frame_size.width < 3 || frame_size.height < 3) return Status::InvalidArgument("frame size must be at least 3x3");
  if (frame_type != CV_8UC1 && frame_type != CV_16UC1) {
    return Status::InvalidArgument("frames must be 8- or 16-bit single-channel");
  }
  if (options.focus_measure != FocusMeasure::kTenengrad) {
    return Status::Unimplemented(std::string("focus_measure ") + FocusMeasureName(options.focus_measure) +
                                 " is not available in this build");
  }
  return std::unique_ptr<SffEngine>(new TenengradGaussianEngine(options, frame_size, frame_type));
}

}  // namespace inspection
