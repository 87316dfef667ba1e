// Correlation focus measure (thesis 5.4.2, eq. 5.24-5.26), streamed frame by frame in tiles,
// with the maximum search of ISFF and the thresholded early stop of ISFF-FAST (thesis 6.4.4).
#include "core/ncc_focus.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <string>
#include <system_error>
#include <thread>

#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr int kMaxJ = 4;

int Reflect101(int p, int len) {
  if (len == 1) return 0;
  while (p < 0 || p >= len) p = p < 0 ? -p : 2 * len - 2 - p;
  return p;
}

// Runs fn(task, worker) for task = 0..n_tasks-1 on up to `threads` threads (the caller's included).
template <typename F>
void ParallelFor(int n_tasks, int threads, F&& fn) {
  threads = std::max(1, std::min(threads, n_tasks));
  std::atomic<int> next{0};
  auto worker = [&](int id) {
    for (int i = next.fetch_add(1); i < n_tasks; i = next.fetch_add(1)) fn(i, id);
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) {
    try {
      pool.emplace_back(worker, t);
    } catch (const std::system_error&) {
      break;  // fewer threads; tasks are shared out dynamically anyway
    }
  }
  worker(0);
  for (auto& t : pool) t.join();
}

int ResolveThreads(int threads) {
  return threads > 0 ? threads : int(std::max(1u, std::thread::hardware_concurrency()));
}

bool SupportedType(int type) { return type == CV_8UC1 || type == CV_16UC1 || type == CV_32FC1; }

// The template's side of eq. 5.25, fixed for the whole stack: the template padded by the patch
// half-width, and per pixel the patch sum and 1 / sqrt(n sum t^2 - (sum t)^2) (0 for a flat
// patch, whose NCC is defined as 0).
struct TemplateStats {
  int hc = 0;
  int n = 0;       // pixels per patch
  cv::Mat t_pad;   // CV_32FC1, (H + 2hc) x (W + 2hc), centred on its mean (NCC ignores offsets)
  cv::Mat t_sum;   // CV_64FC1, H x W
  cv::Mat t_inv;   // CV_64FC1, H x W
};

