// Tile kernel of the correlation focus measure (thesis eq. 5.25-5.26): patch sums slid over the
// rows, the NCC and C sigma_w per pixel, and their sums over U. Row loops vectorise (AVX2 chosen
// at run time); see TileFocusT for the numerics.
#include "core/sff/internal/ncc_kernel.h"

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <type_traits>

namespace inspection::ncc_kernel {

TemplateStats MakeTemplateStats(const cv::Mat& templ, int correlation_window_px) {
  TemplateStats s;
  s.hc = correlation_window_px / 2;
  s.n = correlation_window_px * correlation_window_px;
  // Float is enough here: the template is centred on its mean (NCC ignores offsets), so its
  // patch sums stay a few orders of magnitude inside float's precision, and a patch whose
  // variance is lost to rounding is flat for the NCC anyway.
  cv::Mat t;
  templ.convertTo(t, CV_32F);
  t -= cv::mean(t)[0];
  const cv::Size k(correlation_window_px, correlation_window_px);
  cv::Mat sum2;
  cv::boxFilter(t, s.t_sum, CV_32F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  cv::boxFilter(t.mul(t), sum2, CV_32F, k, {-1, -1}, false, cv::BORDER_REFLECT_101);
  s.t_inv.create(t.size(), CV_32FC1);
  const float n = float(s.n);
  for (int y = 0; y < t.rows; ++y) {
    const float* a = s.t_sum.ptr<float>(y);
    const float* b = sum2.ptr<float>(y);
    float* o = s.t_inv.ptr<float>(y);
    for (int x = 0; x < t.cols; ++x) {
      const float v = n * b[x] - a[x] * a[x];
      // Relative floor: a patch whose variance is at rounding level of its energy is flat.
      o[x] = v > 1e-5f * n * b[x] && v > 0.f ? 1.0f / std::sqrt(v) : 0.0f;
    }
  }
  cv::copyMakeBorder(t, s.t_pad, s.hc, s.hc, s.hc, s.hc, cv::BORDER_REFLECT_101);
  return s;
}

namespace {

// Row kernels, kept apart so they vectorise (AVX2 where the CPU has it, chosen at run time by
// target_clones). Clang rejects target_clones on function templates; its builds (the libFuzzer
// targets, tests/fuzz/run_fuzz.sh) get the portable code, which is the same arithmetic.
#if defined(__clang__)
#define INSPECT_NCC_ROW_KERNEL
#else
#define INSPECT_NCC_ROW_KERNEL __attribute__((target_clones("avx2", "default")))
#endif

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

// TileFocus for frame pixels P and patch sums A.
// Numerics: 8-bit frames with patches up to 15 x 15 are summed in float after subtracting an
// integer offset (the region's first pixel): every partial sum of w and w^2 over a patch
// (<= 225 x 255^2 < 2^24) is an integer that float holds exactly, so n Sww - Sw^2 (taken in
// double) has no cancellation error; larger patches, 16-bit and float frames are summed in
// double. The loops run over whole rows so they
// vectorise.
template <typename P, typename A>
void TileFocusT(const cv::Mat& frame, const TemplateStats& ts, int hs, CorrelationFocusValue value, const cv::Rect& T,
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

}  // namespace

void TileFocus(const cv::Mat& frame, const TemplateStats& ts, int hs, CorrelationFocusValue value, const cv::Rect& T,
               Scratch& s, float* fm, float* nm) {
  switch (frame.depth()) {
    case CV_8U:
      if (ts.n <= 225)
        TileFocusT<uint8_t, float>(frame, ts, hs, value, T, s.f, fm, nm);
      else
        TileFocusT<uint8_t, double>(frame, ts, hs, value, T, s.d, fm, nm);
      break;
    case CV_16U:
      TileFocusT<uint16_t, double>(frame, ts, hs, value, T, s.d, fm, nm);
      break;
    default:
      TileFocusT<float, double>(frame, ts, hs, value, T, s.d, fm, nm);
      break;
  }
}

}  // namespace inspection::ncc_kernel
