// The fused Tenengrad kernel written once (thesis eq. 3.13-3.14 and the state update of 3.1.4)
// and compiled per instruction set, as OpenCV's *.simd.hpp: see core/sff/internal/tenengrad_kernel.h.
//
// Included only by tenengrad_kernel_portable.cc and tenengrad_kernel_avx2.cc, each of which
// first defines
//   SFF_ISA     the Isa whose TenengradKernels members this defines (Isa::kAvx2, ...),
//   SFF_ISA_NS  a namespace of its own for the helpers below (so that the copies compiled for
//               different instruction sets never meet in the linker),
//   SFF_TARGET  the target attribute every function here gets (empty for portable),
// and, in namespace sff_internal::SFF_ISA_NS, its Sobel energy row
//   SobelEnergyRow(a, b, c, TenengradScratch& sc, old_in, old_out, ew): for output columns
//   x < ew, with input rows a, b, c (y-1, y, y+1) and columns x .. x+2 (centre x+1), writes
//   e = Gx^2 + Gy^2 (eq. 3.13) to old_out[x] and adds e - old_in[x] to sc.colsum[x]; old_in is
//   the energy row leaving the window (old_out itself, or zeros while the window fills).
// No include guard: one inclusion per file, inside no namespace.

#include <algorithm>
#include <bit>
#include <cstdint>
#include <opencv2/core.hpp>

#include "core/sff/internal/tenengrad_kernel.h"

