// Automatic z range: focus curves of a coarse sweep on a reduced grid, their resolved peaks and
// the percentile range (z_range_search.h; thesis eq. 3.14 and 3.3.3).
#include "core/sff/z_range_search.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "core/sff/depth_interpolation.h"

namespace inspection {

Status ZRangeSearchOptions::Validate() const {
  if (downsample < 1 || downsample > 16) return Status::InvalidArgument("downsample must be in [1, 16]");
  if (window_px < 3 || window_px > 15 || window_px % 2 == 0) {
    return Status::InvalidArgument("window_px must be odd, 3..15");
  }
  if (!(min_peak_ratio > 1.0)) return Status::InvalidArgument("min_peak_ratio must be > 1");
  if (!(tail_percent >= 0.0 && tail_percent < 50.0)) return Status::InvalidArgument("tail_percent must be in [0, 50)");
  if (!(min_resolved_percent > 0.0 && min_resolved_percent <= 100.0)) {
    return Status::InvalidArgument("min_resolved_percent must be in (0, 100]");
  }
  if (!(max_saturated_share > 0.0 && max_saturated_share <= 1.0)) {
    return Status::InvalidArgument("max_saturated_share must be in (0, 1]");
  }
  if (!(min_bin_percent >= 0.0 && min_bin_percent < 100.0))
    return Status::InvalidArgument("min_bin_percent must be in [0, 100)");
  if (!(min_cluster_percent >= 0.0 && min_cluster_percent <= 100.0)) {
    return Status::InvalidArgument("min_cluster_percent must be in [0, 100]");
  }
  if (!(stop_settled_percent >= 0.0 && stop_settled_percent <= 100.0)) {
    return Status::InvalidArgument("stop_settled_percent must be in [0, 100]");
  }
  return Status::Ok();
}

StatusOr<ZRangeAccumulator> ZRangeAccumulator::Create(const ZRangeSearchOptions& options,
                                                              cv::Size frame_size, int bit_depth) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (bit_depth < 8 || bit_depth > 16) return Status::InvalidArgument("bit_depth must be in [8, 16]");
  if (frame_size.width < 4 * options.downsample || frame_size.height < 4 * options.downsample) {
    return Status::InvalidArgument("frame size " + std::to_string(frame_size.width) + "x" +
                                   std::to_string(frame_size.height) + " is too small for downsample " +
                                   std::to_string(options.downsample));
  }
  ZRangeAccumulator a;
  a.options_ = options;
  a.frame_size_ = frame_size;
  a.bit_depth_ = bit_depth;
  return a;
}

Status ZRangeAccumulator::Reduce(const cv::Mat& frame, double z_um, const std::string& name, cv::Mat* energy,
                                     cv::Mat* saturated) const {
  if (frame.size() != frame_size_ || (frame.type() != CV_8UC1 && frame.type() != CV_16UC1)) {
    return Status::InvalidArgument(name + ": expected a CV_8UC1/CV_16UC1 frame of the camera size");
  }
  if (!std::isfinite(z_um)) return Status::InvalidArgument(name + ": z_um must be finite");
  // Grey levels on one scale whatever the bit depth, so min_peak_ratio means the same.
  cv::Mat f;
  frame.convertTo(f, CV_32F, frame.depth() == CV_16U ? 1.0 / 257.0 : 1.0);
  const double max_value = frame.depth() == CV_16U ? double((1 << bit_depth_) - 1) : 255.0;
  cv::compare(frame, max_value, *saturated, cv::CMP_GE);
  saturated->convertTo(*saturated, CV_32F, 1.0 / 255.0);
  const int d = options_.downsample;
  const cv::Size reduced(frame_size_.width / d, frame_size_.height / d);
  cv::Mat small;
  if (d > 1) {
    cv::resize(f, small, reduced, 0, 0, cv::INTER_AREA);
    cv::resize(*saturated, *saturated, reduced, 0, 0, cv::INTER_AREA);
  } else {
    small = f;
  }
  const cv::Size window(options_.window_px, options_.window_px);
  cv::boxFilter(*saturated, *saturated, CV_32F, window, cv::Point(-1, -1), true, cv::BORDER_REFLECT);
  cv::Mat gx, gy;
  cv::Sobel(small, gx, CV_32F, 1, 0, 3, 1.0, 0.0, cv::BORDER_REFLECT);
  cv::Sobel(small, gy, CV_32F, 0, 1, 3, 1.0, 0.0, cv::BORDER_REFLECT);
  *energy = gx.mul(gx) + gy.mul(gy);
  cv::boxFilter(*energy, *energy, CV_32F, window, cv::Point(-1, -1), true, cv::BORDER_REFLECT);
  return Status::Ok();
}