TemplateStats MakeTemplateStats(const cv::Mat& templ, int correlation_window_px) {
  TemplateStats s;
  s.hc = correlation_window_px / 2;
  s.n = correlation_window_px * correlation_window_px;
  cv::Mat t;
  templ.convertTo(t, CV_64F);
  t -= cv::mean(t)[0];  // smaller magnitudes, less cancellation; NCC is offset-invariant
  cv::Mat t2 = t.mul(t);
  const cv::Size k(correlation_window_px, correlation_window_px);
  cv::boxFilter(t, s.t_sum, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  cv::Mat sum2;
  cv::boxFilter(t2, sum2, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  s.t_inv.create(t.size(), CV_64FC1);
  for (int y = 0; y < t.rows; ++y) {
    const double* a = s.t_sum.ptr<double>(y);
    const double* b = sum2.ptr<double>(y);
    double* o = s.t_inv.ptr<double>(y);
    for (int x = 0; x < t.cols; ++x) {
      const double v = s.n * b[x] - a[x] * a[x];
      // Relative floor: a patch whose variance is at rounding level of its energy is flat.
      o[x] = v > 1e-12 * s.n * b[x] && v > 0 ? 1.0 / std::sqrt(v) : 0.0;
    }
  }
  cv::Mat tf;
  t.convertTo(tf, CV_32F);
  cv::copyMakeBorder(tf, s.t_pad, s.hc, s.hc, s.hc, s.hc, cv::BORDER_REFLECT_101);
  return s;
}

// Per-thread scratch of the tile kernel.
struct Scratch {
  std::vector<float> w;                  // gathered frame patch rows (ih x iw)
  std::vector<double> vw, vww, vwt;      // vertical patch sums per input column
  std::vector<float> c, p;               // NCC and C sigma_w over the region R (rh x rw)
  std::vector<double> vc, vp;            // vertical U sums per R column
  std::vector<int> xs, cidx, ridx;       // reflected indices
};

// The focus values F of the tile T of `frame` and the mean NCC over U: the NCC (eq. 5.25) and
// C sigma_w on the region R = T grown by the U half-width (clipped to the image; U reflects the
// maps at the border), from patches that reflect the frame at the border. fm, nm: T.height x
// T.width, row-major.
template <typename P>
void TileFocus(const cv::Mat& frame, const TemplateStats& ts, int hs, CorrelationFocusValue value, const cv::Rect& T,
               Scratch& s, float* fm, float* nm) {
  const int W = frame.cols, H = frame.rows, hc = ts.hc, n = ts.n;
  const int rx0 = std::max(0, T.x - hs), rx1 = std::min(W, T.x + T.width + hs);
  const int ry0 = std::max(0, T.y - hs), ry1 = std::min(H, T.y + T.height + hs);
  const int rw = rx1 - rx0, rh = ry1 - ry0;
  const int iw = rw + 2 * hc, ih = rh + 2 * hc;

  // Frame patch rows, reflected at the image border; values shifted by a constant (the first
  // pixel of the region) so the double sums stay small: NCC does not see the shift.
  s.xs.resize(iw);
  for (int c = 0; c < iw; ++c) s.xs[c] = Reflect101(rx0 - hc + c, W);
  const float offset = float(frame.at<P>(ry0, rx0));
  s.w.resize(size_t(ih) * iw);
  for (int r = 0; r < ih; ++r) {
    const P* src = frame.ptr<P>(Reflect101(ry0 - hc + r, H));
    float* dst = s.w.data() + size_t(r) * iw;
    const bool inside = rx0 - hc >= 0 && rx1 + hc <= W;
    if (inside) {
      const P* p = src + (rx0 - hc);
      for (int c = 0; c < iw; ++c) dst[c] = float(p[c]) - offset;
    } else {
      for (int c = 0; c < iw; ++c) dst[c] = float(src[s.xs[c]]) - offset;
    }
  }

  // Vertical patch sums of w, w^2 and w t, slid down the region's rows.
  s.vw.assign(iw, 0.0);
  s.vww.assign(iw, 0.0);
  s.vwt.assign(iw, 0.0);
  auto add_row = [&](int r, double sign) {
    const float* wr = s.w.data() + size_t(r) * iw;
    const float* tr = ts.t_pad.ptr<float>(ry0 + r) + rx0;  // t_pad row ry0 + r = image row ry0 - hc + r
    for (int c = 0; c < iw; ++c) {
      const double wv = wr[c];
      s.vw[c] += sign * wv;
      s.vww[c] += sign * wv * wv;
      s.vwt[c] += sign * wv * double(tr[c]);
    }
  };
  for (int r = 0; r < 2 * hc + 1; ++r) add_row(r, 1.0);
  s.c.resize(size_t(rh) * rw);
  s.p.resize(size_t(rh) * rw);
  const int k = 2 * hc + 1;
  for (int y = 0; y < rh; ++y) {
    if (y > 0) {
      add_row(y - 1, -1.0);
      add_row(y + 2 * hc, 1.0);
    }
    double sw = 0, sww = 0, swt = 0;
    for (int c = 0; c < k; ++c) {
      sw += s.vw[c];
      sww += s.vww[c];
      swt += s.vwt[c];
    }
    const double* tsum = ts.t_sum.ptr<double>(ry0 + y) + rx0;
    const double* tinv = ts.t_inv.ptr<double>(ry0 + y) + rx0;
    float* crow = s.c.data() + size_t(y) * rw;
    float* prow = s.p.data() + size_t(y) * rw;
    for (int x = 0; x < rw; ++x) {
      if (x > 0) {
        sw += s.vw[x + k - 1] - s.vw[x - 1];
        sww += s.vww[x + k - 1] - s.vww[x - 1];
        swt += s.vwt[x + k - 1] - s.vwt[x - 1];
      }
      // eq. 5.25 in sums: (n Swt - Sw St) / sqrt((n Sww - Sw^2)(n Stt - St^2)).
      // C sigma_w = cov(w, t) / sigma_t = (n Swt - Sw St) / (n sqrt(n Stt - St^2)).
      const double var_w = n * sww - sw * sw;
      double c = 0.0, p = 0.0;
      if (var_w > 1e-9 * n * sww && var_w > 0 && tinv[x] > 0) {
        const double num = (n * swt - sw * tsum[x]) * tinv[x];
        const double root = std::sqrt(var_w);
        c = std::clamp(num / root, -1.0, 1.0);
        p = c * root / n;
      }
      crow[x] = float(c);
      prow[x] = float(p);
    }
  }

  // F over U (eq. 5.26 or C sigma_w), U reflecting the maps at the image border.
  const int ks = 2 * hs + 1;
  s.cidx.resize(T.width + 2 * hs);
  for (int c = 0; c < T.width + 2 * hs; ++c) s.cidx[c] = Reflect101(T.x - hs + c, W) - rx0;
  s.ridx.resize(T.height + 2 * hs);
  for (int r = 0; r < T.height + 2 * hs; ++r) s.ridx[r] = Reflect101(T.y - hs + r, H) - ry0;
  s.vc.assign(rw, 0.0);
  s.vp.assign(rw, 0.0);
  auto add_u_row = [&](int r, double sign) {
    const float* cr = s.c.data() + size_t(s.ridx[r]) * rw;
    const float* pr = s.p.data() + size_t(s.ridx[r]) * rw;
    for (int x = 0; x < rw; ++x) {
      s.vc[x] += sign * cr[x];
      s.vp[x] += sign * pr[x];
    }
  };
  for (int r = 0; r < ks; ++r) add_u_row(r, 1.0);
  const double u_count = double(ks) * ks;
  const bool shifted = value == CorrelationFocusValue::kShiftedSum;
  for (int y = 0; y < T.height; ++y) {
    if (y > 0) {
      add_u_row(y - 1, -1.0);
      add_u_row(y + 2 * hs, 1.0);
    }
    double acc_c = 0, acc_p = 0;
    for (int c = 0; c < ks; ++c) {
      acc_c += s.vc[s.cidx[c]];
      acc_p += s.vp[s.cidx[c]];
    }
    float* out_f = fm + size_t(y) * T.width;
    float* out_n = nm + size_t(y) * T.width;
    for (int x = 0; x < T.width; ++x) {
      if (x > 0) {
        acc_c += s.vc[s.cidx[x + ks - 1]] - s.vc[s.cidx[x - 1]];
        acc_p += s.vp[s.cidx[x + ks - 1]] - s.vp[s.cidx[x - 1]];
      }
      out_f[x] = float(shifted ? acc_c + u_count : acc_p);
      out_n[x] = float(acc_c / u_count);
    }
  }
}

void TileFocusDispatch(const cv::Mat& frame, const TemplateStats& ts, int hs, CorrelationFocusValue value,
                       const cv::Rect& T, Scratch& s, float* fm, float* nm) {
  switch (frame.depth()) {
    case CV_8U: TileFocus<uint8_t>(frame, ts, hs, value, T, s, fm, nm); break;
    case CV_16U: TileFocus<uint16_t>(frame, ts, hs, value, T, s, fm, nm); break;
    default: TileFocus<float>(frame, ts, hs, value, T, s, fm, nm); break;
  }
}

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
  std::vector<float> best, best_ncc, sum, curv_all, curv_excl, aif;
  std::vector<float> before, after, ring;  // J, J, Jr planes
  std::vector<int16_t> idx;
  std::vector<uint8_t> phase;     // 0 searching, 1 local maximum found (filling `after`), 2 stopped
  std::vector<int16_t> n_seen;    // ISFF-FAST: frames the pixel saw (set when it stops)

  // Tiles.
  std::vector<cv::Rect> tiles;
  std::vector<int> tile_searching;  // pixels of the tile not stopped
  std::vector<Scratch> scratch;
  std::vector<std::vector<float>> fm_buf, nm_buf;
  NccWorkCounters work;
  cv::Mat max_index, frames_searched;

  size_t Plane(int p) const { return size_t(p) * size.area(); }

  // Updates the state of the tile's pixels with their focus values and mean NCC of frame k.
  template <typename P>
  int64_t UpdateTile(const cv::Rect& T, const float* fm, const float* nm, const cv::Mat& frame, int k,
                     int* searching) {
    const size_t A = size.area();
    const float stop_ncc = float(o.stop_threshold);
    int64_t updated = 0;
    for (int y = T.y; y < T.y + T.height; ++y) {
      const P* fr = frame.ptr<P>(y);
      const float* f_row = fm + size_t(y - T.y) * T.width;
      const float* n_row = nm + size_t(y - T.y) * T.width;
      for (int x = T.x; x < T.x + T.width; ++x) {
        const size_t i = size_t(y) * size.width + x;
        if (phase[i] == 2) continue;
        ++updated;
        const float F = f_row[x - T.x];
        float t2 = 0.f;
        if (k >= 2) {
          const float t = F - 2.f * ring[i] + ring[A + i];
          t2 = t * t;
          curv_all[i] += t2;
        }
        const int d = k - idx[i];
        if (phase[i] == 0 && (k == 0 || F > best[i])) {
          best[i] = F;
          best_ncc[i] = n_row[x - T.x];
          idx[i] = int16_t(k);
          for (int t = 0; t < J; ++t) before[Plane(t) + i] = ring[Plane(t) + i];
          curv_excl[i] = t2;
          aif[i] = float(fr[x]);
        } else {
          if (d <= J) after[Plane(d - 1) + i] = F;
          if (d <= 2 && k >= 2) curv_excl[i] += t2;
          if (o.stop_at_first_maximum) {
            // The running maximum followed by a lower value is the first local maximum (an
            // earlier, higher hump would have had its own maximum above the threshold).
            if (phase[i] == 0 && d == 1 && F < best[i] && best_ncc[i] >= stop_ncc) phase[i] = 1;
            if (phase[i] == 1 && d >= J) {
              phase[i] = 2;
              n_seen[i] = int16_t(k + 1);
              --*searching;
            }
          }
        }
        sum[i] += F;
        for (int t = Jr - 1; t > 0; --t) ring[Plane(t) + i] = ring[Plane(t - 1) + i];
        ring[i] = F;
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
  m.ts = MakeTemplateStats(focused_template, options.correlation_window_px);
  const size_t A = m.size.area();
  m.best.assign(A, 0.f);
  m.best_ncc.assign(A, 0.f);
  m.sum.assign(A, 0.f);
  m.curv_all.assign(A, 0.f);
  m.curv_excl.assign(A, 0.f);
  m.aif.assign(A, 0.f);
  m.before.assign(A * m.J, 0.f);
  m.after.assign(A * m.J, 0.f);
  m.ring.assign(A * m.Jr, 0.f);
  m.idx.assign(A, 0);
  m.phase.assign(A, 0);
  m.n_seen.assign(A, 0);
  const int tp = options.tile_px;
  for (int y = 0; y < m.size.height; y += tp)
    for (int x = 0; x < m.size.width; x += tp)
      m.tiles.emplace_back(x, y, std::min(tp, m.size.width - x), std::min(tp, m.size.height - y));
  m.tile_searching.resize(m.tiles.size());
  for (size_t t = 0; t < m.tiles.size(); ++t) m.tile_searching[t] = m.tiles[t].area();
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
  std::atomic<int64_t> updated{0};
  const int hs = m.o.summation_window_px / 2;
  ParallelFor(int(active.size()), m.threads, [&](int a, int worker) {
    const int t = active[a];
    const cv::Rect& T = m.tiles[t];
    std::vector<float>& fm = m.fm_buf[worker];
    std::vector<float>& nm = m.nm_buf[worker];
    fm.resize(size_t(T.area()));
    nm.resize(size_t(T.area()));
    TileFocusDispatch(frame, m.ts, hs, m.o.focus_value, T, m.scratch[worker], fm.data(), nm.data());
    int64_t u = 0;
    if (frame.depth() == CV_8U) u = m.UpdateTile<uint8_t>(T, fm.data(), nm.data(), frame, k, &m.tile_searching[t]);
    else u = m.UpdateTile<uint16_t>(T, fm.data(), nm.data(), frame, k, &m.tile_searching[t]);
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
      const float c = FocusConfidence(s);
      r.confidence.at<float>(y, x) = c;
      if (c >= m.o.min_confidence) {
        r.depth_um.at<float>(y, x) = float(InterpolatePeak(m.o.interpolation, zw, fw, before, after).z_um);
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
  std::vector<float>().swap(m.best);
  std::vector<float>().swap(m.best_ncc);
  std::vector<float>().swap(m.sum);
  std::vector<float>().swap(m.curv_all);
  std::vector<float>().swap(m.curv_excl);
  std::vector<float>().swap(m.aif);
  std::vector<float>().swap(m.before);
  std::vector<float>().swap(m.after);
  std::vector<float>().swap(m.ring);
  std::vector<int16_t>().swap(m.idx);
  std::vector<uint8_t>().swap(m.phase);
  std::vector<int16_t>().swap(m.n_seen);
  return r;
}

int NccFocusEngine::frames_pushed() const { return int(impl_->z.size()); }

size_t NccFocusEngine::state_bytes() const {
  const Impl& m = *impl_;
  const size_t planes = m.best.size() + m.best_ncc.size() + m.sum.size() + m.curv_all.size() + m.curv_excl.size() + m.aif.size() +
                        m.before.size() + m.after.size() + m.ring.size();
  return planes * sizeof(float) + m.idx.size() * 2 + m.phase.size() + m.n_seen.size() * 2 +
         m.ts.t_pad.total() * 4 + m.ts.t_sum.total() * 8 + m.ts.t_inv.total() * 8;
}

const NccWorkCounters& NccFocusEngine::work() const { return impl_->work; }
const cv::Mat& NccFocusEngine::max_index() const { return impl_->max_index; }
const cv::Mat& NccFocusEngine::frames_searched() const { return impl_->frames_searched; }

}  // namespace inspection
