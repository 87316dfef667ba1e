// Correlation focus measure (thesis 5.4.2, eq. 5.24-5.26), streamed frame by frame in tiles,
// with the maximum search of ISFF and the thresholded early stop of ISFF-FAST (thesis 6.4.4).
#include "core/sff/ncc_focus.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>

#include "core/sff/internal/ncc_kernel.h"
#include "core/util/parallel_for.h"

namespace inspection {
namespace {

using ncc_kernel::Scratch;
using ncc_kernel::TemplateStats;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr int kMaxJ = 4;

bool SupportedType(int type) { return type == CV_8UC1 || type == CV_16UC1 || type == CV_32FC1; }

// One state plane. Zero-filled at allocation, so the memory is touched (page faults) while the
// engine is created rather than during the first frame's search.
template <typename T>
class StatePlane {
 public:
  void Allocate(size_t n) {
    data_.reset(new T[n]());
    size_ = n;
  }
  void Release() {
    data_.reset();
    size_ = 0;
  }
  T* data() { return data_.get(); }
  T& operator[](size_t i) { return data_[i]; }
  const T& operator[](size_t i) const { return data_[i]; }
  size_t size() const { return size_; }

 private:
  std::unique_ptr<T[]> data_;
  size_t size_ = 0;
};

Status CheckWindow(int px, int lo, const char* field) {
  if (px < lo || px > 31 || px % 2 == 0) {
    return Status::InvalidArgument(std::string(field) + " must be odd and in " + std::to_string(lo) + "..31");
  }
  return Status::Ok();
}

}  // namespace

const char* CorrelationFocusValueName(CorrelationFocusValue v) {
  return v == CorrelationFocusValue::kShiftedSum ? "shifted_sum" : "contrast_weighted";
}

Status NccFocusOptions::Validate() const {
  INSPECT_RETURN_IF_ERROR(CheckWindow(correlation_window_px, 3, "correlation_window_px"));
  INSPECT_RETURN_IF_ERROR(CheckWindow(summation_window_px, 1, "summation_window_px"));
  if (linefit_half_width < 1 || linefit_half_width > kMaxJ) {
    return Status::InvalidArgument("linefit_half_width must be 1..4");
  }
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) {
    return Status::InvalidArgument("min_confidence must be between 0 and 1");
  }
  if (!(stop_threshold > 0.0 && stop_threshold <= 1.0)) {
    return Status::InvalidArgument("fast_threshold must be in (0, 1] (a normalised correlation)");
  }
  if (tile_px < 8 || tile_px > 256) return Status::InvalidArgument("tile_px must be 8..256");
  if (threads < 0) return Status::InvalidArgument("threads must be >= 0");
  return Status::Ok();
}