Status ZRangeAccumulator::PushFrame(const cv::Mat& frame, double z_um) {
  const std::string name = "coarse frame " + std::to_string(z_um_.size());
  if (!refine_centres_.empty()) return Status::FailedPrecondition(name + ": the sweep's refinement is planned already");
  cv::Mat energy, saturated;
  INSPECT_RETURN_IF_ERROR(Reduce(frame, z_um, name, &energy, &saturated));
  if (z_um_.size() >= 2 && (z_um - z_um_.back()) * (z_um_[1] - z_um_[0]) <= 0.0) {
    return Status::InvalidArgument(name + ": z_um breaks the monotonic order of the sweep");
  }
  if (z_um_.size() == 1 && z_um == z_um_[0]) return Status::InvalidArgument(name + ": z_um repeats frame 0");
  saturated_.push_back(saturated);
  if (focus_.empty()) {
    max_ = energy.clone();
    min_ = energy.clone();
    argmax_ = cv::Mat::zeros(energy.size(), CV_32SC1);
  } else {
    const int k = int(focus_.size());
    for (int r = 0; r < energy.rows; ++r) {
      const float* e = energy.ptr<float>(r);
      float* f_max = max_.ptr<float>(r);
      float* f_min = min_.ptr<float>(r);
      int* best = argmax_.ptr<int>(r);
      for (int c = 0; c < energy.cols; ++c) {
        if (e[c] > f_max[c]) {
          f_max[c] = e[c];
          best[c] = k;
        }
        f_min[c] = std::min(f_min[c], e[c]);
      }
    }
  }
  focus_.push_back(energy);
  z_um_.push_back(z_um);
  return Status::Ok();
}

bool ZRangeAccumulator::PeakIsFocus(int r, int c) const {
  const int n = frames();
  const int best = argmax_.at<int>(r, c);
  const float f_max = max_.at<float>(r, c);
  // The floor: noise and the texture's residue far from focus. A curve that never leaves it
  // (textureless, or focus outside the window) resolves nothing.
  if (!(f_max >= options_.min_peak_ratio * std::max(double(min_.at<float>(r, c)), 1e-6))) return false;
  // Sharpness: two coarse steps away the curve must have fallen by min_sharpness (a focus peak;
  // a defocused highlight's halo changes slowly and fails).
  float f_far = 0.0f;
  if (best >= 2) f_far = std::max(f_far, focus_[size_t(best - 2)].at<float>(r, c));
  if (best + 2 < n) f_far = std::max(f_far, focus_[size_t(best + 2)].at<float>(r, c));
  if (!(f_max >= options_.min_sharpness * f_far)) return false;
  return saturated_[size_t(best)].at<float>(r, c) <= options_.max_saturated_share;
}

double ZRangeAccumulator::SettledPercent() const {
  const int n = frames();
  if (n < 3) return 0.0;
  long settled = 0;
  for (int r = 0; r < max_.rows; ++r) {
    const int* best = argmax_.ptr<int>(r);
    for (int c = 0; c < max_.cols; ++c) {
      // Finish's tests, with the frame two past the peak taken; the peak need not have a frame
      // below it (focus at or below the window's start is passed too).
      if (best[c] + 2 < n && PeakIsFocus(r, c)) ++settled;
    }
  }
  return 100.0 * double(settled) / double(max_.total());
}

