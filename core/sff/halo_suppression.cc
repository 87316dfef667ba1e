// Z-ordered re-selection of focus peaks near depth jumps (core/sff/halo_suppression.h).
#include "core/sff/halo_suppression.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>

#include "core/io/colour.h"  // LuminanceOf
#include "core/io/stack.h"  // CheckMonotonicZ
#include "core/sff/all_in_focus.h"
#include "core/sff/depth_interpolation.h"
#include "core/sff/focus_measure.h"

namespace inspection {

namespace {

// Fractional frame index of depth d on the (strictly monotonic) z positions; NaN stays NaN.
// Outside the stack's range: clamped to its ends.
float FrameIndexOf(double d, const std::vector<double>& z) {
  if (!std::isfinite(d)) return std::numeric_limits<float>::quiet_NaN();
  const int n = int(z.size());
  const bool up = z[1] > z[0];
  const auto before = [&](double a, double b) { return up ? a < b : a > b; };
  if (!before(z[0], d)) return 0.f;
  if (!before(d, z[size_t(n - 1)])) return float(n - 1);
  int lo = 0, hi = n - 1;  // z[lo] <= d < z[hi] in stack order
  while (hi - lo > 1) {
    const int mid = (lo + hi) / 2;
    (before(d, z[size_t(mid)]) ? hi : lo) = mid;
  }
  return float(lo + (d - z[size_t(lo)]) / (z[size_t(hi)] - z[size_t(lo)]));
}

// One candidate pixel and the levels of its two layers: the occluder, the surface behind.
struct Candidate {
  int pixel = 0;  // linear index
  int layer[2] = {};
};

}  // namespace

Status HaloSuppressionOptions::Validate() const {
  if (band_radius_px < 2 || band_radius_px > 64) return Status::InvalidArgument("band_radius_px must be in 2..64");
  if (layer_half_width_frames < 1 || layer_half_width_frames > 4) {
    return Status::InvalidArgument("layer_half_width_frames must be in 1..4");
  }
  // A jump must be wider than both layers' frame ranges, or the layers would overlap.
  if (!(min_jump_frames >= 2.0 * layer_half_width_frames) || !std::isfinite(min_jump_frames)) {
    return Status::InvalidArgument("min_jump_frames must be >= 2 * layer_half_width_frames (the layers would overlap)");
  }
  if (!(min_layer_support > 0.0 && min_layer_support < 1.0)) {
    return Status::InvalidArgument("min_layer_support must be in (0, 1)");
  }
  if (!(max_other_layer_ratio > 0.0 && max_other_layer_ratio < 1.0)) {
    return Status::InvalidArgument("max_other_layer_ratio must be in (0, 1)");
  }
  if (!(min_layer_focus_ratio > 0.0 && min_layer_focus_ratio <= 10.0)) {
    return Status::InvalidArgument("min_layer_focus_ratio must be in (0, 10]");
  }
  if (!(min_own_peak_ratio >= 0.0) || !std::isfinite(min_own_peak_ratio)) {
    return Status::InvalidArgument("min_own_peak_ratio must be >= 0");
  }
  if (!(min_confidence >= 0.0 && min_confidence < 1.0)) return Status::InvalidArgument("min_confidence must be in [0, 1)");
  return Status::Ok();
}

namespace {

// Per pixel, over the frame levels k (the confident pixels whose rounded depth is k - hw .. k + hw
// within the window): how many there are, the mean log of their peak focus and their mean depth
// (frames). Visits every level in order with its window sums; O(pixels) memory.
class LevelSweep {
 public:
  LevelSweep(const cv::Mat& level, const cv::Mat& index, const cv::Mat& log_peak, int levels, int half_width, int side)
      : level_(level), index_(index), log_peak_(log_peak), n_(levels), hw_(half_width), box_(side, side) {}

