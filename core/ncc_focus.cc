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
#include <type_traits>

#include <immintrin.h>

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
  cv::Mat t_sum;   // CV_32FC1, H x W
  cv::Mat t_inv;   // CV_32FC1, H x W
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
  cv::Mat sum1, sum2;
  cv::boxFilter(t, sum1, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  cv::boxFilter(t2, sum2, CV_64F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  s.t_inv.create(t.size(), CV_32FC1);
  for (int y = 0; y < t.rows; ++y) {
    const double* a = sum1.ptr<double>(y);
    const double* b = sum2.ptr<double>(y);
    float* o = s.t_inv.ptr<float>(y);
    for (int x = 0; x < t.cols; ++x) {
      const double v = s.n * b[x] - a[x] * a[x];
      // Relative floor: a patch whose variance is at rounding level of its energy is flat.
      o[x] = v > 1e-12 * s.n * b[x] && v > 0 ? float(1.0 / std::sqrt(v)) : 0.0f;
    }
  }
  sum1.convertTo(s.t_sum, CV_32F);
  cv::Mat tf;
  t.convertTo(tf, CV_32F);
  cv::copyMakeBorder(tf, s.t_pad, s.hc, s.hc, s.hc, s.hc, cv::BORDER_REFLECT_101);
  return s;
}

// Per-thread scratch of the tile kernel. A: accumulator type of the patch sums.
template <typename A>
struct ScratchT {
  std::vector<A> w;                   // gathered frame patch rows (ih x iw), shifted by an offset
  std::vector<A> vw, vww, vwt;        // vertical patch sums per input column
  std::vector<A> sw, sww, swt;        // patch sums per region column (one row)
  std::vector<float> c, p;            // NCC and C sigma_w over the region R (rh x rw)
  std::vector<float> vc, vp;          // vertical U sums per R column
  std::vector<float> hc_row, hp_row;  // one row of vc / vp with the U border reflected
  std::vector<int> xs, cidx, ridx;    // reflected indices
};
struct Scratch {
  ScratchT<float> f;
  ScratchT<double> d;
};

// Row kernels, kept apart so they vectorise (AVX2 where the CPU has it, chosen at run time by
// target_clones).
#define INSPECT_NCC_ROW_KERNEL __attribute__((target_clones("avx2", "default")))

// out[x] = sum of v[x .. x + k - 1], x = 0..count-1.
template <typename A>
INSPECT_NCC_ROW_KERNEL void WindowSums(const A* __restrict v, A* __restrict out, int count, int k) {
  for (int x = 0; x < count; ++x) out[x] = v[x];
  for (int j = 1; j < k; ++j)
    for (int x = 0; x < count; ++x) out[x] += v[x + j];
}

// Slides the vertical patch sums by one row: - row o, + row n (o and n of w and t).
template <typename A>
INSPECT_NCC_ROW_KERNEL void SlidePatchSums(const A* __restrict wo, const A* __restrict wn, const float* __restrict to,
                                           const float* __restrict tn, A* __restrict vw, A* __restrict vww,
                                           A* __restrict vwt, int count) {
  for (int c = 0; c < count; ++c) {
    vw[c] += wn[c] - wo[c];
    vww[c] += wn[c] * wn[c] - wo[c] * wo[c];
    vwt[c] += wn[c] * A(tn[c]) - wo[c] * A(to[c]);
  }
}

// eq. 5.25 in sums: C = (n Swt - Sw St) / sqrt((n Sww - Sw^2)(n Stt - St^2)), and
// C sigma_w = cov(w, t) / sigma_t = (n Swt - Sw St) / (n sqrt(n Stt - St^2)); 0 for a flat patch
// (sww >= 0, so var_w > 1e-9 n sww also asks var_w > 0: a variance at rounding level is flat).
template <typename A>
void NccRowPortable(const A* sw, const A* sww, const A* swt, const float* tsum, const float* tinv, int n, int begin,
                    int count, float* c_out, float* p_out) {
  for (int x = begin; x < count; ++x) {
    const double var_w = double(n) * double(sww[x]) - double(sw[x]) * double(sw[x]);
    const float num = (float(n) * float(swt[x]) - float(sw[x]) * tsum[x]) * tinv[x];
    const bool ok = var_w > 1e-9 * double(n) * double(sww[x]);
    const float root = ok ? float(std::sqrt(var_w)) : 1.0f;
    const float c = ok ? std::clamp(num / root, -1.0f, 1.0f) : 0.0f;
    c_out[x] = c;
    p_out[x] = c * root / float(n);
  }
}

// The same for float sums, 8 pixels per step; the variance in double as above (the float sums
// are exact integers, their products are not). Same results as the portable loop up to the
// rounding of one float division.
__attribute__((target("avx2"))) void NccRowAvx2(const float* sw, const float* sww, const float* swt, const float* tsum,
                                                const float* tinv, int n, int count, float* c_out, float* p_out) {
  const __m256d nd = _mm256_set1_pd(n), tiny = _mm256_set1_pd(1e-9 * n);
  const __m256 nf = _mm256_set1_ps(float(n)), inv_n = _mm256_set1_ps(1.0f / float(n));
  const __m256 one = _mm256_set1_ps(1.0f), minus_one = _mm256_set1_ps(-1.0f);
  int x = 0;
  for (; x + 8 <= count; x += 8) {
    const __m256 a = _mm256_loadu_ps(sw + x), b = _mm256_loadu_ps(sww + x);
    __m256d var[2], thr[2];
    for (int h = 0; h < 2; ++h) {
      const __m256d ad = _mm256_cvtps_pd(h ? _mm256_extractf128_ps(a, 1) : _mm256_castps256_ps128(a));
      const __m256d bd = _mm256_cvtps_pd(h ? _mm256_extractf128_ps(b, 1) : _mm256_castps256_ps128(b));
      var[h] = _mm256_sub_pd(_mm256_mul_pd(nd, bd), _mm256_mul_pd(ad, ad));
      thr[h] = _mm256_mul_pd(tiny, bd);
    }
    // Pack the two 4 x 64-bit masks and variances into 8 x 32-bit lanes.
    const __m128 m0 = _mm256_cvtpd_ps(_mm256_cmp_pd(var[0], thr[0], _CMP_GT_OQ));
    const __m128 m1 = _mm256_cvtpd_ps(_mm256_cmp_pd(var[1], thr[1], _CMP_GT_OQ));
    // A true 64-bit mask converts to NaN, a false one to 0: NaN != NaN marks the true lanes.
    const __m256 mask_nan = _mm256_set_m128(m1, m0);
    const __m256 ok = _mm256_cmp_ps(mask_nan, mask_nan, _CMP_UNORD_Q);
    const __m256 var_f = _mm256_set_m128(_mm256_cvtpd_ps(var[1]), _mm256_cvtpd_ps(var[0]));
    const __m256 root = _mm256_sqrt_ps(_mm256_blendv_ps(one, var_f, ok));
    const __m256 num = _mm256_mul_ps(
        _mm256_sub_ps(_mm256_mul_ps(nf, _mm256_loadu_ps(swt + x)), _mm256_mul_ps(a, _mm256_loadu_ps(tsum + x))),
        _mm256_loadu_ps(tinv + x));
    __m256 c = _mm256_min_ps(_mm256_max_ps(_mm256_div_ps(num, root), minus_one), one);
    c = _mm256_and_ps(c, ok);
    _mm256_storeu_ps(c_out + x, c);
    _mm256_storeu_ps(p_out + x, _mm256_mul_ps(_mm256_mul_ps(c, root), inv_n));
  }
  NccRowPortable(sw, sww, swt, tsum, tinv, n, x, count, c_out, p_out);
}

bool HasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

template <typename A>
void NccRow(const A* sw, const A* sww, const A* swt, const float* tsum, const float* tinv, int n, int count,
            float* c_out, float* p_out) {
  if constexpr (std::is_same_v<A, float>) {
    if (HasAvx2()) return NccRowAvx2(sw, sww, swt, tsum, tinv, n, count, c_out, p_out);
  }
  NccRowPortable(sw, sww, swt, tsum, tinv, n, 0, count, c_out, p_out);
}

// The focus values F of the tile T of `frame` and the mean NCC over U: the NCC (eq. 5.25) and
// C sigma_w on the region R = T grown by the U half-width (clipped to the image; U reflects the
// maps at the border), from patches that reflect the frame at the border. fm, nm: T.height x
// T.width, row-major.
//
// Numerics: 8-bit frames with patches up to 15 x 15 are summed in float after subtracting an
// integer offset (the region's first pixel): every partial sum of w and w^2 over a patch
// (<= 225 x 255^2 < 2^24) is an integer that float holds exactly, so n Sww - Sw^2 (taken in
// double) has no cancellation error; larger patches, 16-bit and float frames are summed in
// double. The loops run over whole rows so they
// vectorise.
template <typename P, typename A>
void TileFocus(const cv::Mat& frame, const TemplateStats& ts, int hs, CorrelationFocusValue value, const cv::Rect& T,
               ScratchT<A>& s, float* fm, float* nm) {
  const int W = frame.cols, H = frame.rows, hc = ts.hc, n = ts.n, k = 2 * hc + 1;
  const int rx0 = std::max(0, T.x - hs), rx1 = std::min(W, T.x + T.width + hs);
  const int ry0 = std::max(0, T.y - hs), ry1 = std::min(H, T.y + T.height + hs);
  const int rw = rx1 - rx0, rh = ry1 - ry0;
  const int iw = rw + 2 * hc, ih = rh + 2 * hc;

  s.xs.resize(iw);
  for (int c = 0; c < iw; ++c) s.xs[c] = Reflect101(rx0 - hc + c, W);
  const A offset = A(frame.at<P>(ry0, rx0));
  s.w.resize(size_t(ih) * iw);
  const bool inside = rx0 - hc >= 0 && rx1 + hc <= W;
  for (int r = 0; r < ih; ++r) {
    const P* src = frame.ptr<P>(Reflect101(ry0 - hc + r, H));
    A* dst = s.w.data() + size_t(r) * iw;
    if (inside) {
      const P* p = src + (rx0 - hc);
      for (int c = 0; c < iw; ++c) dst[c] = A(p[c]) - offset;
    } else {
      for (int c = 0; c < iw; ++c) dst[c] = A(src[s.xs[c]]) - offset;
    }
  }

  // Vertical patch sums of w, w^2 and w t, slid down the region's rows.
  s.vw.assign(iw, A(0));
  s.vww.assign(iw, A(0));
  s.vwt.assign(iw, A(0));
  s.sw.resize(rw);
  s.sww.resize(rw);
  s.swt.resize(rw);
  A* __restrict vw = s.vw.data();
  A* __restrict vww = s.vww.data();
  A* __restrict vwt = s.vwt.data();
  auto w_row = [&](int r) { return s.w.data() + size_t(r) * iw; };
  // t_pad row ry0 + r is image row ry0 - hc + r, the same as input row r.
  auto t_row = [&](int r) { return ts.t_pad.ptr<float>(ry0 + r) + rx0; };
  for (int r = 0; r < k; ++r) {
    const A* wr = w_row(r);
    const float* tr = t_row(r);
    for (int c = 0; c < iw; ++c) {
      vw[c] += wr[c];
      vww[c] += wr[c] * wr[c];
      vwt[c] += wr[c] * A(tr[c]);
    }
  }
  s.c.resize(size_t(rh) * rw);
  s.p.resize(size_t(rh) * rw);
  for (int y = 0; y < rh; ++y) {
    if (y > 0) SlidePatchSums(w_row(y - 1), w_row(y + 2 * hc), t_row(y - 1), t_row(y + 2 * hc), vw, vww, vwt, iw);
    // Horizontal patch sums: k shifted adds over the row.
    WindowSums(vw, s.sw.data(), rw, k);
    WindowSums(vww, s.sww.data(), rw, k);
    WindowSums(vwt, s.swt.data(), rw, k);
    NccRow(s.sw.data(), s.sww.data(), s.swt.data(), ts.t_sum.ptr<float>(ry0 + y) + rx0,
           ts.t_inv.ptr<float>(ry0 + y) + rx0, n, rw, s.c.data() + size_t(y) * rw, s.p.data() + size_t(y) * rw);
  }

  // F over U (eq. 5.26 or C sigma_w), U reflecting the maps at the image border.
  const int ks = 2 * hs + 1, uw = T.width + 2 * hs;
  s.cidx.resize(uw);
  for (int c = 0; c < uw; ++c) s.cidx[c] = Reflect101(T.x - hs + c, W) - rx0;
  s.ridx.resize(T.height + 2 * hs);
  for (int r = 0; r < T.height + 2 * hs; ++r) s.ridx[r] = Reflect101(T.y - hs + r, H) - ry0;
  s.vc.assign(rw, 0.f);
  s.vp.assign(rw, 0.f);
  s.hc_row.resize(uw);
  s.hp_row.resize(uw);
  float* __restrict vc = s.vc.data();
  float* __restrict vp = s.vp.data();
  for (int r = 0; r < ks; ++r) {
    const float* cr = s.c.data() + size_t(s.ridx[r]) * rw;
    const float* pr = s.p.data() + size_t(s.ridx[r]) * rw;
    for (int x = 0; x < rw; ++x) {
      vc[x] += cr[x];
      vp[x] += pr[x];
    }
  }
  const float u_count = float(ks * ks), inv_u = 1.0f / u_count;
  const bool shifted = value == CorrelationFocusValue::kShiftedSum;
  for (int y = 0; y < T.height; ++y) {
    if (y > 0) {
      const float* co = s.c.data() + size_t(s.ridx[y - 1]) * rw;
      const float* cn = s.c.data() + size_t(s.ridx[y + 2 * hs]) * rw;
      const float* po = s.p.data() + size_t(s.ridx[y - 1]) * rw;
      const float* pn = s.p.data() + size_t(s.ridx[y + 2 * hs]) * rw;
      for (int x = 0; x < rw; ++x) {
        vc[x] += cn[x] - co[x];
        vp[x] += pn[x] - po[x];
      }
    }
    float* __restrict hcr = s.hc_row.data();
    float* __restrict hpr = s.hp_row.data();
    for (int c = 0; c < uw; ++c) {
      hcr[c] = vc[s.cidx[c]];
      hpr[c] = vp[s.cidx[c]];
    }
    float* __restrict out_f = fm + size_t(y) * T.width;
    float* __restrict out_n = nm + size_t(y) * T.width;
    WindowSums(hcr, out_n, T.width, ks);
    WindowSums(hpr, out_f, T.width, ks);
    for (int x = 0; x < T.width; ++x) {
      if (shifted) out_f[x] = out_n[x] + u_count;
      out_n[x] *= inv_u;
    }
  }
}

void TileFocusDispatch(const cv::Mat& frame, const TemplateStats& ts, int hs, CorrelationFocusValue value,
                       const cv::Rect& T, Scratch& s, float* fm, float* nm) {
  switch (frame.depth()) {
    case CV_8U:
      if (ts.n <= 225) TileFocus<uint8_t, float>(frame, ts, hs, value, T, s.f, fm, nm);
      else TileFocus<uint8_t, double>(frame, ts, hs, value, T, s.d, fm, nm);
      break;
    case CV_16U: TileFocus<uint16_t, double>(frame, ts, hs, value, T, s.d, fm, nm); break;
    default: TileFocus<float, double>(frame, ts, hs, value, T, s.d, fm, nm); break;
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
  std::vector<int> tile_searching;     // pixels of the tile not stopped
  std::vector<cv::Rect> tile_active;   // bounding box of those pixels: what is computed
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
    TileFocusDispatch(frame, m.ts, hs, m.o.focus_value, T, m.scratch[worker], fm.data(), nm.data());
    int64_t u = 0;
    const int searching_before = m.tile_searching[t];
    if (frame.depth() == CV_8U) u = m.UpdateTile<uint8_t>(T, fm.data(), nm.data(), frame, k, &m.tile_searching[t]);
    else u = m.UpdateTile<uint16_t>(T, fm.data(), nm.data(), frame, k, &m.tile_searching[t]);
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
         m.ts.t_pad.total() * 4 + m.ts.t_sum.total() * 4 + m.ts.t_inv.total() * 4;
}

const NccWorkCounters& NccFocusEngine::work() const { return impl_->work; }
const cv::Mat& NccFocusEngine::max_index() const { return impl_->max_index; }
const cv::Mat& NccFocusEngine::frames_searched() const { return impl_->frames_searched; }

}  // namespace inspection