Status ZRangeAccumulator::PushRefinementFrame(const cv::Mat& frame, double z_um) {
  const std::string name = "refinement frame " + std::to_string(refine_z_um_.size());
  cv::Mat energy, saturated;
  INSPECT_RETURN_IF_ERROR(Reduce(frame, z_um, name, &energy, &saturated));
  if (refine_centres_.empty()) return Status::FailedPrecondition(name + ": no refinement planned (PlanRefinement)");
  auto at = [z_um](double z) { return std::abs(z - z_um) < 1e-6; };
  if (std::none_of(refine_planned_z_um_.begin(), refine_planned_z_um_.end(), at)) {
    return Status::InvalidArgument(name + ": z_um " + std::to_string(z_um) + " is not a planned refinement position");
  }
  if (std::any_of(refine_z_um_.begin(), refine_z_um_.end(), at)) {
    return Status::InvalidArgument(name + ": z_um " + std::to_string(z_um) + " was refined already");
  }
  refine_z_um_.push_back(z_um);
  refine_focus_.push_back(std::move(energy));
  refine_saturated_.push_back(std::move(saturated));
  return Status::Ok();
}

std::vector<double> ZRangeAccumulator::PlanRefinement(const ZRangeEstimate& first) {
  std::vector<double> out;
  const int n = frames();
  if (n < 3) return out;
  auto nearest = [&](double z) {
    int k = 0;
    for (int i = 1; i < n; ++i) {
      if (std::abs(z_um_[size_t(i)] - z) < std::abs(z_um_[size_t(k)] - z)) k = i;
    }
    return k;
  };
  auto taken = [&](double z) {  // both ends may share a coarse frame or a neighbour
    return std::any_of(out.begin(), out.end(), [z](double t) { return std::abs(t - z) < 1e-6; });
  };
  for (double end : {first.z_low_um, first.z_high_um}) {
    const int k = nearest(end);
    if (std::find(refine_centres_.begin(), refine_centres_.end(), k) == refine_centres_.end()) {
      refine_centres_.push_back(k);
    }
    for (int side : {-1, 1}) {
      const int j = k + side;
      if (j < 0 || j >= n) continue;
      const double z = 0.5 * (z_um_[size_t(k)] + z_um_[size_t(j)]);
      if (!taken(z)) out.push_back(z);
    }
  }
  std::sort(out.begin(), out.end());
  refine_planned_z_um_.insert(refine_planned_z_um_.end(), out.begin(), out.end());
  return out;
}

// See PeakZ: 1/e^2.
constexpr double kSecondSourceRise = 0.135;

float ZRangeAccumulator::PeakZ(int r, int c, int best) const {
  const double z_prev = z_um_[size_t(best - 1)], z_next = z_um_[size_t(best + 1)];
  const double z_min = std::min(z_prev, z_next), z_max = std::max(z_prev, z_next);
  // Samples (z, F, saturated share) of the curve from the coarse neighbours' z to the maximum's
  // other neighbour: the three coarse ones and the refinement frames between them.
  struct Sample {
    double z, f, saturated;
  };
  // PlanRefinement places at most two between a frame's neighbours; more pushed by hand are
  // taken up to the array's size.
  Sample s[3 + 8];
  int count = 0;
  for (int i = best - 1; i <= best + 1; ++i) {
    s[count++] = {z_um_[size_t(i)], focus_[size_t(i)].at<float>(r, c), saturated_[size_t(i)].at<float>(r, c)};
  }
  const bool centred = std::find(refine_centres_.begin(), refine_centres_.end(), best) != refine_centres_.end();
  for (size_t i = 0; centred && i < refine_z_um_.size() && count < 11; ++i) {
    const double z = refine_z_um_[i];
    if (z > z_min && z < z_max) {
      s[count++] = {z, refine_focus_[i].at<float>(r, c), refine_saturated_[i].at<float>(r, c)};
    }
  }
  if (count == 3) return float(DefocusParabolaPeakZ(s[0].z, s[1].z, s[2].z, s[0].f, s[1].f, s[2].f));
  for (int i = 1; i < count; ++i) {  // by z (a few samples: insertion)
    for (int j = i; j > 0 && s[j].z < s[j - 1].z; --j) std::swap(s[j], s[j - 1]);
  }
  int m = 0;
  for (int i = 1; i < count; ++i) {
    if (s[i].f > s[m].f) m = i;
  }
  // The coarse neighbours are below the coarse maximum, so the largest sample is inside.
  if (m == 0 || m == count - 1) return std::numeric_limits<float>::quiet_NaN();
  // Away from the largest sample the curve falls; a sample rising above the one nearer the
  // peak by more than kSecondSourceRise of the peak is a second source of focus energy (a halo's
  // edge). Smaller rises are the floor's noise: the tails half a coarse step out sit at about
  // 1/e^2 of the peak by the coarse step's design (SearchPatternCoarseStepUm).
  const double rise = kSecondSourceRise * s[m].f;
  for (int i = 0; i < m; ++i) {
    if (s[i].f > s[i + 1].f + rise) return std::numeric_limits<float>::quiet_NaN();
  }
  for (int i = m; i + 1 < count; ++i) {
    if (s[i + 1].f > s[i].f + rise) return std::numeric_limits<float>::quiet_NaN();
  }
  if (s[m].saturated > options_.max_saturated_share) return std::numeric_limits<float>::quiet_NaN();
  return float(DefocusParabolaPeakZ(s[m - 1].z, s[m].z, s[m + 1].z, s[m - 1].f, s[m].f, s[m + 1].f));
}