Status ComputeNccFocus(const cv::Mat& frame, const cv::Mat& focused_template, int correlation_window_px,
                       int summation_window_px, CorrelationFocusValue value, cv::Mat* ncc, cv::Mat* focus) {
  INSPECT_RETURN_IF_ERROR(CheckWindow(correlation_window_px, 3, "correlation_window_px"));
  INSPECT_RETURN_IF_ERROR(CheckWindow(summation_window_px, 1, "summation_window_px"));
  if (!SupportedType(frame.type()) || !SupportedType(focused_template.type())) {
    return Status::InvalidArgument("frame and template must be single-channel 8-bit, 16-bit or float images");
  }
  if (frame.size() != focused_template.size() || frame.empty()) {
    return Status::InvalidArgument("frame and template must have one (non-empty) size");
  }
  if (ncc == nullptr) return Status::InvalidArgument("ncc output is null");
  // Straightforward double-precision box sums: the reference the tiled engine is tested against.
  cv::Mat w, t;
  frame.convertTo(w, CV_64F);
  focused_template.convertTo(t, CV_64F);
  w -= cv::mean(w)[0];
  t -= cv::mean(t)[0];
  const cv::Size k(correlation_window_px, correlation_window_px);
  const double n = double(k.area());
  cv::Mat sw, st, sww, stt, swt;
  cv::boxFilter(w, sw, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  cv::boxFilter(t, st, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  cv::boxFilter(w.mul(w), sww, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  cv::boxFilter(t.mul(t), stt, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  cv::boxFilter(w.mul(t), swt, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  ncc->create(frame.size(), CV_32FC1);
  cv::Mat per_pixel(frame.size(), CV_64FC1);  // C + 1, or C sigma_w
  for (int y = 0; y < frame.rows; ++y)
    for (int x = 0; x < frame.cols; ++x) {
      const double vw = n * sww.at<double>(y, x) - sw.at<double>(y, x) * sw.at<double>(y, x);
      const double vt = n * stt.at<double>(y, x) - st.at<double>(y, x) * st.at<double>(y, x);
      double c = 0.0;
      if (vw > 1e-9 * n * sww.at<double>(y, x) && vw > 0 && vt > 1e-12 * n * stt.at<double>(y, x) && vt > 0) {
        c = std::clamp((n * swt.at<double>(y, x) - sw.at<double>(y, x) * st.at<double>(y, x)) / std::sqrt(vw * vt),
                       -1.0, 1.0);
      }
      ncc->at<float>(y, x) = float(c);
      // sigma_w = sqrt(vw) / n.
      per_pixel.at<double>(y, x) =
          value == CorrelationFocusValue::kShiftedSum ? c + 1.0 : c * std::sqrt(std::max(vw, 0.0)) / n;
    }
  if (focus != nullptr) {
    cv::Mat f;
    cv::boxFilter(per_pixel, f, CV_64F, {summation_window_px, summation_window_px}, {-1, -1}, false,
                  cv::BORDER_REFLECT_101);
    f.convertTo(*focus, CV_32F);
  }
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------
// Engine.

struct NccFocusEngine::Impl {
  NccFocusOptions o;
  cv::Size size;
  int frame_type = CV_8UC1;
  int threads = 1;
  int J = 1;   // values kept on each side of the maximum
  int Jr = 2;  // ring of the last values: max(J, 2)
  TemplateStats ts;
  std::vector<double> z;
  bool finished = false;

  // State planes (one entry per pixel).
  StatePlane<float> best, best_ncc, sum, curv_all, curv_excl, aif;
  StatePlane<float> before, after, ring;  // J, J, Jr planes
  StatePlane<int16_t> idx;
  std::vector<uint8_t> phase;  // 0 searching, 1 local maximum found (filling `after`), 2 stopped
  StatePlane<int16_t> n_seen;  // ISFF-FAST: frames the pixel saw (set when it stops)

  // Tiles.
  std::vector<cv::Rect> tiles;
  std::vector<int> tile_searching;    // pixels of the tile not stopped
  std::vector<cv::Rect> tile_active;  // bounding box of those pixels: what is computed
  std::vector<Scratch> scratch;
  std::vector<std::vector<float>> fm_buf, nm_buf;
  NccWorkCounters work;
  cv::Mat max_index, frames_searched;

  size_t Plane(int p) const { return size_t(p) * size.area(); }

  // Bounding box of the pixels of T that are still searching (T if none stopped).
  cv::Rect SearchingBox(const cv::Rect& T) const {
    int x0 = T.x + T.width, x1 = T.x - 1, y0 = T.y + T.height, y1 = T.y - 1;
    for (int y = T.y; y < T.y + T.height; ++y) {
      const uint8_t* ph = phase.data() + size_t(y) * size.width;
      for (int x = T.x; x < T.x + T.width; ++x) {
        if (ph[x] == 2) continue;
        x0 = std::min(x0, x);
        x1 = std::max(x1, x);
        y0 = std::min(y0, y);
        y1 = std::max(y1, y);
      }
    }
    return x1 < x0 ? cv::Rect(T.x, T.y, 0, 0) : cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1);
  }

  // Updates the state of the tile's pixels with their focus values and mean NCC of frame k.
  template <typename P>
  int64_t UpdateTile(const cv::Rect& T, const float* fm, const float* nm, const cv::Mat& frame, int k, int* searching) {
    const float stop_ncc = float(o.stop_threshold);
    const bool fast = o.stop_at_first_maximum;
    // Plane base pointers: ring[0] is the last value, ring[1] the one before.
    float* const ring0 = ring.data();
    float* const ring1 = ring.data() + Plane(1);  // Jr >= 2
    int64_t updated = 0;
    for (int y = T.y; y < T.y + T.height; ++y) {
      const P* fr = frame.ptr<P>(y);
      const float* f_row = fm + size_t(y - T.y) * T.width;
      const float* n_row = nm + size_t(y - T.y) * T.width;
      const size_t row = size_t(y) * size.width;
      for (int x = T.x; x < T.x + T.width; ++x) {
        const size_t i = row + x;
        const uint8_t ph = phase[i];
        if (ph == 2) continue;
        ++updated;
        const float F = f_row[x - T.x];
        float t2 = 0.f;
        if (k >= 2) {
          const float t = F - 2.f * ring0[i] + ring1[i];
          t2 = t * t;
          curv_all[i] += t2;
        } else if (k == 0) {
          sum[i] = 0.f;
          curv_all[i] = 0.f;
        }
        if (ph == 0 && (k == 0 || F > best[i])) {
          best[i] = F;
          best_ncc[i] = n_row[x - T.x];
          idx[i] = int16_t(k);
          for (int t = 0; t < J; ++t) before[Plane(t) + i] = ring[Plane(t) + i];
          curv_excl[i] = t2;
          aif[i] = float(fr[x]);
        } else {
          const int d = k - idx[i];
          if (d <= J) after[Plane(d - 1) + i] = F;
          if (d <= 2 && k >= 2) curv_excl[i] += t2;
          if (fast) {
            // The running maximum followed by a lower value is the first local maximum (an
            // earlier, higher hump would have had its own maximum above the threshold).
            if (ph == 0 && d == 1 && F < best[i] && best_ncc[i] >= stop_ncc) phase[i] = 1;
            if (phase[i] == 1 && d >= J) {
              phase[i] = 2;
              n_seen[i] = int16_t(k + 1);
              --*searching;
            }
          }
        }
        sum[i] += F;
        for (int t = Jr - 1; t > 1; --t) ring[Plane(t) + i] = ring[Plane(t - 1) + i];
        ring1[i] = ring0[i];
        ring0[i] = F;
      }
    }
    return updated;
  }
};

NccFocusEngine::NccFocusEngine(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
NccFocusEngine::~NccFocusEngine() = default;

StatusOr<std::unique_ptr<NccFocusEngine>> NccFocusEngine::Create(const NccFocusOptions& options,
                                                                 const cv::Mat& focused_template, int frame_type) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (frame_type != CV_8UC1 && frame_type != CV_16UC1) {
    return Status::InvalidArgument("frame type must be 8-bit or 16-bit single channel");
  }
  if (focused_template.empty() || !SupportedType(focused_template.type())) {
    return Status::InvalidArgument("focused template must be a non-empty single-channel 8-bit, 16-bit or float image");
  }
  if (!cv::checkRange(focused_template)) return Status::InvalidArgument("focused template has non-finite values");
  if (focused_template.rows < 2 || focused_template.cols < 2) {
    return Status::InvalidArgument("focused template must be at least 2 x 2 pixels");
  }
  auto impl = std::make_unique<Impl>();
  Impl& m = *impl;
  m.o = options;
  m.size = focused_template.size();
  m.frame_type = frame_type;
  m.threads = ResolveThreads(options.threads);
  m.J = options.interpolation == DepthInterpolation::kLineFit ? options.linefit_half_width : 1;
  m.Jr = std::max(m.J, 2);
  m.ts = ncc_kernel::MakeTemplateStats(focused_template, options.correlation_window_px);
  const size_t A = m.size.area();
  for (StatePlane<float>* p : {&m.best, &m.best_ncc, &m.sum, &m.curv_all, &m.curv_excl, &m.aif}) p->Allocate(A);
  m.before.Allocate(A * m.J);
  m.after.Allocate(A * m.J);
  m.ring.Allocate(A * m.Jr);
  m.idx.Allocate(A);
  m.n_seen.Allocate(A);
  m.phase.assign(A, 0);
  const int tp = options.tile_px;
  for (int y = 0; y < m.size.height; y += tp)
    for (int x = 0; x < m.size.width; x += tp)
      m.tiles.emplace_back(x, y, std::min(tp, m.size.width - x), std::min(tp, m.size.height - y));
  m.tile_searching.resize(m.tiles.size());
  for (size_t t = 0; t < m.tiles.size(); ++t) m.tile_searching[t] = m.tiles[t].area();
  m.tile_active = m.tiles;
  m.scratch.resize(m.threads);
  m.fm_buf.resize(m.threads);
  m.nm_buf.resize(m.threads);
  return std::unique_ptr<NccFocusEngine>(new NccFocusEngine(std::move(impl)));
}

Status NccFocusEngine::PushFrame(const cv::Mat& frame, double z_um) {
  Impl& m = *impl_;
  const int k = int(m.z.size());
  const std::string name = "frame " + std::to_string(k);
  if (m.finished) return Status::FailedPrecondition("NCC engine: " + name + " pushed after Finish");
  if (frame.type() != m.frame_type || frame.size() != m.size) {
    return Status::InvalidArgument(name + ": size or type differs from the template / first frame");
  }
  if (!std::isfinite(z_um)) return Status::InvalidArgument(name + ": z_um is not finite");
  if (k >= 2 && (z_um - m.z[k - 1]) * (m.z[1] - m.z[0]) <= 0) {
    return Status::InvalidArgument(name + ": z_um breaks the monotonic z order of the stack");
  }
  if (k == 1 && z_um == m.z[0]) return Status::InvalidArgument(name + ": z_um equals the previous frame's");
  if (k >= std::numeric_limits<int16_t>::max()) return Status::InvalidArgument(name + ": too many frames");
  m.z.push_back(z_um);

  std::vector<int> active;
  active.reserve(m.tiles.size());
  for (size_t t = 0; t < m.tiles.size(); ++t)
    if (m.tile_searching[t] > 0) active.push_back(int(t));
  m.work.tile_frames += int64_t(active.size());
  m.work.tile_frames_full += int64_t(m.tiles.size());
  m.work.computed_pixel_frames_full += int64_t(m.size.area());
  for (int t : active) m.work.computed_pixel_frames += m.tile_active[t].area();
  std::atomic<int64_t> updated{0};
  const int hs = m.o.summation_window_px / 2;
  ParallelFor(int(active.size()), m.threads, [&](int a, int worker) {
    const int t = active[a];
    const cv::Rect T = m.tile_active[t];
    std::vector<float>& fm = m.fm_buf[worker];
    std::vector<float>& nm = m.nm_buf[worker];
    fm.resize(size_t(T.area()));
    nm.resize(size_t(T.area()));
    ncc_kernel::TileFocus(frame, m.ts, hs, m.o.focus_value, T, m.scratch[worker], fm.data(), nm.data());
    int64_t u = 0;
    const int searching_before = m.tile_searching[t];
    if (frame.depth() == CV_8U)
      u = m.UpdateTile<uint8_t>(T, fm.data(), nm.data(), frame, k, &m.tile_searching[t]);
    else
      u = m.UpdateTile<uint16_t>(T, fm.data(), nm.data(), frame, k, &m.tile_searching[t]);
    // ISFF-FAST: the next frame is computed only over the box of the pixels still searching
    // (the NCC of a pixel needs its neighbours' patches, so a box, not a pixel list).
    if (m.tile_searching[t] != searching_before && m.tile_searching[t] > 0) m.tile_active[t] = m.SearchingBox(T);
    updated += u;
  });
  m.work.pixel_frames += updated.load();
  return Status::Ok();
}

StatusOr<DepthResult> NccFocusEngine::Finish() {
  Impl& m = *impl_;
  if (m.finished) return Status::FailedPrecondition("NCC engine: Finish called twice");
  const int n_total = int(m.z.size());
  if (n_total < 3) {
    return Status::InvalidArgument("a stack needs at least 3 frames, got " + std::to_string(n_total));
  }
  m.finished = true;
  DepthResult r;
  r.frame_count = n_total;
  r.depth_um.create(m.size, CV_32FC1);
  r.confidence.create(m.size, CV_32FC1);
  cv::Mat aif_f(m.size, CV_32FC1);
  m.max_index.create(m.size, CV_16SC1);
  m.frames_searched.create(m.size, CV_16SC1);
  const int J = m.J;
  std::atomic<size_t> valid{0};
  std::atomic<int64_t> stopped{0};
  ParallelFor(m.size.height, m.threads, [&](int y, int) {
    size_t v = 0;
    int64_t st = 0;
    double zw[2 * kMaxJ + 1], fw[2 * kMaxJ + 1];
    for (int x = 0; x < m.size.width; ++x) {
      const size_t i = size_t(y) * m.size.width + x;
      const bool has_stopped = m.phase[i] == 2;
      st += has_stopped;
      const int n = has_stopped ? m.n_seen[i] : n_total;
      const int mi = m.idx[i];
      const int before = std::min(J, mi), after = std::min(J, n - 1 - mi);
      zw[before] = m.z[mi];
      fw[before] = m.best[i];
      for (int t = 1; t <= before; ++t) {
        zw[before - t] = m.z[mi - t];
        fw[before - t] = m.before[m.Plane(t - 1) + i];
      }
      for (int t = 1; t <= after; ++t) {
        zw[before + t] = m.z[mi + t];
        fw[before + t] = m.after[m.Plane(t - 1) + i];
      }
      FocusCurveSummary s;
      s.peak = m.best[i];
      s.mean = double(m.sum[i]) / n;
      const int excluded = std::max(0, std::min(n - 1, mi + 2) - std::max(2, mi) + 1);
      s.curvature_sq_sum = double(m.curv_all[i]) - double(m.curv_excl[i]);
      s.curvature_count = std::max(0, n - 2) - excluded;
      s.peak_at_end = mi == 0 || mi == n_total - 1;
      s.flank_terms = FlankTermCount(mi, n);
      const float c = FocusConfidence(s);
      r.confidence.at<float>(y, x) = c;
      if (c >= m.o.min_confidence) {
        // Only kept pixels are interpolated (the logarithms are the costly part).
        const double z_um = IsThreePointMethod(m.o.interpolation) && before == 1 && after == 1
                                ? ThreePointPeakZ(m.o.interpolation, zw[0], zw[1], zw[2], fw[0], fw[1], fw[2])
                                : InterpolatePeak(m.o.interpolation, zw, fw, before, after).z_um;
        r.depth_um.at<float>(y, x) = float(z_um);
        ++v;
      } else {
        r.depth_um.at<float>(y, x) = kNaN;
      }
      aif_f.at<float>(y, x) = m.aif[i];
      m.max_index.at<int16_t>(y, x) = int16_t(mi);
      m.frames_searched.at<int16_t>(y, x) = int16_t(n);
    }
    valid += v;
    stopped += st;
  });
  m.work.stopped_pixels = stopped.load();
  aif_f.convertTo(r.all_in_focus, m.frame_type);
  r.valid_fraction = double(valid.load()) / double(m.size.area());
  // Release the state: the engine is done.
  for (StatePlane<float>* p :
       {&m.best, &m.best_ncc, &m.sum, &m.curv_all, &m.curv_excl, &m.aif, &m.before, &m.after, &m.ring}) {
    p->Release();
  }
  m.idx.Release();
  m.n_seen.Release();
  std::vector<uint8_t>().swap(m.phase);
  return r;
}

int NccFocusEngine::frames_pushed() const { return int(impl_->z.size()); }

size_t NccFocusEngine::state_bytes() const {
  const Impl& m = *impl_;
  const size_t planes = m.best.size() + m.best_ncc.size() + m.sum.size() + m.curv_all.size() + m.curv_excl.size() +
                        m.aif.size() + m.before.size() + m.after.size() + m.ring.size();
  return planes * sizeof(float) + m.idx.size() * 2 + m.phase.size() + m.n_seen.size() * 2 + m.ts.t_pad.total() * 4 +
         m.ts.t_sum.total() * 4 + m.ts.t_inv.total() * 4;
}

const NccWorkCounters& NccFocusEngine::work() const { return impl_->work; }
const cv::Mat& NccFocusEngine::max_index() const { return impl_->max_index; }
const cv::Mat& NccFocusEngine::frames_searched() const { return impl_->frames_searched; }

}  // namespace inspection
