// Tile kernel of the correlation focus measure (thesis eq. 5.25-5.26): patch sums slid over the
// rows, the NCC and C sigma_w per pixel, and their sums over U. Row loops vectorise (AVX2 chosen
// at run time); see TileFocusT for the numerics.
#include "core/sff/internal/ncc_kernel.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <type_traits>

#include "core/sff/internal/ncc_row_kernel.h"

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

// Row kernels (core/sff/internal/ncc_row_kernel.h), AVX2 where the CPU has it.
template <typename A>
void WindowSums(const A* v, A* out, int count, int k) {
  static const auto fn = PickPatchSums<A>().window_sums;
  fn(v, out, count, k);
}

template <typename A>
void SlidePatchSums(const A* wo, const A* wn, const float* to, const float* tn, A* vw, A* vww, A* vwt, int count) {
  static const auto fn = PickPatchSums<A>().slide;
  fn(wo, wn, to, tn, vw, vww, vwt, count);
}

template <typename A>
void NccRow(const A* sw, const A* sww, const A* swt, const float* tsum, const float* tinv, int n, int count,
            float* c_out, float* p_out) {
  if constexpr (std::is_same_v<A, float>) {
    static const NccRowFloatFn row = PickNccRowFloat();
    return row(sw, sww, swt, tsum, tinv, n, count, c_out, p_out);
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