namespace {

double Percentile(std::vector<float>& v, double percent) {
  const size_t k = std::min(v.size() - 1, size_t(std::floor(percent / 100.0 * double(v.size() - 1) + 0.5)));
  std::nth_element(v.begin(), v.begin() + long(k), v.end());
  return v[k];
}

// A peak further than one coarse step from the median of the resolved peaks around it is not a
// surface: the halo of a defocused highlight on its dark surround, or noise. A surface (tilted,
// curved or stepped) has its neighbours at its height or on both sides of it.
void RejectInconsistentPeaks(int radius, double step_um, cv::Mat* peak_z_um) {
  const cv::Mat in = peak_z_um->clone();
  std::vector<float> around;
  for (int r = 0; r < in.rows; ++r) {
    float* out = peak_z_um->ptr<float>(r);
    for (int c = 0; c < in.cols; ++c) {
      if (std::isnan(out[c])) continue;
      around.clear();
      for (int y = std::max(0, r - radius); y <= std::min(in.rows - 1, r + radius); ++y) {
        const float* p = in.ptr<float>(y);
        for (int x = std::max(0, c - radius); x <= std::min(in.cols - 1, c + radius); ++x) {
          if (!std::isnan(p[x])) around.push_back(p[x]);
        }
      }
      std::nth_element(around.begin(), around.begin() + long(around.size() / 2), around.end());
      if (std::abs(out[c] - around[around.size() / 2]) > step_um) out[c] = std::numeric_limits<float>::quiet_NaN();
    }
  }
}

// Bins of a quarter coarse step, each needing a quarter of min_bin_percent: the density
// min_bin_percent per coarse step asks for, with gaps resolved finely enough that where the
// grid falls (it starts at the lowest peak) does not decide whether a sparse halo a coarse step
// above a surface joins it (the cutter at 1024x768, seed 5: one coarse-step bin of 1.1 % bridged
// its land and the halo 15-40 um above it once the lowest peak moved by 5 um).
constexpr double kClusterBinsPerStep = 4.0;

// The peaks inside the kept clusters (ZRangeSearchOptions::min_bin_percent).
std::vector<float> ClusteredPeaks(const std::vector<float>& peaks, double step_um, const ZRangeSearchOptions& o) {
  const double bin_um = step_um / kClusterBinsPerStep;
  const auto [min_it, max_it] = std::minmax_element(peaks.begin(), peaks.end());
  const double z0 = *min_it;
  const int bins = int(std::floor((*max_it - z0) / bin_um)) + 1;
  auto bin_of = [&](float z) { return std::min(bins - 1, int(std::floor((z - z0) / bin_um))); };
  std::vector<long> count(size_t(bins), 0);
  for (float z : peaks) ++count[size_t(bin_of(z))];
  const double bin_min = o.min_bin_percent / 100.0 * double(peaks.size()) / kClusterBinsPerStep;
  // Runs of full bins; each run takes the sparse bin on either side too (the partial bin at the
  // end of a surface's range), but never bridges an empty gap.
  std::vector<int> cluster(size_t(bins), -1);
  std::vector<long> cluster_count;
  for (int b = 0; b < bins; ++b) {
    if (double(count[size_t(b)]) < bin_min) continue;
    if (b >= 1 && cluster[size_t(b - 1)] >= 0 && double(count[size_t(b - 1)]) >= bin_min) {
      cluster[size_t(b)] = cluster[size_t(b - 1)];
      continue;
    }
    cluster[size_t(b)] = int(cluster_count.size());
    cluster_count.push_back(0);
    if (b >= 1 && cluster[size_t(b - 1)] < 0) cluster[size_t(b - 1)] = cluster[size_t(b)];
  }
  for (int b = 1; b < bins; ++b) {  // the sparse bin above each run
    if (cluster[size_t(b)] < 0 && double(count[size_t(b - 1)]) >= bin_min) cluster[size_t(b)] = cluster[size_t(b - 1)];
  }
  for (int b = 0; b < bins; ++b) {
    if (cluster[size_t(b)] >= 0) cluster_count[size_t(cluster[size_t(b)])] += count[size_t(b)];
  }
  if (cluster_count.empty()) return peaks;  // all sparse: nothing to tell clutter from surface
  const long largest = *std::max_element(cluster_count.begin(), cluster_count.end());
  const double cluster_min = o.min_cluster_percent / 100.0 * double(peaks.size());
  std::vector<float> kept;
  kept.reserve(peaks.size());
  for (float z : peaks) {
    const int id = cluster[size_t(bin_of(z))];
    if (id < 0) continue;
    const long c = cluster_count[size_t(id)];
    if (c == largest || double(c) >= cluster_min) kept.push_back(z);
  }
  return kept;
}

}  // namespace