namespace inspection::sff_internal::SFF_ISA_NS {

// ---- Exact state update (StatePlanes), per row ----

// First frame: the maximum is frame 0.
template <typename T, typename P>
SFF_INLINE SFF_TARGET void InitRow(StatePlanes<T, P>& s, size_t off, const T* __restrict f, const P* __restrict pix,
                                   int n) {
  T* __restrict best = s.best.data() + off;
  uint32_t* __restrict idx_aif = s.idx_aif.data() + off;
  float* __restrict sum = s.sum.data() + off;
  for (int x = 0; x < n; ++x) {
    best[x] = f[x];
    idx_aif[x] = uint32_t(pix[x]);  // index 0
    sum[x] = ToFloat(f[x]);
  }
  std::fill_n(s.curv_all.data() + off, n, 0.f);
  std::fill_n(s.curv_excl.data() + off, n, 0.f);
  std::fill_n(s.last2.data() + off, n, T(0));
  for (int i = 0; i < s.j; ++i) {
    std::fill_n(s.before[i].data() + off, n, T(0));
    std::fill_n(s.after[i].data() + off, n, T(0));
    std::fill_n(s.ring[i].data() + off, n, T(0));
    if (i == 0) std::copy_n(f, n, s.ring[0].data() + off);
  }
}

// Row kernels of the state update. Each is a separate non-inlined function with restrict
// pointers and lanes of one width, the form in which GCC vectorises them; masks are built with
// integer bit operations because GCC does not if-convert an integer comparison selecting a float.

// Curve statistics of one pixel at frame k >= 2, before its maximum is updated: fv = F_k,
// t2 = t_k^2 (t_k = F_k - 2 F_(k-1) + F_(k-2)), new_max: F_k > F_max, id: the maximum's frame.
// Adds F_k to sum and t_k^2 to curv_all; curv_excl keeps the t_k^2 that involve the current
// maximum (m is k-2, k-1 or k): t_k^2 alone when F_k is a new maximum, else plus t_k^2 when m is
// k-1 or k-2.
SFF_INLINE SFF_TARGET void AddCurveStats(float fv, float t2, bool new_max, int32_t id, int32_t km1, int32_t km2,
                                         float& sum, float& curv_all, float& curv_excl) {
  const uint32_t mgt = uint32_t(-int32_t(new_max));
  const uint32_t mnear = uint32_t(-int32_t((id == km1) | (id == km2)));
  const uint32_t tb = std::bit_cast<uint32_t>(t2);
  const float kept = curv_excl + std::bit_cast<float>(tb & mnear);
  sum += fv;
  curv_all += t2;
  curv_excl = std::bit_cast<float>((tb & mgt) | (std::bit_cast<uint32_t>(kept) & ~mgt));
}

// Sum of F and, for k >= 2, t_k = F_k - 2 F_(k-1) + F_(k-2) (exact in T for int32), whose square
// goes to curv_all and, when t_k involves the maximum (m is k-2, k-1 or k: new max), to curv_excl.
template <typename T>
SFF_TARGET __attribute__((noinline)) void StatsRow(int n, int k, const T* __restrict f, const T* __restrict best,
                                                   const uint32_t* __restrict idx_aif, const T* __restrict last,
                                                   const T* __restrict last2, float* __restrict sum,
                                                   float* __restrict curv_all, float* __restrict curv_excl) {
  if (k < 2) {
    for (int x = 0; x < n; ++x) sum[x] += ToFloat(f[x]);
    return;
  }
  const int32_t km1 = k - 1, km2 = k - 2;
  for (int x = 0; x < n; ++x) {
    const T v = f[x];
    // In float: for wide windows 2 F overflows int32.
    const float t = (ToFloat(v) - ToFloat(last[x])) - (ToFloat(last[x]) - ToFloat(last2[x]));
    AddCurveStats(ToFloat(v), t * t, v > best[x], int32_t(idx_aif[x] >> 16), km1, km2, sum[x], curv_all[x],
                  curv_excl[x]);
  }
}

// Frame k >= 1, one neighbour each side: statistics and maximum tracking in one pass. For k == 1
// t_k does not exist: curv_scale = 0 makes it contribute nothing.
template <typename T, typename P>
SFF_TARGET __attribute__((noinline)) void UpdateRowJ1(int n, int k, float curv_scale, const T* __restrict f,
                                                      const P* __restrict pix, T* __restrict best,
                                                      uint32_t* __restrict idx_aif, T* __restrict prev,
                                                      T* __restrict next, T* __restrict last, T* __restrict last2,
                                                      float* __restrict sum, float* __restrict curv_all,
                                                      float* __restrict curv_excl) {
  const int32_t km1 = k - 1, km2 = k - 2;
  const uint32_t k_bits = uint32_t(k) << 16;
  for (int x = 0; x < n; ++x) {
    const T v = f[x], b = best[x], l = last[x], l2 = last2[x];
    const uint32_t w = idx_aif[x];
    const int32_t id = int32_t(w >> 16);
    const float t = (ToFloat(v) - ToFloat(l)) - (ToFloat(l) - ToFloat(l2));  // float: 2 F overflows int32
    AddCurveStats(ToFloat(v), curv_scale * (t * t), v > b, id, km1, km2, sum[x], curv_all[x], curv_excl[x]);
    const bool gt = v > b;
    const T nx = next[x], pv = prev[x];
    const uint32_t p = k_bits | uint32_t(pix[x]);
    next[x] = gt ? T(0) : (id == km1 ? v : nx);
    prev[x] = gt ? l : pv;
    best[x] = gt ? v : b;
    idx_aif[x] = gt ? p : w;
    last2[x] = l;
    last[x] = v;
  }
}

// Frame k >= 1, general j (line fit).
template <typename T, typename P>
SFF_TARGET void UpdateRowGeneral(StatePlanes<T, P>& s, size_t off, int k, const T* f, const P* pix, int n) {
  const int J = s.j;
  // Curve statistics of frame k >= 1, before the maximum is updated: sum, second differences.
  StatsRow(n, k, f, s.best.data() + off, s.idx_aif.data() + off, s.ring[0].data() + off, s.last2.data() + off,
           s.sum.data() + off, s.curv_all.data() + off, s.curv_excl.data() + off);
  for (int x = 0; x < n; ++x) {
    const size_t i = off + x;
    const T v = f[x];
    const bool gt = v > s.best[i];
    const int dist = k - s.IndexOf(s.idx_aif[i]);
    for (int j = 0; j < J; ++j) {
      if (gt) {
        s.before[j][i] = s.ring[j][i];
        s.after[j][i] = T(0);
      } else if (dist == j + 1) {
        s.after[j][i] = v;
      }
    }
    if (gt) {
      s.best[i] = v;
      s.idx_aif[i] = s.Pack(k, uint32_t(pix[x]));
    }
    s.last2[i] = s.ring[0][i];
    for (int j = J - 1; j > 0; --j) s.ring[j][i] = s.ring[j - 1][i];
    s.ring[0][i] = v;
  }
}

template <typename T, typename P>
SFF_TARGET inline void UpdateRow(StatePlanes<T, P>& s, size_t off, int k, const T* f, const P* pix, int n) {
  if (k == 0) {
    InitRow(s, off, f, pix, n);
  } else if (s.j == 1) {
    // The hot path (maximum and Gaussian interpolation).
    const float curv_scale = k >= 2 ? 1.f : 0.f;
    UpdateRowJ1<T, P>(n, k, curv_scale, f, pix, s.best.data() + off, s.idx_aif.data() + off, s.before[0].data() + off,
                      s.after[0].data() + off, s.ring[0].data() + off, s.last2.data() + off, s.sum.data() + off,
                      s.curv_all.data() + off, s.curv_excl.data() + off);
  } else {
    UpdateRowGeneral(s, off, k, f, pix, n);
  }
}

// ---- The fused tile ----

inline SFF_TARGET int Reflect101(int p, int len) {
  if (len == 1) return 0;
  while (p < 0 || p >= len) p = p < 0 ? -p : 2 * len - 2 - p;
  return p;
}

// Horizontal window sum of the column sums: out[x] = sum of colsum[x .. x + window - 1]. Built
// from pair sums p[x] = colsum[x] + colsum[x + 1]: (window + 1) / 2 passes instead of window.
// W: the window as a compile-time constant (the common sizes): one pass adds all pair sums.
template <int W>
SFF_INLINE SFF_TARGET void WindowRowFixed(const int32_t* __restrict colsum, int32_t* __restrict pairs,
                                          int32_t* __restrict out, int tw) {
  const int np = tw + W - 2;
  for (int x = 0; x < np; ++x) pairs[x] = colsum[x] + colsum[x + 1];
  for (int x = 0; x < tw; ++x) {
    int32_t s = colsum[x + W - 1];
    for (int i = 0; i + 1 < W; i += 2) s += pairs[x + i];
    out[x] = s;
  }
}

SFF_INLINE SFF_TARGET void WindowRow(const int32_t* __restrict colsum, int32_t* __restrict pairs,
                                     int32_t* __restrict out, int tw, int window) {
  switch (window) {
    case 3:
      return WindowRowFixed<3>(colsum, pairs, out, tw);
    case 5:
      return WindowRowFixed<5>(colsum, pairs, out, tw);
    case 7:
      return WindowRowFixed<7>(colsum, pairs, out, tw);
    case 9:
      return WindowRowFixed<9>(colsum, pairs, out, tw);
    case 11:
      return WindowRowFixed<11>(colsum, pairs, out, tw);
    default:
      break;
  }
  const int np = tw + window - 2;
  for (int x = 0; x < np; ++x) pairs[x] = colsum[x] + colsum[x + 1];
  const int32_t* __restrict last = colsum + window - 1;
  for (int x = 0; x < tw; ++x) out[x] = pairs[x] + last[x];
  for (int i = 2; i + 1 < window; i += 2) {
    const int32_t* __restrict p = pairs + i;
    for (int x = 0; x < tw; ++x) out[x] += p[x];
  }
}

// Tenengrad over the tile [x0, x0 + tw) x [y0, y0 + th) of an 8-bit frame, BORDER_REFLECT_101;
// sink(y, focus_row, pixel_row) receives each output row (tw values).
template <typename Sink>
SFF_INLINE SFF_TARGET void TenengradTile(const cv::Mat& frame, int x0, int y0, int tw, int th, int window,
                                         TenengradScratch& sc, Sink&& sink, const cv::Mat* prefetch_next = nullptr) {
  const int r = window / 2, ew = tw + 2 * r, pw = ew + 2, es = TenengradScratch::EnergyStride(ew);
  const int rows = frame.rows, cols = frame.cols;
  std::fill_n(sc.colsum.data(), es, 0);  // the energy ring needs no clearing: see old_in below
  // Columns x0 - r - 1 .. x0 + tw + r: [lo, hi) lie inside the frame and are copied directly,
  // the few outside are mirrored (BORDER_REFLECT_101).
  const int c_first = x0 - r - 1;
  const int lo = std::max(0, -c_first), hi = std::min(pw, cols - c_first);
  int loaded = 0, e_rows = 0;
  for (int yin = y0 - r - 1; yin <= y0 + th + r; ++yin) {
    const int ry = Reflect101(yin, rows);
    const uint8_t* src = frame.ptr<uint8_t>(ry);
    if (prefetch_next) {
      // The same rows of the next frame: the tile reads them on its next pass, by then from cache.
      const uint8_t* nx = prefetch_next->ptr<uint8_t>(ry) + std::max(c_first, 0);
      for (int i = 0; i < hi - lo; i += 64) __builtin_prefetch(nx + i, 0, 3);
    }
    int16_t* __restrict dst = sc.in[loaded % 3].data();
    {
      const uint8_t* __restrict s = src + c_first;
      for (int i = lo; i < hi; ++i) dst[i] = s[i];
    }
    for (int i = 0; i < lo; ++i) dst[i] = src[Reflect101(c_first + i, cols)];
    for (int i = std::max(hi, lo); i < pw; ++i) dst[i] = src[Reflect101(c_first + i, cols)];
    ++loaded;
    if (loaded < 3) continue;
    int32_t* old_out = sc.ering.data() + size_t(e_rows % window) * es;
    const int32_t* old_in = e_rows < window ? sc.zeros.data() : old_out;
    SobelEnergyRow(sc.in[loaded % 3].data(), sc.in[(loaded + 1) % 3].data(), sc.in[(loaded + 2) % 3].data(), sc, old_in,
                   old_out, ew);
    ++e_rows;
    if (e_rows < window) continue;
    const int y = y0 + e_rows - window;
    // A sink with Dest(y) receives the focus row in place (no copy).
    int32_t* focus_row = sc.focus.data();
    if constexpr (requires { sink.Dest(y); }) focus_row = sink.Dest(y);
    WindowRow(sc.colsum.data(), sc.pairs.data(), focus_row, tw, window);
    sink(y, focus_row, frame.ptr<uint8_t>(y) + x0);
  }
}

// Sink of the fused kernel: updates the state of the tile row (a functor rather than a lambda so
// that it is always inlined, and compiled for this file's instruction set).
struct StateSink {
  StatePlanes<int32_t, uint8_t>& st;
  int k, y0, tw, sx, sy;
  SFF_INLINE SFF_TARGET void operator()(int y, const int32_t* f, const uint8_t* pix) {
    UpdateRow(st, size_t(y - y0 + sy) * st.width + sx, k, f, pix, tw);
  }
};

// Sink of the batch path: keeps the focus row of frame slot `slot` for the later state update.
struct VolumeSink {
  int32_t* vol;
  int slot, y0, tw;
  SFF_INLINE SFF_TARGET int32_t* Dest(int y) { return vol + (size_t(slot) * kBatchTileH + size_t(y - y0)) * kTileW; }
  SFF_INLINE SFF_TARGET void operator()(int, const int32_t*, const uint8_t*) {}  // already in place
};

// Sink of the whole-frame map (ComputeTenengradU8): copies each focus row out.
struct CopySink {
  cv::Mat* out;
  int x0, tw;
  SFF_INLINE SFF_TARGET void operator()(int y, const int32_t* f, const uint8_t*) {
    std::copy_n(f, tw, out->ptr<int32_t>(y) + x0);
  }
};

template <typename P>
SFF_TARGET void ExactRowsFromFocusImpl(StatePlanes<float, P>& st, int k, const cv::Mat& focus, int focus_y0,
                                       const cv::Mat& frame, int y_begin, int y_end) {
  for (int y = y_begin; y < y_end; ++y)
    UpdateRow(st, size_t(y) * st.width, k, focus.ptr<float>(y - focus_y0), frame.ptr<P>(y), st.width);
}

}  // namespace inspection::sff_internal::SFF_ISA_NS