  // visit(k, count, log_sum, index_sum): CV_32FC1 window sums for levels k - hw .. k + hw.
  template <typename Visit>
  void Run(const Visit& visit) const {
    const int slots = 2 * hw_ + 1;
    const cv::Size size = level_.size();
    std::vector<cv::Mat> ring[3];
    for (auto& r : ring) r.resize(size_t(slots));
    cv::Mat sum[3], mask[3];
    for (int j = 0; j < 3; ++j) {
      sum[j] = cv::Mat(size, CV_32FC1, cv::Scalar(0));
      mask[j] = cv::Mat(size, CV_32FC1);
    }
    for (int k = 0; k < n_ + hw_; ++k) {
      for (int j = 0; j < 3; ++j) {
        cv::Mat& slot = ring[j][size_t(k % slots)];
        if (!slot.empty()) sum[j] -= slot;
        slot.release();
      }
      if (k < n_) {
        for (int y = 0; y < size.height; ++y) {
          const int32_t* l = level_.ptr<int32_t>(y);
          const float* idx = index_.ptr<float>(y);
          const float* lp = log_peak_.ptr<float>(y);
          float* m0 = mask[0].ptr<float>(y);
          float* m1 = mask[1].ptr<float>(y);
          float* m2 = mask[2].ptr<float>(y);
          for (int x = 0; x < size.width; ++x) {
            const bool in = l[x] == k;
            m0[x] = in ? 1.f : 0.f;
            m1[x] = in ? lp[x] : 0.f;
            m2[x] = in ? idx[x] : 0.f;
          }
        }
        for (int j = 0; j < 3; ++j) {
          cv::Mat& slot = ring[j][size_t(k % slots)];
          cv::boxFilter(mask[j], slot, CV_32F, box_, {-1, -1}, false, cv::BORDER_CONSTANT);
          sum[j] += slot;
        }
      }
      if (k - hw_ >= 0) visit(k - hw_, sum[0], sum[1], sum[2]);
    }
  }