StatusOr<ZRangeEstimate> ZRangeAccumulator::Finish() const {
  const int n = frames();
  if (n < 3) return Status::FailedPrecondition("the coarse sweep needs at least 3 frames, has " + std::to_string(n));
  const cv::Size size = focus_[0].size();
  ZRangeEstimate e;
  e.peak_z_um.create(size, CV_32FC1);
  std::vector<float> peaks;
  peaks.reserve(size_t(size.area()));
  long at_first = 0, at_last = 0;
  for (int r = 0; r < size.height; ++r) {
    const int* best_row = argmax_.ptr<int>(r);
    float* out = e.peak_z_um.ptr<float>(r);
    for (int c = 0; c < size.width; ++c) {
      out[c] = std::numeric_limits<float>::quiet_NaN();
      if (!PeakIsFocus(r, c)) continue;
      // A maximum at the first or last frame says only that focus lies at or beyond the window's
      // end (or a halo grows towards it): counted, not used for the range.
      const int best = best_row[c];
      if (best == 0 || best == n - 1) {
        (best == 0 ? at_first : at_last) += 1;
        continue;
      }
      out[c] = PeakZ(r, c, best);
    }
  }
  RejectInconsistentPeaks(options_.consistency_radius, std::abs(z_um_[1] - z_um_[0]), &e.peak_z_um);
  for (int r = 0; r < size.height; ++r) {
    const float* p = e.peak_z_um.ptr<float>(r);
    for (int c = 0; c < size.width; ++c) {
      if (!std::isnan(p[c])) peaks.push_back(p[c]);
    }
  }
  e.resolved_percent = 100.0 * double(peaks.size()) / double(size.area());
  if (e.resolved_percent < options_.min_resolved_percent) {
    char buf[320];
    std::snprintf(buf, sizeof(buf),
                  "automatic z range: no focus found in the search window z %.3f .. %.3f um (%.2f %% of the field "
                  "shows a focus peak, %.2f %% needed): the specimen lacks texture under the search pattern or its "
                  "focus lies outside the window",
                  std::min(z_um_.front(), z_um_.back()), std::max(z_um_.front(), z_um_.back()), e.resolved_percent,
                  options_.min_resolved_percent);
    return Status::FailedPrecondition(buf);
  }
  e.at_first_frame_percent = 100.0 * double(at_first) / double(size.area());
  e.at_last_frame_percent = 100.0 * double(at_last) / double(size.area());
  std::vector<float> kept = ClusteredPeaks(peaks, std::abs(z_um_[1] - z_um_[0]), options_);
  e.clustered_percent = 100.0 * double(kept.size()) / double(peaks.size());
  e.z_low_um = Percentile(kept, options_.tail_percent);
  e.z_high_um = Percentile(kept, 100.0 - options_.tail_percent);
  return e;
}