namespace inspection::sff_internal {

template <>
SFF_TARGET void TenengradKernels<SFF_ISA>::FusedTileFrame(const cv::Mat& frame, int k, int x0, int y0, int tw, int th,
                                                          int window, TenengradScratch& sc,
                                                          StatePlanes<int32_t, uint8_t>& st, int sx, int sy,
                                                          const cv::Mat* next) {
  SFF_ISA_NS::TenengradTile(frame, x0, y0, tw, th, window, sc, SFF_ISA_NS::StateSink{st, k, y0, tw, sx, sy}, next);
}

template <>
SFF_TARGET void TenengradKernels<SFF_ISA>::FocusRowsToVolume(const cv::Mat& frame, int slot, int x0, int y0, int tw,
                                                             int th, int window, TenengradScratch& sc, int32_t* vol,
                                                             const cv::Mat* next) {
  SFF_ISA_NS::TenengradTile(frame, x0, y0, tw, th, window, sc, SFF_ISA_NS::VolumeSink{vol, slot, y0, tw}, next);
}

template <>
SFF_TARGET void TenengradKernels<SFF_ISA>::ExactRowFrames(StatePlanes<int32_t, uint8_t>& st, size_t off, int n,
                                                          int k_begin, int k_end, const int32_t* vol_row,
                                                          size_t slot_stride, const uint8_t* const* pix_rows) {
  for (int k = k_begin; k < k_end; ++k) {
    SFF_ISA_NS::UpdateRow(st, off, k, vol_row + size_t(k - k_begin) * slot_stride, pix_rows[k - k_begin], n);
  }
}

template <>
SFF_TARGET void TenengradKernels<SFF_ISA>::ExactRowsFromFocus(StatePlanes<float, uint8_t>& st, int k,
                                                              const cv::Mat& focus, int focus_y0, const cv::Mat& frame,
                                                              int y_begin, int y_end) {
  SFF_ISA_NS::ExactRowsFromFocusImpl(st, k, focus, focus_y0, frame, y_begin, y_end);
}

template <>
SFF_TARGET void TenengradKernels<SFF_ISA>::ExactRowsFromFocus(StatePlanes<float, uint16_t>& st, int k,
                                                              const cv::Mat& focus, int focus_y0, const cv::Mat& frame,
                                                              int y_begin, int y_end) {
  SFF_ISA_NS::ExactRowsFromFocusImpl(st, k, focus, focus_y0, frame, y_begin, y_end);
}

template <>
SFF_TARGET void TenengradKernels<SFF_ISA>::TenengradMap(const cv::Mat& frame, int window_px, cv::Mat* out) {
  TenengradScratch sc;
  sc.Reserve(window_px);
  for (int y0 = 0; y0 < frame.rows; y0 += kTileH) {
    for (int x0 = 0; x0 < frame.cols; x0 += kTileW) {
      const int tw = std::min(kTileW, frame.cols - x0), th = std::min(kTileH, frame.rows - y0);
      SFF_ISA_NS::TenengradTile(frame, x0, y0, tw, th, window_px, sc, SFF_ISA_NS::CopySink{out, x0, tw});
    }
  }
}

}  // namespace inspection::sff_internal

#undef SFF_ISA
#undef SFF_ISA_NS
#undef SFF_TARGET