 private:
  const cv::Mat& level_;
  const cv::Mat& index_;
  const cv::Mat& log_peak_;
  int n_, hw_;
  cv::Size box_;
};

// A layer near a pixel: its level (frame), its typical peak focus (geometric mean) and its mean
// depth (frames) over its confident pixels in the window.
struct Layer {
  int32_t level = -1;
  float typical = 0.f;
  float index = 0.f;
  float support = 0.f;
};

}  // namespace

StatusOr<DepthResult> SuppressHalos(const DepthResult& first, const std::function<StatusOr<cv::Mat>(int)>& frame,
                                    const std::vector<double>& z_um, const SffOptions& sff,
                                    const HaloSuppressionOptions& options, HaloSuppressionFigures* figures) {
  INSPECT_RETURN_IF_ERROR(options.Validate().WithContext("halo_suppression"));
  INSPECT_RETURN_IF_ERROR(sff.Validate());
  const int n = int(z_um.size());
  if (n < 3) return Status::InvalidArgument("halo suppression needs at least 3 frames");
  INSPECT_RETURN_IF_ERROR(CheckMonotonicZ(z_um));
  if (first.depth_um.empty() || first.depth_um.type() != CV_32FC1 || first.confidence.size() != first.depth_um.size() ||
      first.confidence.type() != CV_32FC1 || first.all_in_focus.size() != first.depth_um.size()) {
    return Status::InvalidArgument("halo suppression needs the engine's depth, confidence and all-in-focus images");
  }
  const cv::Size size = first.depth_um.size();
  const int pixels = size.area();
  const int hw = options.layer_half_width_frames;
  const int slots = 2 * hw + 1;
  const int side = 2 * options.band_radius_px + 1;
  const int frame_type = first.all_in_focus.type();
  const int channels = first.all_in_focus.channels();
  if (frame_type != CV_8UC1 && frame_type != CV_16UC1 && frame_type != CV_8UC3 && frame_type != CV_16UC3) {
    return Status::InvalidArgument("halo suppression needs an 8- or 16-bit grey or BGR all-in-focus image");
  }

  // The engine's depth in frames, and the confident pixels that define the layers.
  cv::Mat index(size, CV_32FC1), level(size, CV_32SC1);
  for (int y = 0; y < size.height; ++y) {
    const float* d = first.depth_um.ptr<float>(y);
    const float* c = first.confidence.ptr<float>(y);
    float* k = index.ptr<float>(y);
    int32_t* l = level.ptr<int32_t>(y);
    for (int x = 0; x < size.width; ++x) {
      k[x] = FrameIndexOf(d[x], z_um);
      l[x] = std::isfinite(k[x]) && c[x] >= options.min_confidence ? int(std::lround(k[x])) : -1;
    }
  }

  // Pass 1 over the frames: every pixel's peak focus value (the engine keeps it but does not
  // return it), the layers' typical values come from it.
  auto load = [&](int i) -> StatusOr<cv::Mat> {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, frame(i));
    const std::string name = "halo suppression: frame " + std::to_string(i);
    if (f.size() != size) return Status::InvalidArgument(name + " differs in size from the depth map");
    if (f.type() != frame_type) return Status::InvalidArgument(name + " differs in type from the all-in-focus image");
    return f.isContinuous() ? f : f.clone();
  };
  // Colour frames: focus on their luminance, as the engine measured it (core/io/colour.h).
  auto measure = [&](const cv::Mat& frame, cv::Mat* score_f) -> Status {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, LuminanceOf(frame));
    cv::Mat score;
    INSPECT_RETURN_IF_ERROR(FocusScore(f, sff.focus_measure, sff.window_px, &score));
    score.convertTo(*score_f, CV_32F);
    if (sff.illumination_invariant) {
      INSPECT_RETURN_IF_ERROR(NormaliseFocusByIllumination(f, sff.focus_measure, sff.window_px, score_f));
    }
    return Status::Ok();
  };
  cv::Mat peak(size, CV_32FC1, cv::Scalar(0)), score_f;
  for (int i = 0; i < n; ++i) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, load(i));
    INSPECT_RETURN_IF_ERROR(measure(f, &score_f));
    cv::max(peak, score_f, peak);
  }
  cv::Mat log_peak;
  cv::log(cv::max(peak, 1e-20), log_peak);

  // The layers near each pixel. The occluder: of the levels that at least min_layer_support of
  // the window's pixels have, the one with the highest typical focus (a bright or high-contrast
  // surface, whose blur is what spreads). The surface behind the blur: the best-supported level
  // at least min_jump_frames from the occluder.
  const float support = float(options.min_layer_support * side * side);
  std::vector<Layer> occluder(static_cast<size_t>(pixels)), behind(static_cast<size_t>(pixels));
  const LevelSweep sweep(level, index, log_peak, n, hw, side);
  sweep.Run([&](int k, const cv::Mat& count, const cv::Mat& log_sum, const cv::Mat& index_sum) {
    const float* c = count.ptr<float>();
    const float* ls = log_sum.ptr<float>();
    const float* is = index_sum.ptr<float>();
    for (int p = 0; p < pixels; ++p) {
      if (c[p] < support) continue;
      const float typical = std::exp(ls[p] / c[p]);
      Layer& o = occluder[size_t(p)];
      if (typical > o.typical) o = {k, typical, is[p] / c[p], c[p]};
    }
  });
  sweep.Run([&](int k, const cv::Mat& count, const cv::Mat& log_sum, const cv::Mat& index_sum) {
    const float* c = count.ptr<float>();
    const float* ls = log_sum.ptr<float>();
    const float* is = index_sum.ptr<float>();
    for (int p = 0; p < pixels; ++p) {
      const Layer& o = occluder[size_t(p)];
      if (c[p] < support || o.level < 0) continue;
      // The jump between the layers' mean depths: the window sums of neighbouring levels overlap.
      const float mean_index = is[p] / c[p];
      if (std::abs(mean_index - o.index) < options.min_jump_frames) continue;
      Layer& b = behind[size_t(p)];
      if (c[p] > b.support) b = {k, std::exp(ls[p] / c[p]), mean_index, c[p]};
    }
  });

  std::vector<Candidate> candidates;
  for (int p = 0; p < pixels; ++p) {
    const Layer& o = occluder[size_t(p)];
    const Layer& b = behind[size_t(p)];
    if (o.level < 0 || b.level < 0) continue;
    // Each layer's frames are centred on its pixels' mean depth.
    candidates.push_back({p, {std::clamp(int(std::lround(o.index)), 0, n - 1), std::clamp(int(std::lround(b.index)), 0, n - 1)}});
  }
  DepthResult out;
  out.depth_um = first.depth_um.clone();
  out.confidence = first.confidence.clone();
  out.all_in_focus = first.all_in_focus.clone();
  out.valid_fraction = first.valid_fraction;
  out.frame_count = first.frame_count;
  if (figures) *figures = {double(candidates.size()) / pixels, 0.0};
  if (candidates.empty()) return out;

  // Pass 2: each candidate's focus and pixel values (every channel) in its two layers' frames.
  std::vector<float> focus(candidates.size() * 2 * slots, -1.f);
  std::vector<uint16_t> value(candidates.size() * 2 * slots * size_t(channels), 0);
  for (int i = 0; i < n; ++i) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, load(i));
    INSPECT_RETURN_IF_ERROR(measure(f, &score_f));
    const float* s = score_f.ptr<float>();
    for (size_t c = 0; c < candidates.size(); ++c) {
      for (int l = 0; l < 2; ++l) {
        const int slot = i - (candidates[c].layer[l] - hw);
        if (slot < 0 || slot >= slots) continue;
        const size_t at = (c * 2 + size_t(l)) * slots + size_t(slot);
        const int p = candidates[c].pixel;
        focus[at] = s[p];
        for (int ch = 0; ch < channels; ++ch) {
          const size_t from = size_t(p) * size_t(channels) + size_t(ch);
          value[at * size_t(channels) + size_t(ch)] = f.depth() == CV_8U ? f.ptr<uint8_t>()[from] : f.ptr<uint16_t>()[from];
        }
      }
    }
  }

  // Decision (z order): a candidate that shows none of the occluder's sharp content (its focus
  // in the occluder's frames is below max_other_layer_ratio of the occluder's typical value: the
  // occluder's edge does not reach it, only its blur can), whose depth is not the surface
  // behind's, and whose focus in that surface's frames is consistent with it, is that surface.
  size_t moved = 0;
  float* depth = out.depth_um.ptr<float>();
  const float* idx = index.ptr<float>();
  for (size_t c = 0; c < candidates.size(); ++c) {
    const int p = candidates[c].pixel;
    const Layer* layer[2] = {&occluder[size_t(p)], &behind[size_t(p)]};
    double ratio[2] = {0, 0};
    int best[2] = {0, 0};
    for (int l = 0; l < 2; ++l) {
      const int k = candidates[c].layer[l];
      const int a = std::max(0, k - hw), b = std::min(n - 1, k + hw);
      const float* f = &focus[(c * 2 + size_t(l)) * slots];
      int m = a;
      for (int i = a + 1; i <= b; ++i)
        if (f[i - (k - hw)] > f[m - (k - hw)]) m = i;
      best[l] = m;
      ratio[l] = f[m - (k - hw)] / layer[l]->typical;
    }
    const int kb = candidates[c].layer[1];
    if (ratio[0] >= options.max_other_layer_ratio) continue;  // shows the occluder: keep
    if (std::isfinite(idx[p]) && std::abs(idx[p] - float(kb)) <= float(hw) + 0.5f) continue;  // already behind
    if (ratio[1] < options.min_layer_focus_ratio) continue;  // not that surface's texture either
    if (peak.ptr<float>()[p] < options.min_own_peak_ratio * layer[1]->typical) continue;  // no outshining blur
    const int a = std::max(0, kb - hw), b = std::min(n - 1, kb + hw);
    const int m = best[1];
    const float* f = &focus[(c * 2 + 1) * slots];
    if (m > a && m < b) {
      // Its own peak inside the surface's frames: interpolate as the engine does.
      const int reach = sff.interpolation == DepthInterpolation::kLineFit ? sff.linefit_half_width : 1;
      const int before = std::min(reach, m - a), after = std::min(reach, b - m);
      double zs[2 * 4 + 1], fs[2 * 4 + 1];
      for (int i = -before; i <= after; ++i) {
        zs[i + before] = z_um[size_t(m + i)];
        fs[i + before] = f[m + i - (kb - hw)];
      }
      depth[p] = float(InterpolatePeak(sff.interpolation, zs, fs, before, after).z_um);
    } else if (options.depth_from_surface_without_peak) {
      // No peak of its own under the occluder's blur: the surface's depth around it.
      const float t = layer[1]->index;
      const int k0 = std::clamp(int(std::floor(t)), 0, n - 2);
      depth[p] = float(z_um[size_t(k0)] + (t - k0) * (z_um[size_t(k0 + 1)] - z_um[size_t(k0)]));
    }
    // All-in-focus: the frame where the occluder is in focus, so its blur does not shine
    // through (its own layer's frame would show the surface sharp but veiled by that blur).
    const size_t at = options.all_in_focus_from_occluder_focus
                          ? (c * 2) * slots + size_t(hw)
                          : (c * 2 + 1) * slots + size_t(std::clamp(m, a, b) - (kb - hw));
    for (int ch = 0; ch < channels; ++ch) {
      const uint16_t v = value[at * size_t(channels) + size_t(ch)];
      const size_t to = size_t(p) * size_t(channels) + size_t(ch);
      if (out.all_in_focus.depth() == CV_8U) {
        out.all_in_focus.ptr<uint8_t>()[to] = uint8_t(v);
      } else {
        out.all_in_focus.ptr<uint16_t>()[to] = v;
      }
    }
    ++moved;
  }
  size_t valid = 0;
  for (int p = 0; p < pixels; ++p) valid += std::isfinite(depth[p]) ? 1 : 0;
  out.valid_fraction = double(valid) / pixels;
  if (figures) figures->reassigned_fraction = double(moved) / pixels;
  return out;
}

}  // namespace inspection