double SearchPatternCoarseStepUm(double blur_radius_px_per_um, double camera_px_per_projector_px) {
  if (!(blur_radius_px_per_um > 0.0) || !(camera_px_per_projector_px > 0.0)) return 0.0;
  const double period_px = 2.0 * kSearchCellProjectorPx * camera_px_per_projector_px;
  // Rounded down to whole um (0.5 um below 2 um): a step an operator reads as it is, never
  // coarser than the optics allow.
  const double step = 2.0 * period_px / (M_PI * blur_radius_px_per_um);
  return step >= 2.0 ? std::floor(step) : std::max(0.5, std::floor(2.0 * step) / 2.0);
}

StatusOr<std::vector<double>> CoarseSweepZ(const ZRangeSearchSettings& s, double travel_min_um, double travel_max_um,
                                           int max_frames, const std::string& prefix) {
  auto fmt = [](double v) {
    char b[32];
    std::snprintf(b, sizeof(b), "%.3f", v);
    return std::string(b);
  };
  for (auto [name, z] :
       {std::pair{"window_start_um", s.window_start_um}, std::pair{"window_end_um", s.window_end_um}}) {
    if (!std::isfinite(z)) return Status::InvalidArgument(prefix + name + " must be finite");
    if (z < travel_min_um || z > travel_max_um) {
      return Status::InvalidArgument(prefix + name + " " + fmt(z) + " is outside the stage travel [" +
                                     fmt(travel_min_um) + ", " + fmt(travel_max_um) + "]");
    }
  }
  const double lo = std::min(s.window_start_um, s.window_end_um), hi = std::max(s.window_start_um, s.window_end_um);
  if (!(hi > lo)) return Status::InvalidArgument(prefix + "window_start_um and window_end_um must differ");
  if (!(s.coarse_step_um > 0.0) || !std::isfinite(s.coarse_step_um)) {
    return Status::InvalidArgument(prefix + "coarse_step_um must be > 0 (got " + fmt(s.coarse_step_um) + ")");
  }
  // Three frames at least: the peak needs its two neighbours.
  if (s.coarse_step_um > (hi - lo) / 2.0 + 1e-9) {
    return Status::InvalidArgument(prefix + "coarse_step_um " + fmt(s.coarse_step_um) +
                                   " is larger than half the search window (" + fmt(hi - lo) +
                                   " um): the sweep needs at least 3 frames");
  }
  const long steps = long(std::ceil((hi - lo) / s.coarse_step_um - 1e-6));
  if (steps + 1 > max_frames) {
    return Status::InvalidArgument(prefix + "coarse_step_um " + fmt(s.coarse_step_um) + " over the window " + fmt(lo) +
                                   " .. " + fmt(hi) + " um needs " + std::to_string(steps + 1) +
                                   " coarse frames, more than " + std::to_string(max_frames) +
                                   ": narrow the window or take a larger step");
  }
  std::vector<double> z;
  for (long i = 0; i < steps; ++i) z.push_back(lo + double(i) * s.coarse_step_um);
  z.push_back(hi);
  return z;
}

FineRange ChooseFineRange(const ZRangeEstimate& estimate, double fine_step_um, double margin_um, int min_frames,
                          double travel_min_um, double travel_max_um) {
  const double want_start = estimate.z_low_um - margin_um, want_end = estimate.z_high_um + margin_um;
  const long steps =
      std::max(long(std::max(min_frames, 3)) - 1, long(std::ceil((want_end - want_start) / fine_step_um - 1e-6)));
  const double span = double(steps) * fine_step_um;
  // The rounding to whole steps is shared by both ends; then the range is shifted, not cut, to
  // stay within the travel.
  double start = 0.5 * (want_start + want_end) - 0.5 * span;
  start = std::min(start, travel_max_um - span);
  start = std::max(start, travel_min_um);
  return {start, std::min(travel_max_um, start + span)};
}

}  // namespace inspection
