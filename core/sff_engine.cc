// Streaming shape from focus (thesis 3.1): per-frame focus measure (3.1.3), running per-pixel
// maximum with its neighbours, depth interpolation and confidence at the end (3.1.4).
// Per-pixel state is O(pixels): best focus value, its frame index, j values before and after it,
// the last j values, the curve's sum and squared steps (for the confidence) and the all-in-focus
// grey value. 8-bit Tenengrad runs through a fused integer kernel (Sobel, squares, window sum and
// state update in one pass over a cache-sized tile, AVX2 / AVX-512 selected at run time); with
// maximum or Gaussian interpolation (the scan default) its state is the compact 23-byte layout
// described at CompactState (exact 32-bit state was 40 bytes), and PushFrame takes frames in
// chunks of 8 so that the state, which bounds its speed, is streamed through memory once per
// chunk rather than once per frame. The line fit and every other measure (through
// core/focus_measure.h) keep exact 32-bit state: 28 + 12 j bytes per pixel (StatePlanes).
#include "core/sff_engine.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <thread>
#include <type_traits>

#include <immintrin.h>

#include <opencv2/imgproc.hpp>

#include "core/cpu_features.h"
#include "core/depth_interpolation.h"
#include "core/focus_measure.h"
#include "core/parallel_for.h"
#include "core/sff_state.h"
#include "core/stack.h"

namespace inspection {

using namespace sff_internal;  // NOLINT: transitional, while the kernels move out

namespace {

// Tile of the fused kernel in PushFrame: 256 x 64 pixels; the halo (window + 1 extra rows and
// columns of input) stays near 10 % for the 7 x 7 window.
constexpr int kTileW = 256;
constexpr int kTileH = 64;
// Batch path: 256 x 32 tiles (compact state 23 bytes per pixel = 188 KB, in L2; exact line-fit
// state up to 76 bytes = 620 KB), frames in chunks of 8 whose focus rows are kept (256 x 32 x 8
// x 4 B = 256 KB) so that each state row is updated for 8 frames while it sits in registers / L1.
constexpr int kBatchTileH = 32;
constexpr int kFrameChunk = 8;

int Reflect101(int p, int len) {
  if (len == 1) return 0;
  while (p < 0 || p >= len) p = p < 0 ? -p : 2 * len - 2 - p;
  return p;
}

// First frame: the maximum is frame 0.
template <typename T, typename P>
SFF_INLINE void InitRow(StatePlanes<T, P>& s, size_t off, const T* __restrict f, const P* __restrict pix, int n) {
  T* __restrict best = s.best.data() + off;
  int32_t* __restrict idx = s.idx.data() + off;
  float* __restrict sum = s.sum.data() + off;
  int32_t* __restrict aif = s.aif.data() + off;
  for (int x = 0; x < n; ++x) {
    best[x] = f[x];
    idx[x] = 0;
    sum[x] = ToFloat(f[x]);
    aif[x] = pix[x];
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

// Row kernels of the state update, compiled twice: for AVX2 and portable (the ISA is chosen at
// run time). Each is a separate non-inlined function with restrict pointers and lanes of one
// width, the form in which GCC vectorises them; masks are built with integer bit operations
// because GCC does not if-convert an integer comparison selecting a float.
#define SFF_DEFINE_ROW_KERNELS(NS, ...)                                                                       \
  namespace NS {                                                                                              \
  /* Sum of F and, for k >= 2, t_k = F_k - 2 F_(k-1) + F_(k-2) (exact in T for int32), whose square */   \
  /* goes to curv_all and, when t_k involves the maximum (m is k-2, k-1 or k: new max), to curv_excl. */      \
  template <typename T>                                                                                       \
  __VA_ARGS__ void StatsRow(int n, int k, const T* __restrict f, const T* __restrict best,                   \
                            const int32_t* __restrict idx, const T* __restrict last,                          \
                            const T* __restrict last2, float* __restrict sum, float* __restrict curv_all,     \
                            float* __restrict curv_excl) {                                                    \
    if (k < 2) {                                                                                              \
      for (int x = 0; x < n; ++x) sum[x] += ToFloat(f[x]);                                                    \
      return;                                                                                                 \
    }                                                                                                         \
    const int32_t km1 = k - 1, km2 = k - 2;                                                                   \
    for (int x = 0; x < n; ++x) {                                                                             \
      const T v = f[x];                                                                                       \
      /* In float: for wide windows 2 F overflows int32. */                                                   \
      const float t = (ToFloat(v) - ToFloat(last[x])) - (ToFloat(last[x]) - ToFloat(last2[x]));               \
      const float t2 = t * t;                                                                                 \
      const uint32_t mgt = uint32_t(-int32_t(v > best[x]));                                                   \
      const int32_t id = idx[x];                                                                              \
      const uint32_t mnear = uint32_t(-int32_t((id == km1) | (id == km2)));                                   \
      const uint32_t tb = std::bit_cast<uint32_t>(t2);                                                        \
      const float kept = curv_excl[x] + std::bit_cast<float>(tb & mnear);                                     \
      sum[x] += ToFloat(v);                                                                                   \
      curv_all[x] += t2;                                                                                      \
      curv_excl[x] = std::bit_cast<float>((tb & mgt) | (std::bit_cast<uint32_t>(kept) & ~mgt));              \
    }                                                                                                         \
  }                                                                                                           \
  /* Frame k >= 1, one neighbour each side: statistics and maximum tracking in one pass. For k == 1 */  \
  /* t_k does not exist: curv_scale = 0 makes it contribute nothing. */                                     \
  template <typename T, typename P>                                                                           \
  __VA_ARGS__ void UpdateRowJ1(int n, int k, float curv_scale, const T* __restrict f,                        \
                               const P* __restrict pix, T* __restrict best, int32_t* __restrict idx,          \
                               T* __restrict prev, T* __restrict next, T* __restrict last,                    \
                               T* __restrict last2, int32_t* __restrict aif, float* __restrict sum,           \
                               float* __restrict curv_all, float* __restrict curv_excl) {                     \
    const int32_t kk = k, km1 = k - 1, km2 = k - 2;                                                           \
    for (int x = 0; x < n; ++x) {                                                                             \
      const T v = f[x], b = best[x], l = last[x], l2 = last2[x];                                              \
      const int32_t id = idx[x];                                                                              \
      const float t = (ToFloat(v) - ToFloat(l)) - (ToFloat(l) - ToFloat(l2)); /* float: 2 F overflows int32 */ \
      const float t2 = curv_scale * (t * t);                                                                  \
      const uint32_t mgt = uint32_t(-int32_t(v > b));                                                         \
      const uint32_t mnear = uint32_t(-int32_t((id == km1) | (id == km2)));                                   \
      const uint32_t tb = std::bit_cast<uint32_t>(t2);                                                        \
      const float kept = curv_excl[x] + std::bit_cast<float>(tb & mnear);                                     \
      sum[x] += ToFloat(v);                                                                                   \
      curv_all[x] += t2;                                                                                      \
      curv_excl[x] = std::bit_cast<float>((tb & mgt) | (std::bit_cast<uint32_t>(kept) & ~mgt));              \
      const bool gt = v > b;                                                                                  \
      const T nx = next[x], pv = prev[x];                                                                     \
      const int32_t a = aif[x], p = pix[x];                                                                   \
      next[x] = gt ? T(0) : (id == km1 ? v : nx);                                                             \
      prev[x] = gt ? l : pv;                                                                                  \
      best[x] = gt ? v : b;                                                                                   \
      idx[x] = gt ? kk : id;                                                                                  \
      aif[x] = gt ? p : a;                                                                                    \
      last2[x] = l;                                                                                           \
      last[x] = v;                                                                                            \
    }                                                                                                         \
  }                                                                                                           \
  }  // namespace NS

SFF_DEFINE_ROW_KERNELS(avx2, __attribute__((target("avx2"), noinline)))
SFF_DEFINE_ROW_KERNELS(portable, __attribute__((noinline)))

// Curve statistics of frame k >= 1, before the maximum is updated: sum, second differences.
template <typename T>
void CurveStats(bool simd, int k, const T* f, const T* best, const int32_t* idx, const T* last, const T* last2,
                float* sum, float* curv_all, float* curv_excl, int n) {
  if (simd) avx2::StatsRow(n, k, f, best, idx, last, last2, sum, curv_all, curv_excl);
  else portable::StatsRow(n, k, f, best, idx, last, last2, sum, curv_all, curv_excl);
}

// Frame k >= 1, general j (line fit).
template <typename T, typename P>
void UpdateRowGeneral(StatePlanes<T, P>& s, size_t off, int k, const T* f, const P* pix, int n) {
  const int J = s.j;
  CurveStats(s.simd, k, f, s.best.data() + off, s.idx.data() + off, s.ring[0].data() + off, s.last2.data() + off,
             s.sum.data() + off, s.curv_all.data() + off, s.curv_excl.data() + off, n);
  for (int x = 0; x < n; ++x) {
    const size_t i = off + x;
    const T v = f[x];
    const bool gt = v > s.best[i];
    const int dist = k - int(s.idx[i]);
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
      s.idx[i] = k;
      s.aif[i] = pix[x];
    }
    s.last2[i] = s.ring[0][i];
    for (int j = J - 1; j > 0; --j) s.ring[j][i] = s.ring[j - 1][i];
    s.ring[0][i] = v;
  }
}

template <typename T, typename P>
inline void UpdateRow(StatePlanes<T, P>& s, size_t off, int k, const T* f, const P* pix, int n) {
  if (k == 0) {
    InitRow(s, off, f, pix, n);
  } else if (s.j == 1) {
    // The hot path (maximum and Gaussian interpolation).
    const float curv_scale = k >= 2 ? 1.f : 0.f;
    if (s.simd) {
      avx2::UpdateRowJ1<T, P>(n, k, curv_scale, f, pix, s.best.data() + off, s.idx.data() + off,
                              s.before[0].data() + off, s.after[0].data() + off, s.ring[0].data() + off,
                              s.last2.data() + off, s.aif.data() + off, s.sum.data() + off, s.curv_all.data() + off,
                              s.curv_excl.data() + off);
    } else {
      portable::UpdateRowJ1<T, P>(n, k, curv_scale, f, pix, s.best.data() + off, s.idx.data() + off,
                                  s.before[0].data() + off, s.after[0].data() + off, s.ring[0].data() + off,
                                  s.last2.data() + off, s.aif.data() + off, s.sum.data() + off,
                                  s.curv_all.data() + off, s.curv_excl.data() + off);
    }
  } else {
    UpdateRowGeneral(s, off, k, f, pix, n);
  }
}

// Scratch of the fused Tenengrad kernel for one tile (one per worker thread).
struct TenengradScratch {
  std::vector<int16_t> in[3];   // three input rows, reflected, widened: width tw + 2R + 2
  std::vector<int16_t> sv, dv;  // vertical [1 2 1] and [1 0 -1] of the three rows (AVX2 path)
  std::vector<int32_t> ering;   // the last `window` energy rows Gx^2 + Gy^2: stride EnergyStride(ew)
  std::vector<int32_t> zeros;   // an all-zero energy row: the "old" row of the first `window` rows
  std::vector<int32_t> colsum;  // vertical window sums of the energy
  std::vector<int32_t> pairs;   // horizontal pair sums of colsum
  std::vector<int32_t> focus;   // one output row
  void Reserve(int window) {
    const int r = window / 2, ew = kTileW + 2 * r, es = EnergyStride(ew);
    // The AVX2 kernel runs whole blocks of 16 up to es (+ 16 input columns); the columns past
    // the tile's are computed but never read.
    for (auto& v : in) v.resize(size_t(es) + 18);
    sv.resize(size_t(es) + 18);
    dv.resize(size_t(es) + 18);
    ering.resize(size_t(es) * window);
    zeros.assign(size_t(es), 0);
    colsum.resize(size_t(es));
    pairs.resize(size_t(ew));
    focus.resize(size_t(kTileW));
  }
  // Energy row width ew rounded up to whole blocks of 16.
  static int EnergyStride(int ew) { return (ew + 15) & ~15; }
};

// Sobel energy of one row (eq. 3.13-3.14 before the window sum) and the running column sums.
// a, b, c: input rows y-1, y, y+1; output x uses columns x .. x+2 (centre x+1).
// old_in: the energy row leaving the window (old_out itself, or zeros while the window fills).
SFF_INLINE void EnergyRow(const int16_t* __restrict a, const int16_t* __restrict b, const int16_t* __restrict c,
                          const int32_t* old_in, int32_t* old_out, int32_t* __restrict colsum, int ew) {
  for (int x = 0; x < ew; ++x) {
    const int32_t gx = (a[x] + 2 * b[x] + c[x]) - (a[x + 2] + 2 * b[x + 2] + c[x + 2]);
    const int32_t gy = (a[x] - c[x]) + 2 * (a[x + 1] - c[x + 1]) + (a[x + 2] - c[x + 2]);
    const int32_t e = gx * gx + gy * gy;
    colsum[x] += e - old_in[x];
    old_out[x] = e;
  }
}

// The same with AVX2 in 16-bit lanes: |Gx|, |Gy| <= 1020 fit int16, and vpmaddwd of interleaved
// (Gx, Gy) pairs gives Gx^2 + Gy^2 in int32 exactly.
// Whole blocks of 16 up to EnergyStride(ew) (buffers sized by TenengradScratch::Reserve): the
// columns past ew hold garbage that is never read.
__attribute__((target("avx2"))) inline void EnergyRowAvx2(const int16_t* a, const int16_t* b, const int16_t* c,
                                                          int16_t* sv, int16_t* dv, const int32_t* old_in,
                                                          int32_t* old_out, int32_t* colsum, int ew) {
  const int es = TenengradScratch::EnergyStride(ew);
  for (int i = 0; i < es + 2; i += 16) {
    const __m256i va = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(a + i));
    const __m256i vb = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + i));
    const __m256i vc = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(c + i));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(sv + i),
                        _mm256_add_epi16(_mm256_add_epi16(va, vc), _mm256_add_epi16(vb, vb)));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(dv + i), _mm256_sub_epi16(va, vc));
  }
  for (int x = 0; x < es; x += 16) {
    const __m256i gx = _mm256_sub_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(sv + x)),
                                        _mm256_loadu_si256(reinterpret_cast<const __m256i*>(sv + x + 2)));
    const __m256i d1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(dv + x + 1));
    const __m256i gy = _mm256_add_epi16(
        _mm256_add_epi16(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(dv + x)),
                         _mm256_loadu_si256(reinterpret_cast<const __m256i*>(dv + x + 2))),
        _mm256_add_epi16(d1, d1));
    const __m256i lo = _mm256_unpacklo_epi16(gx, gy), hi = _mm256_unpackhi_epi16(gx, gy);
    const __m256i elo = _mm256_madd_epi16(lo, lo), ehi = _mm256_madd_epi16(hi, hi);
    // unpack works within 128-bit lanes: restore pixel order x .. x+7 and x+8 .. x+15.
    const __m256i e0 = _mm256_permute2x128_si256(elo, ehi, 0x20);
    const __m256i e1 = _mm256_permute2x128_si256(elo, ehi, 0x31);
    __m256i* cs = reinterpret_cast<__m256i*>(colsum + x);
    const __m256i* oi = reinterpret_cast<const __m256i*>(old_in + x);
    __m256i* od = reinterpret_cast<__m256i*>(old_out + x);
    const __m256i o0 = _mm256_loadu_si256(oi), o1 = _mm256_loadu_si256(oi + 1);
    _mm256_storeu_si256(cs, _mm256_add_epi32(_mm256_loadu_si256(cs), _mm256_sub_epi32(e0, o0)));
    _mm256_storeu_si256(cs + 1, _mm256_add_epi32(_mm256_loadu_si256(cs + 1), _mm256_sub_epi32(e1, o1)));
    _mm256_storeu_si256(od, e0);
    _mm256_storeu_si256(od + 1, e1);
  }
}

// Horizontal window sum of the column sums: out[x] = sum of colsum[x .. x + window - 1]. Built
// from pair sums p[x] = colsum[x] + colsum[x + 1]: (window + 1) / 2 passes instead of window.
// W: the window as a compile-time constant (the common sizes): one pass adds all pair sums.
template <int W>
SFF_INLINE void WindowRowFixed(const int32_t* __restrict colsum, int32_t* __restrict pairs, int32_t* __restrict out,
                               int tw) {
  const int np = tw + W - 2;
  for (int x = 0; x < np; ++x) pairs[x] = colsum[x] + colsum[x + 1];
  for (int x = 0; x < tw; ++x) {
    int32_t s = colsum[x + W - 1];
    for (int i = 0; i + 1 < W; i += 2) s += pairs[x + i];
    out[x] = s;
  }
}

SFF_INLINE void WindowRow(const int32_t* __restrict colsum, int32_t* __restrict pairs, int32_t* __restrict out,
                          int tw, int window) {
  switch (window) {
    case 3: return WindowRowFixed<3>(colsum, pairs, out, tw);
    case 5: return WindowRowFixed<5>(colsum, pairs, out, tw);
    case 7: return WindowRowFixed<7>(colsum, pairs, out, tw);
    case 9: return WindowRowFixed<9>(colsum, pairs, out, tw);
    case 11: return WindowRowFixed<11>(colsum, pairs, out, tw);
    default: break;
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
template <bool kAvx2, typename Sink>
SFF_INLINE void TenengradTile(const cv::Mat& frame, int x0, int y0, int tw, int th, int window,
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
    if constexpr (kAvx2) {
      EnergyRowAvx2(sc.in[loaded % 3].data(), sc.in[(loaded + 1) % 3].data(), sc.in[(loaded + 2) % 3].data(),
                    sc.sv.data(), sc.dv.data(), old_in, old_out, sc.colsum.data(), ew);
    } else {
      EnergyRow(sc.in[loaded % 3].data(), sc.in[(loaded + 1) % 3].data(), sc.in[(loaded + 2) % 3].data(), old_in,
                old_out, sc.colsum.data(), ew);
    }
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
// that it is always inlined into the AVX2 clone).
struct StateSink {
  StatePlanes<int32_t, uint8_t>& st;
  int k, y0, tw, sx, sy;
  SFF_INLINE void operator()(int y, const int32_t* f, const uint8_t* pix) {
    UpdateRow(st, size_t(y - y0 + sy) * st.width + sx, k, f, pix, tw);
  }
};

// One frame k over one tile, updating state whose (0, 0) is the tile's top-left at (sx, sy).
template <bool kAvx2>
SFF_INLINE void FusedTileFrameImpl(const cv::Mat& frame, int k, int x0, int y0, int tw, int th, int window,
                                   TenengradScratch& sc, StatePlanes<int32_t, uint8_t>& st, int sx, int sy,
                                   const cv::Mat* next) {
  TenengradTile<kAvx2>(frame, x0, y0, tw, th, window, sc, StateSink{st, k, y0, tw, sx, sy}, next);
}

__attribute__((target("avx2"))) void FusedTileFrameAvx2(const cv::Mat& frame, int k, int x0, int y0, int tw, int th,
                                                        int window, TenengradScratch& sc,
                                                        StatePlanes<int32_t, uint8_t>& st, int sx, int sy,
                                                        const cv::Mat* next) {
  FusedTileFrameImpl<true>(frame, k, x0, y0, tw, th, window, sc, st, sx, sy, next);
}
void FusedTileFramePortable(const cv::Mat& frame, int k, int x0, int y0, int tw, int th, int window,
                            TenengradScratch& sc, StatePlanes<int32_t, uint8_t>& st, int sx, int sy,
                            const cv::Mat* next) {
  FusedTileFrameImpl<false>(frame, k, x0, y0, tw, th, window, sc, st, sx, sy, next);
}

void FusedTileFrame(const cv::Mat& frame, int k, int x0, int y0, int tw, int th, int window, TenengradScratch& sc,
                    StatePlanes<int32_t, uint8_t>& st, int sx, int sy, const cv::Mat* next = nullptr) {
  if (st.simd) FusedTileFrameAvx2(frame, k, x0, y0, tw, th, window, sc, st, sx, sy, next);
  else FusedTileFramePortable(frame, k, x0, y0, tw, th, window, sc, st, sx, sy, next);
}

__attribute__((target("avx2"))) inline __m256i ld(const int32_t* p) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
}
__attribute__((target("avx2"))) inline void st(int32_t* p, __m256i v) {
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), v);
}

// Lanes of y where the 32-bit lane of mask is all ones, else of x (mask lanes: 0 or all ones).
// vblendvps: GCC turns _mm256_blendv_epi8 on such masks into an extra byte comparison.
__attribute__((target("avx2"))) inline __m256i BlendLanes(__m256i x, __m256i y, __m256i mask) {
  return _mm256_castps_si256(
      _mm256_blendv_ps(_mm256_castsi256_ps(x), _mm256_castsi256_ps(y), _mm256_castsi256_ps(mask)));
}

// Frames k_begin .. k_end-1 over pixels x_begin .. x_end-1 of a row (frame 0 on the Reset
// state initialises it: t_0 and t_1 do not exist, F_max = F(0), idx = 0): the focus
// value of frame k at x is vol_row[(k - slot0) * slot_stride + x], its grey value
// pix_rows[k - slot0][x]. The reference for the vector kernels below, which do the same float
// and integer operations in the same order (bit-identical). Since idx < k at frame k,
// idx == k-1 is idx > k-2 and idx in {k-1, k-2} (t_k involves the maximum) is idx > k-3.
void UpdateCompactScalar(const CompactPtrs& s, int x_begin, int x_end, int k_begin, int k_end, int slot0,
                         const int32_t* vol_row, size_t slot_stride, const uint8_t* const* pix_rows) {
  const float pmax = FromBits(kPendingMaxBits);
  for (int x = x_begin; x < x_end; ++x) {
    int32_t b = s.best[x];
    const uint32_t w1 = s.sum_idx[x], w2 = s.kept_idx[x];
    int32_t id = int32_t((w1 & 0xFFu) | ((w2 & 0xFFu) << 8));
    float sum = FromBits(w1 & kSumMask), kept = FromBits(w2 & kSumMask);
    uint32_t lbits = (uint32_t(s.last[x]) << 12) + kOneBits, l2bits = (uint32_t(s.last2[x]) << 12) + kOneBits;
    uint32_t pbits = (uint32_t(s.before[x]) << 12) + kOneBits, nbits = (uint32_t(s.after[x]) << 12) + kOneBits;
    uint32_t ebits = (uint32_t(s.pending[x]) << 13) + kOneBits;
    int32_t a = s.aif[x];
    float lf = FromBits(lbits) - 1.f;
    float d = lf - (FromBits(l2bits) - 1.f);  // F(k-1) - F(k-2)
    float ef = FromBits(ebits) - 1.f;
    for (int k = k_begin; k < k_end; ++k) {
      const int slot = k - slot0;
      const int32_t v = vol_row[size_t(slot) * slot_stride + x];
      const int32_t p = pix_rows[slot][x];
      const float fv = float(v);
      const float t = (fv - lf) - d;  // t_k in float: for wide windows 2 F overflows int32
      const float t2 = k >= 2 ? t * t : 0.f;  // t_1 does not exist
      const bool gt = v > b, was = id > k - 2, near = id > k - 3;
      kept = FromBits(Bits(kept + (gt ? ef : (near ? 0.f : t2))) & kSumMask);
      const float en = gt ? t2 : ef + (near ? t2 : 0.f);
      const float e1 = en + 1.f;
      ebits = Bits(e1 < pmax ? e1 : pmax) & kPendingMask;
      ef = FromBits(ebits) - 1.f;
      sum = FromBits(Bits(sum + fv) & kSumMask);
      const uint32_t vbits = Bits(fv + 1.f) & kSampleMask;
      const float vf = FromBits(vbits) - 1.f;
      nbits = gt ? kOneBits : (was ? vbits : nbits);
      pbits = gt ? lbits : pbits;
      b = gt ? v : b;
      id = gt ? k : id;
      a = gt ? p : a;
      d = vf - lf;
      lf = vf;
      l2bits = lbits;
      lbits = vbits;
    }
    s.best[x] = b;
    s.sum_idx[x] = Bits(sum) | (uint32_t(id) & 0xFFu);
    s.kept_idx[x] = Bits(kept) | (uint32_t(id) >> 8);
    s.last[x] = uint16_t((lbits - kOneBits) >> 12);
    s.last2[x] = uint16_t((l2bits - kOneBits) >> 12);
    s.before[x] = uint16_t((pbits - kOneBits) >> 12);
    s.after[x] = uint16_t((nbits - kOneBits) >> 12);
    s.pending[x] = uint16_t((ebits - kOneBits) >> 13);
    s.aif[x] = uint8_t(a);
  }
}

__attribute__((target("avx2"))) inline __m256i Ld16(const uint16_t* p) {
  return _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
}
__attribute__((target("avx2"))) inline void St16(uint16_t* p, __m256i v) {  // lanes < 65536
  _mm_storeu_si128(reinterpret_cast<__m128i*>(p),
                   _mm_packus_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1)));
}
__attribute__((target("avx2"))) inline __m256i Ld8(const uint8_t* p) {
  return _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)));
}
__attribute__((target("avx2"))) inline void St8(uint8_t* p, __m256i v) {  // lanes < 256
  const __m128i w = _mm_packus_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
  _mm_storel_epi64(reinterpret_cast<__m128i*>(p), _mm_packus_epi16(w, w));
}
__attribute__((target("avx2"))) inline __m256 AsPs(__m256i v) { return _mm256_castsi256_ps(v); }
__attribute__((target("avx2"))) inline __m256i AsSi(__m256 v) { return _mm256_castps_si256(v); }

// UpdateCompactScalar for blocks of 8 pixels whose state stays in registers over the frames.
__attribute__((target("avx2"))) void UpdateCompactAvx2(const CompactPtrs& s, int x_begin, int x_end, int k_begin,
                                                       int k_end, int slot0, const int32_t* vol_row,
                                                       size_t slot_stride, const uint8_t* const* pix_rows) {
  const __m256i one_bits = _mm256_set1_epi32(int(kOneBits)), low8 = _mm256_set1_epi32(0xFF);
  const __m256i sample_mask = _mm256_set1_epi32(int(kSampleMask)), pending_mask = _mm256_set1_epi32(int(kPendingMask));
  const __m256 sum_mask = AsPs(_mm256_set1_epi32(int(kSumMask)));
  const __m256 pmax = AsPs(_mm256_set1_epi32(int(kPendingMaxBits)));
  const __m256 fone = _mm256_set1_ps(1.f), fzero = _mm256_setzero_ps();
  const __m256i ione = _mm256_set1_epi32(1);
  for (int x = x_begin; x + 8 <= x_end; x += 8) {
    __m256i b = ld(s.best + x);
    const __m256i w1 = ld(reinterpret_cast<const int32_t*>(s.sum_idx + x));
    const __m256i w2 = ld(reinterpret_cast<const int32_t*>(s.kept_idx + x));
    __m256i id = _mm256_or_si256(_mm256_and_si256(w1, low8), _mm256_slli_epi32(_mm256_and_si256(w2, low8), 8));
    __m256 sum = _mm256_and_ps(AsPs(w1), sum_mask), kept = _mm256_and_ps(AsPs(w2), sum_mask);
    __m256i lbits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.last + x), 12), one_bits);
    __m256i l2bits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.last2 + x), 12), one_bits);
    __m256i pbits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.before + x), 12), one_bits);
    __m256i nbits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.after + x), 12), one_bits);
    __m256i ebits = _mm256_add_epi32(_mm256_slli_epi32(Ld16(s.pending + x), 13), one_bits);
    __m256i a = Ld8(s.aif + x);
    __m256 lf = _mm256_sub_ps(AsPs(lbits), fone);
    __m256 d = _mm256_sub_ps(lf, _mm256_sub_ps(AsPs(l2bits), fone));
    __m256 ef = _mm256_sub_ps(AsPs(ebits), fone);
    __m256i kv = _mm256_set1_epi32(k_begin), km2 = _mm256_set1_epi32(k_begin - 2),
            km3 = _mm256_set1_epi32(k_begin - 3);
    for (int k = k_begin; k < k_end; ++k) {
      const int slot = k - slot0;
      const __m256i v = ld(vol_row + size_t(slot) * slot_stride + x);
      const __m256i p = Ld8(pix_rows[slot] + x);
      const __m256 fv = _mm256_cvtepi32_ps(v);
      const __m256 t = _mm256_sub_ps(_mm256_sub_ps(fv, lf), d);
      const __m256 t2 = k >= 2 ? _mm256_mul_ps(t, t) : fzero;
      const __m256i gt = _mm256_cmpgt_epi32(v, b);
      const __m256 gtf = AsPs(gt);
      const __m256i was = _mm256_cmpgt_epi32(id, km2);
      const __m256 nearf = AsPs(_mm256_cmpgt_epi32(id, km3));
      kept = _mm256_and_ps(_mm256_add_ps(kept, _mm256_blendv_ps(_mm256_andnot_ps(nearf, t2), ef, gtf)), sum_mask);
      const __m256 en = _mm256_blendv_ps(_mm256_add_ps(ef, _mm256_and_ps(nearf, t2)), t2, gtf);
      ebits = _mm256_and_si256(AsSi(_mm256_min_ps(_mm256_add_ps(en, fone), pmax)), pending_mask);
      ef = _mm256_sub_ps(AsPs(ebits), fone);
      sum = _mm256_and_ps(_mm256_add_ps(sum, fv), sum_mask);
      const __m256i vbits = _mm256_and_si256(AsSi(_mm256_add_ps(fv, fone)), sample_mask);
      const __m256 vf = _mm256_sub_ps(AsPs(vbits), fone);
      nbits = BlendLanes(BlendLanes(nbits, vbits, was), one_bits, gt);
      pbits = BlendLanes(pbits, lbits, gt);
      b = BlendLanes(b, v, gt);
      id = BlendLanes(id, kv, gt);
      a = BlendLanes(a, p, gt);
      d = _mm256_sub_ps(vf, lf);
      lf = vf;
      l2bits = lbits;
      lbits = vbits;
      kv = _mm256_add_epi32(kv, ione);
      km2 = _mm256_add_epi32(km2, ione);
      km3 = _mm256_add_epi32(km3, ione);
    }
    st(s.best + x, b);
    st(reinterpret_cast<int32_t*>(s.sum_idx + x), _mm256_or_si256(AsSi(sum), _mm256_and_si256(id, low8)));
    st(reinterpret_cast<int32_t*>(s.kept_idx + x), _mm256_or_si256(AsSi(kept), _mm256_srli_epi32(id, 8)));
    St16(s.last + x, _mm256_srli_epi32(_mm256_sub_epi32(lbits, one_bits), 12));
    St16(s.last2 + x, _mm256_srli_epi32(_mm256_sub_epi32(l2bits, one_bits), 12));
    St16(s.before + x, _mm256_srli_epi32(_mm256_sub_epi32(pbits, one_bits), 12));
    St16(s.after + x, _mm256_srli_epi32(_mm256_sub_epi32(nbits, one_bits), 12));
    St16(s.pending + x, _mm256_srli_epi32(_mm256_sub_epi32(ebits, one_bits), 13));
    St8(s.aif + x, a);
  }
}

// GCC 12's AVX-512 headers trip -Wmaybe-uninitialized (their _mm512_undefined_* pass-through).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
__attribute__((target("avx512f"))) inline __m512 And512(__m512 x, __m512i mask) {
  return _mm512_castsi512_ps(_mm512_and_si512(_mm512_castps_si512(x), mask));
}
__attribute__((target("avx512f"))) inline __m512i Ld16x16(const uint16_t* p) {
  return _mm512_cvtepu16_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)));
}
__attribute__((target("avx512f"))) inline void St16x16(uint16_t* p, __m512i v) {
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), _mm512_cvtepi32_epi16(v));
}

// UpdateCompactAvx2 with 16 lanes and mask registers: the same operations per pixel (a masked
// add of t_k^2 equals adding t_k^2 & mask, as the pending sum is never -0), bit-identical.
__attribute__((target("avx512f"))) void UpdateCompactAvx512(const CompactPtrs& s, int x_begin, int x_end,
                                                            int k_begin, int k_end, int slot0, const int32_t* vol_row,
                                                            size_t slot_stride, const uint8_t* const* pix_rows) {
  const __m512i one_bits = _mm512_set1_epi32(int(kOneBits)), low8 = _mm512_set1_epi32(0xFF);
  const __m512i sample_mask = _mm512_set1_epi32(int(kSampleMask)), pending_mask = _mm512_set1_epi32(int(kPendingMask));
  const __m512i sum_mask = _mm512_set1_epi32(int(kSumMask));
  const __m512 pmax = _mm512_castsi512_ps(_mm512_set1_epi32(int(kPendingMaxBits)));
  const __m512 fone = _mm512_set1_ps(1.f), fzero = _mm512_setzero_ps();
  const __m512i ione = _mm512_set1_epi32(1);
  for (int x = x_begin; x + 16 <= x_end; x += 16) {
    __m512i b = _mm512_loadu_si512(s.best + x);
    const __m512i w1 = _mm512_loadu_si512(s.sum_idx + x), w2 = _mm512_loadu_si512(s.kept_idx + x);
    __m512i id = _mm512_or_si512(_mm512_and_si512(w1, low8), _mm512_slli_epi32(_mm512_and_si512(w2, low8), 8));
    __m512 sum = _mm512_castsi512_ps(_mm512_and_si512(w1, sum_mask));
    __m512 kept = _mm512_castsi512_ps(_mm512_and_si512(w2, sum_mask));
    __m512i lbits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.last + x), 12), one_bits);
    __m512i l2bits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.last2 + x), 12), one_bits);
    __m512i pbits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.before + x), 12), one_bits);
    __m512i nbits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.after + x), 12), one_bits);
    __m512i ebits = _mm512_add_epi32(_mm512_slli_epi32(Ld16x16(s.pending + x), 13), one_bits);
    __m512i a = _mm512_cvtepu8_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(s.aif + x)));
    __m512 lf = _mm512_sub_ps(_mm512_castsi512_ps(lbits), fone);
    __m512 d = _mm512_sub_ps(lf, _mm512_sub_ps(_mm512_castsi512_ps(l2bits), fone));
    __m512 ef = _mm512_sub_ps(_mm512_castsi512_ps(ebits), fone);
    __m512i kv = _mm512_set1_epi32(k_begin), km2 = _mm512_set1_epi32(k_begin - 2),
            km3 = _mm512_set1_epi32(k_begin - 3);
    for (int k = k_begin; k < k_end; ++k) {
      const int slot = k - slot0;
      const __m512i v = _mm512_loadu_si512(vol_row + size_t(slot) * slot_stride + x);
      const __m512i p = _mm512_cvtepu8_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(pix_rows[slot] + x)));
      const __m512 fv = _mm512_cvtepi32_ps(v);
      const __m512 t = _mm512_sub_ps(_mm512_sub_ps(fv, lf), d);
      const __m512 t2 = k >= 2 ? _mm512_mul_ps(t, t) : fzero;
      const __mmask16 gt = _mm512_cmpgt_epi32_mask(v, b);
      const __mmask16 was = _mm512_cmpgt_epi32_mask(id, km2);
      const __mmask16 near = _mm512_cmpgt_epi32_mask(id, km3);
      const __m512 addend = _mm512_mask_mov_ps(_mm512_maskz_mov_ps(_mm512_knot(near), t2), gt, ef);
      kept = And512(_mm512_add_ps(kept, addend), sum_mask);
      const __m512 en = _mm512_mask_mov_ps(_mm512_mask_add_ps(ef, near, ef, t2), gt, t2);
      ebits = _mm512_and_si512(_mm512_castps_si512(_mm512_min_ps(_mm512_add_ps(en, fone), pmax)), pending_mask);
      ef = _mm512_sub_ps(_mm512_castsi512_ps(ebits), fone);
      sum = And512(_mm512_add_ps(sum, fv), sum_mask);
      const __m512i vbits = _mm512_and_si512(_mm512_castps_si512(_mm512_add_ps(fv, fone)), sample_mask);
      const __m512 vf = _mm512_sub_ps(_mm512_castsi512_ps(vbits), fone);
      nbits = _mm512_mask_mov_epi32(_mm512_mask_mov_epi32(nbits, was, vbits), gt, one_bits);
      pbits = _mm512_mask_mov_epi32(pbits, gt, lbits);
      b = _mm512_mask_mov_epi32(b, gt, v);
      id = _mm512_mask_mov_epi32(id, gt, kv);
      a = _mm512_mask_mov_epi32(a, gt, p);
      d = _mm512_sub_ps(vf, lf);
      lf = vf;
      l2bits = lbits;
      lbits = vbits;
      kv = _mm512_add_epi32(kv, ione);
      km2 = _mm512_add_epi32(km2, ione);
      km3 = _mm512_add_epi32(km3, ione);
    }
    _mm512_storeu_si512(s.best + x, b);
    _mm512_storeu_si512(s.sum_idx + x, _mm512_or_si512(_mm512_castps_si512(sum), _mm512_and_si512(id, low8)));
    _mm512_storeu_si512(s.kept_idx + x, _mm512_or_si512(_mm512_castps_si512(kept), _mm512_srli_epi32(id, 8)));
    St16x16(s.last + x, _mm512_srli_epi32(_mm512_sub_epi32(lbits, one_bits), 12));
    St16x16(s.last2 + x, _mm512_srli_epi32(_mm512_sub_epi32(l2bits, one_bits), 12));
    St16x16(s.before + x, _mm512_srli_epi32(_mm512_sub_epi32(pbits, one_bits), 12));
    St16x16(s.after + x, _mm512_srli_epi32(_mm512_sub_epi32(nbits, one_bits), 12));
    St16x16(s.pending + x, _mm512_srli_epi32(_mm512_sub_epi32(ebits, one_bits), 13));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(s.aif + x), _mm512_cvtepi32_epi8(a));
  }
}
#pragma GCC diagnostic pop

// Frames k_begin .. k_end-1 over the n pixels of a state row at off: AVX-512 blocks of 16, AVX2
// blocks of 8 and the scalar rest, as the state selects.
void UpdateCompactRow(CompactState& st, size_t off, int n, int k_begin, int k_end, int slot0, const int32_t* vol_row,
                      size_t slot_stride, const uint8_t* const* pix_rows) {
  const CompactPtrs s = st.Row(off);
  int x = 0;
  if (st.avx512 && n >= 16) {
    x = n & ~15;
    UpdateCompactAvx512(s, 0, x, k_begin, k_end, slot0, vol_row, slot_stride, pix_rows);
  }
  if (st.avx2 && n - x >= 8) {
    const int x8 = x + ((n - x) & ~7);
    UpdateCompactAvx2(s, x, x8, k_begin, k_end, slot0, vol_row, slot_stride, pix_rows);
    x = x8;
  }
  if (x < n) UpdateCompactScalar(s, x, n, k_begin, k_end, slot0, vol_row, slot_stride, pix_rows);
}

// Sink of the batch path: keeps the focus row of frame slot `slot` for the later state update.
struct VolumeSink {
  int32_t* vol;
  int slot, y0, tw;
  SFF_INLINE int32_t* Dest(int y) { return vol + (size_t(slot) * kBatchTileH + size_t(y - y0)) * kTileW; }
  SFF_INLINE void operator()(int, const int32_t*, const uint8_t*) {}  // already in place
};

__attribute__((target("avx2"))) void FocusRowsToVolumeAvx2(const cv::Mat& frame, int slot, int x0, int y0, int tw,
                                                           int th, int window, TenengradScratch& sc, int32_t* vol,
                                                           const cv::Mat* next) {
  TenengradTile<true>(frame, x0, y0, tw, th, window, sc, VolumeSink{vol, slot, y0, tw}, next);
}
void FocusRowsToVolumePortable(const cv::Mat& frame, int slot, int x0, int y0, int tw, int th, int window,
                               TenengradScratch& sc, int32_t* vol, const cv::Mat* next) {
  TenengradTile<false>(frame, x0, y0, tw, th, window, sc, VolumeSink{vol, slot, y0, tw}, next);
}

template <typename P>
__attribute__((target("avx2"))) void UpdateRowsAvx2(StatePlanes<float, P>& st, int k, const cv::Mat& focus,
                                                    const cv::Mat& frame, int y_begin, int y_end) {
  for (int y = y_begin; y < y_end; ++y)
    UpdateRow(st, size_t(y) * st.width, k, focus.ptr<float>(y), frame.ptr<P>(y), st.width);
}
template <typename P>
void UpdateRowsPortable(StatePlanes<float, P>& st, int k, const cv::Mat& focus, const cv::Mat& frame, int y_begin,
                        int y_end) {
  for (int y = y_begin; y < y_end; ++y)
    UpdateRow(st, size_t(y) * st.width, k, focus.ptr<float>(y), frame.ptr<P>(y), st.width);
}

// Natural logarithm of positive, finite floats: exponent and mantissa in [sqrt(1/2), sqrt(2)),
// log(m) = 2 atanh(s), s = (m - 1) / (m + 1), |s| < 0.172, series to s^9 (relative error < 1e-7).
__attribute__((target("avx2"))) inline __m256 LogPositiveAvx2(__m256 x) {
  const __m256i bits = _mm256_castps_si256(x);
  __m256i e = _mm256_sub_epi32(_mm256_srli_epi32(bits, 23), _mm256_set1_epi32(127));
  __m256 m = _mm256_castsi256_ps(_mm256_or_si256(_mm256_and_si256(bits, _mm256_set1_epi32(0x007fffff)),
                                                 _mm256_set1_epi32(0x3f800000)));  // [1, 2)
  const __m256 big = _mm256_cmp_ps(m, _mm256_set1_ps(1.41421356f), _CMP_GT_OQ);
  m = _mm256_blendv_ps(m, _mm256_mul_ps(m, _mm256_set1_ps(0.5f)), big);
  e = _mm256_sub_epi32(e, _mm256_castps_si256(big));  // big lanes are -1: e + 1
  const __m256 one = _mm256_set1_ps(1.f);
  const __m256 sv = _mm256_div_ps(_mm256_sub_ps(m, one), _mm256_add_ps(m, one));
  const __m256 s2 = _mm256_mul_ps(sv, sv);
  __m256 poly = _mm256_set1_ps(1.f / 9.f);
  poly = _mm256_add_ps(_mm256_mul_ps(poly, s2), _mm256_set1_ps(1.f / 7.f));
  poly = _mm256_add_ps(_mm256_mul_ps(poly, s2), _mm256_set1_ps(1.f / 5.f));
  poly = _mm256_add_ps(_mm256_mul_ps(poly, s2), _mm256_set1_ps(1.f / 3.f));
  poly = _mm256_add_ps(_mm256_mul_ps(poly, s2), one);
  const __m256 log_m = _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(2.f), sv), poly);
  return _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(e), _mm256_set1_ps(0.69314718056f)), log_m);
}

// Interpolation and confidence of a compact state row span, 8 pixels at a time in float (one
// neighbour each side, maximum or Gaussian): the confidence of FocusConfidence and the Gaussian
// position of GaussianPeakZ. The outputs may be the state's own buffers (PushFrame's Finish
// writes depth into best and confidence into sum_idx): each block is read before it is written.
// Returns the number of kept pixels among the first n8 (a multiple of 8).
__attribute__((target("avx2"))) size_t FinishCompactAvx2(const CompactPtrs& s, int n8, const float* zf, int n,
                                                         bool gaussian, float min_confidence, uint32_t* depth,
                                                         uint32_t* conf, uint8_t* aif) {
  size_t valid = 0;
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.f);
  const __m256i izero = _mm256_setzero_si256(), low8 = _mm256_set1_epi32(0xFF);
  const __m256i one_bits = _mm256_set1_epi32(int(kOneBits));
  const __m256 sum_mask = AsPs(_mm256_set1_epi32(int(kSumMask)));
  const __m256i last_frame = _mm256_set1_epi32(n - 1);
  const __m256 inv_n = _mm256_set1_ps(1.f / float(n));
  const __m256 nan = _mm256_set1_ps(std::numeric_limits<float>::quiet_NaN());
  for (int x = 0; x < n8; x += 8) {
    const __m256i w1 = ld(reinterpret_cast<const int32_t*>(s.sum_idx + x));
    const __m256i w2 = ld(reinterpret_cast<const int32_t*>(s.kept_idx + x));
    const __m256i m = _mm256_or_si256(_mm256_and_si256(w1, low8), _mm256_slli_epi32(_mm256_and_si256(w2, low8), 8));
    const __m256 best = _mm256_cvtepi32_ps(ld(s.best + x));
    const __m256 f1 = _mm256_sub_ps(AsPs(_mm256_add_epi32(_mm256_slli_epi32(Ld16(s.before + x), 12), one_bits)), one);
    const __m256 f3 = _mm256_sub_ps(AsPs(_mm256_add_epi32(_mm256_slli_epi32(Ld16(s.after + x), 12), one_bits)), one);
    const __m128i grey = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(s.aif + x));
    // Confidence: prominence over the noise level of the second differences away from the peak.
    const __m256 mean = _mm256_mul_ps(_mm256_and_ps(AsPs(w1), sum_mask), inv_n);
    const __m256 prominence = _mm256_sub_ps(best, mean);
    const __m256i hi = _mm256_min_epi32(last_frame, _mm256_add_epi32(m, _mm256_set1_epi32(2)));
    const __m256i lo = _mm256_max_epi32(_mm256_set1_epi32(2), m);
    const __m256i excluded = _mm256_max_epi32(izero, _mm256_add_epi32(_mm256_sub_epi32(hi, lo), _mm256_set1_epi32(1)));
    const __m256i count = _mm256_sub_epi32(_mm256_set1_epi32(std::max(0, n - 2)), excluded);
    const __m256 sq = _mm256_max_ps(zero, _mm256_and_ps(AsPs(w2), sum_mask));
    const __m256 countf = _mm256_cvtepi32_ps(count);
    __m256 sigma = _mm256_sqrt_ps(_mm256_div_ps(sq, _mm256_mul_ps(_mm256_set1_ps(6.f), _mm256_max_ps(countf, one))));
    sigma = _mm256_and_ps(sigma, _mm256_cmp_ps(countf, zero, _CMP_GT_OQ));
    sigma = _mm256_max_ps(sigma, _mm256_mul_ps(_mm256_set1_ps(1e-3f), best));
    __m256 c = _mm256_sub_ps(one, _mm256_div_ps(_mm256_mul_ps(_mm256_set1_ps(float(kConfidenceSnrZero)), sigma),
                                                _mm256_max_ps(prominence, _mm256_set1_ps(1e-30f))));
    c = _mm256_min_ps(one, _mm256_max_ps(zero, c));
    const __m256 has_peak = _mm256_and_ps(_mm256_cmp_ps(prominence, zero, _CMP_GT_OQ),
                                          _mm256_cmp_ps(best, zero, _CMP_GT_OQ));
    c = _mm256_and_ps(c, has_peak);
    const __m256i at_end = _mm256_or_si256(_mm256_cmpeq_epi32(m, izero), _mm256_cmpeq_epi32(m, last_frame));
    c = _mm256_blendv_ps(c, _mm256_mul_ps(c, _mm256_set1_ps(0.5f)), AsPs(at_end));
    // Depth: the frame's z, moved to the Gaussian's peak where the fit is valid.
    const __m256 z2 = _mm256_i32gather_ps(zf, m, 4);
    __m256 z_um = z2;
    if (gaussian) {
      const __m256i mm1 = _mm256_max_epi32(izero, _mm256_sub_epi32(m, _mm256_set1_epi32(1)));
      const __m256i mp1 = _mm256_min_epi32(last_frame, _mm256_add_epi32(m, _mm256_set1_epi32(1)));
      const __m256 u1 = _mm256_sub_ps(_mm256_i32gather_ps(zf, mm1, 4), z2);
      const __m256 u3 = _mm256_sub_ps(_mm256_i32gather_ps(zf, mp1, 4), z2);
      const __m256 ok_f = _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(f1, zero, _CMP_GT_OQ),
                                                      _mm256_cmp_ps(f3, zero, _CMP_GT_OQ)),
                                        _mm256_andnot_ps(AsPs(at_end), _mm256_cmp_ps(best, zero, _CMP_GT_OQ)));
      // Logs only of positive finite ratios (others are masked out below).
      const __m256 safe1 = _mm256_blendv_ps(one, f1, ok_f), safe3 = _mm256_blendv_ps(one, f3, ok_f);
      const __m256 safe2 = _mm256_blendv_ps(one, best, ok_f);
      const __m256 a = LogPositiveAvx2(_mm256_div_ps(safe2, safe1));
      const __m256 b = LogPositiveAvx2(_mm256_div_ps(safe2, safe3));
      const __m256 den = _mm256_sub_ps(_mm256_mul_ps(a, u3), _mm256_mul_ps(b, u1));
      const __m256 num_var = _mm256_mul_ps(_mm256_mul_ps(u1, u3), _mm256_sub_ps(u1, u3));
      const __m256 mu = _mm256_div_ps(
          _mm256_sub_ps(_mm256_mul_ps(a, _mm256_mul_ps(u3, u3)), _mm256_mul_ps(b, _mm256_mul_ps(u1, u1))),
          _mm256_mul_ps(_mm256_set1_ps(2.f), den));
      const __m256 in_range = _mm256_and_ps(_mm256_cmp_ps(mu, _mm256_min_ps(u1, u3), _CMP_GE_OQ),
                                            _mm256_cmp_ps(mu, _mm256_max_ps(u1, u3), _CMP_LE_OQ));
      const __m256 ok = _mm256_and_ps(_mm256_and_ps(ok_f, in_range),
                                      _mm256_cmp_ps(_mm256_mul_ps(den, num_var), zero, _CMP_GT_OQ));
      z_um = _mm256_add_ps(z2, _mm256_and_ps(mu, ok));
    }
    const __m256 keep = _mm256_cmp_ps(c, _mm256_set1_ps(min_confidence), _CMP_GE_OQ);
    _mm256_storeu_ps(reinterpret_cast<float*>(conf + x), c);
    _mm256_storeu_ps(reinterpret_cast<float*>(depth + x), _mm256_blendv_ps(nan, z_um, keep));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(aif + x), grey);
    valid += size_t(__builtin_popcount(unsigned(_mm256_movemask_ps(keep))));
  }
  return valid;
}

// Scalar twin of LogPositiveAvx2: the same float operations in the same order (bit-identical).
inline float LogPositiveScalar(float x) {
  const uint32_t bits = std::bit_cast<uint32_t>(x);
  int32_t e = int32_t(bits >> 23) - 127;
  float m = std::bit_cast<float>((bits & 0x007fffffu) | 0x3f800000u);
  if (m > 1.41421356f) {
    m = m * 0.5f;
    e += 1;
  }
  const float sv = (m - 1.f) / (m + 1.f);
  const float s2 = sv * sv;
  float poly = 1.f / 9.f;
  poly = poly * s2 + 1.f / 7.f;
  poly = poly * s2 + 1.f / 5.f;
  poly = poly * s2 + 1.f / 3.f;
  poly = poly * s2 + 1.f;
  const float log_m = (2.f * sv) * poly;
  return float(e) * 0.69314718056f + log_m;
}

// Scalar twin of FinishCompactAvx2 for pixels x_begin .. count-1 (the tail after the AVX2
// blocks, or everything without AVX2): bit-identical per pixel; the same in-place rule.
size_t FinishCompactScalar(const CompactPtrs& s, int x_begin, int count, const float* zf, int n, bool gaussian,
                           float min_confidence, uint32_t* depth, uint32_t* conf, uint8_t* aif) {
  auto maxps = [](float a, float b) { return a > b ? a : b; };  // _mm256_max_ps(a, b)
  auto minps = [](float a, float b) { return a < b ? a : b; };  // _mm256_min_ps(a, b)
  size_t valid = 0;
  const float inv_n = 1.f / float(n);
  for (int x = x_begin; x < count; ++x) {
    const uint32_t w1 = s.sum_idx[x], w2 = s.kept_idx[x];
    const int32_t m = int32_t((w1 & 0xFFu) | ((w2 & 0xFFu) << 8));
    const float best = float(s.best[x]);
    const float f1 = FromBits((uint32_t(s.before[x]) << 12) + kOneBits) - 1.f;
    const float f3 = FromBits((uint32_t(s.after[x]) << 12) + kOneBits) - 1.f;
    const uint8_t grey = s.aif[x];
    const float mean = FromBits(w1 & kSumMask) * inv_n;
    const float prominence = best - mean;
    const int32_t hi = std::min(n - 1, m + 2), lo = std::max(2, m);
    const int32_t excluded = std::max(0, hi - lo + 1);
    const int32_t count_t = std::max(0, n - 2) - excluded;
    const float sq = maxps(0.f, FromBits(w2 & kSumMask));
    const float countf = float(count_t);
    float sigma = std::sqrt(sq / (6.f * maxps(countf, 1.f)));
    if (!(countf > 0.f)) sigma = 0.f;
    sigma = maxps(sigma, 1e-3f * best);
    float c = 1.f - (float(kConfidenceSnrZero) * sigma) / maxps(prominence, 1e-30f);
    c = minps(1.f, maxps(0.f, c));
    if (!(prominence > 0.f && best > 0.f)) c = 0.f;
    const bool at_end = m == 0 || m == n - 1;
    if (at_end) c = c * 0.5f;
    const float z2 = zf[m];
    float z_um = z2;
    if (gaussian) {
      const float u1 = zf[std::max(0, m - 1)] - z2, u3 = zf[std::min(n - 1, m + 1)] - z2;
      const bool ok_f = f1 > 0.f && f3 > 0.f && !at_end && best > 0.f;
      if (ok_f) {
        const float a = LogPositiveScalar(best / f1), b = LogPositiveScalar(best / f3);
        const float den = a * u3 - b * u1;
        const float num_var = (u1 * u3) * (u1 - u3);
        if (den * num_var > 0.f) {
          const float mu = (a * (u3 * u3) - b * (u1 * u1)) / (2.f * den);
          if (mu >= minps(u1, u3) && mu <= maxps(u1, u3)) z_um = z2 + mu;
        }
      }
      if (z_um == z2) z_um = z2 + 0.f;  // as the vector path adds a masked +0
    }
    const bool keep = c >= min_confidence;
    conf[x] = Bits(c);
    depth[x] = Bits(keep ? z_um : std::numeric_limits<float>::quiet_NaN());
    aif[x] = grey;
    valid += keep;
  }
  return valid;
}

// Interpolation and confidence of count pixels of a compact state row at off; outputs as above.
size_t FinishCompactRow(CompactState& st, size_t off, int count, const std::vector<float>& zf, const SffOptions& o,
                        uint32_t* depth, uint32_t* conf, uint8_t* aif) {
  const CompactPtrs s = st.Row(off);
  const int n = int(zf.size());
  const bool gaussian = o.interpolation == DepthInterpolation::kGaussian;
  const int n8 = st.avx2 ? (count & ~7) : 0;
  size_t valid = 0;
  if (n8 > 0) valid = FinishCompactAvx2(s, n8, zf.data(), n, gaussian, float(o.min_confidence), depth, conf, aif);
  return valid + FinishCompactScalar(s, n8, count, zf.data(), n, gaussian, float(o.min_confidence), depth, conf, aif);
}

Status CheckFrame(const cv::Mat& frame, int k, cv::Size size, int type) {
  if (frame.empty()) return Status::InvalidArgument("frame " + std::to_string(k) + ": empty image");
  if (frame.size() != size) {
    return Status::InvalidArgument("frame " + std::to_string(k) + ": size " + std::to_string(frame.cols) + "x" +
                                   std::to_string(frame.rows) + " differs from the stack's " +
                                   std::to_string(size.width) + "x" + std::to_string(size.height));
  }
  if (frame.type() != type) {
    return Status::InvalidArgument("frame " + std::to_string(k) + ": pixel type " + std::to_string(frame.type()) +
                                   " differs from the stack's " + std::to_string(type) +
                                   " (bit depth or channels mismatch)");
  }
  return Status::Ok();
}

// Checks of PushFrame for frame k = z.size(): the engine is open, the frame matches, z_um is
// finite and continues the strictly monotonic z, at most 65535 frames (16-bit frame index).
Status CheckPush(const cv::Mat& frame, double z_um, const std::vector<double>& z, bool finished, cv::Size size,
                 int type) {
  const int k = int(z.size());
  if (finished) return Status::FailedPrecondition("engine already finished");
  INSPECT_RETURN_IF_ERROR(CheckFrame(frame, k, size, type));
  if (!std::isfinite(z_um)) return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um is not finite");
  if (k >= 1) {
    const double dz = z_um - z.back();
    if (dz == 0.0 || (k >= 2 && (dz > 0) != (z[1] > z[0]))) {
      return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um " + std::to_string(z_um) +
                                     (dz == 0.0 ? " duplicates the previous frame's" : " is not strictly monotonic"));
    }
  }
  if (k >= 65535) return Status::ResourceExhausted("frame " + std::to_string(k) + ": more than 65535 frames");
  return Status::Ok();
}

// Engine of every case but the compact one below: other measures and 16-bit frames (float
// focus values) and the line fit (j neighbours each side), with exact per-pixel state.
template <typename T, typename P>
class Engine final : public SffEngine {
 public:
  static constexpr bool kFused = std::is_same_v<T, int32_t>;

  Engine(const SffOptions& o, cv::Size size, int type) : options_(o), size_(size), type_(type) {
    const int j = o.interpolation == DepthInterpolation::kLineFit ? o.linefit_half_width : 1;
    state_.Allocate(size.width, size.height, j, o.use_simd);
    threads_ = ResolveThreads(o.threads);
    if constexpr (kFused) {
      scratch_.resize(size_t(threads_));
      for (auto& s : scratch_) s.Reserve(o.window_px);
    }
  }

  Status PushFrame(const cv::Mat& frame, double z_um) override {
    const int k = int(z_.size());
    INSPECT_RETURN_IF_ERROR(CheckPush(frame, z_um, z_, finished_, size_, type_));
    if constexpr (kFused) {
      const int tiles_x = (size_.width + kTileW - 1) / kTileW, tiles_y = (size_.height + kTileH - 1) / kTileH;
      ParallelFor(tiles_x * tiles_y, threads_, [&](int t, int worker) {
        const int x0 = (t % tiles_x) * kTileW, y0 = (t / tiles_x) * kTileH;
        const int tw = std::min(kTileW, size_.width - x0), th = std::min(kTileH, size_.height - y0);
        FusedTileFrame(frame, k, x0, y0, tw, th, options_.window_px, scratch_[size_t(worker)], state_, x0, y0);
      });
    } else {
      cv::Mat focus;
      INSPECT_RETURN_IF_ERROR(ComputeFocusMeasure(frame, options_.focus_measure, options_.window_px, &focus)
                                  .WithContext("frame " + std::to_string(k) + ": "));
      const int bands = std::min(size_.height, threads_ * 4);
      ParallelFor(bands, threads_, [&](int b, int) {
        const int y_begin = size_.height * b / bands, y_end = size_.height * (b + 1) / bands;
        if (state_.simd) UpdateRowsAvx2(state_, k, focus, frame, y_begin, y_end);
        else UpdateRowsPortable(state_, k, focus, frame, y_begin, y_end);
      });
    }
    z_.push_back(z_um);
    return Status::Ok();
  }

  StatusOr<DepthResult> Finish() override {
    const int n = int(z_.size());
    if (finished_) return Status::FailedPrecondition("engine already finished");
    if (n < 3) return Status::InvalidArgument("stack has " + std::to_string(n) + " frames; at least 3 are needed");
    finished_ = true;
    DepthOutputs out;
    out.depth.create(size_, CV_32F);
    out.confidence.create(size_, CV_32F);
    out.aif.create(size_, type_);
    std::atomic<size_t> valid{0};
    ParallelFor(size_.height, threads_, [&](int y, int) {
      valid += FinishExactSpan(state_, size_t(y) * size_.width, size_.width, z_, options_, out, 0, y);
    });
    DepthResult r;
    r.depth_um = out.depth;
    r.confidence = out.confidence;
    r.all_in_focus = out.aif;
    r.frame_count = n;
    r.valid_fraction = double(valid.load()) / double(size_.area());
    state_ = {};  // release the O(pixels) state
    return r;
  }

  int frames_pushed() const override { return int(z_.size()); }
  size_t state_bytes() const override { return state_.Bytes(); }

 private:
  SffOptions options_;
  cv::Size size_;
  int type_;
  int threads_ = 1;
  bool finished_ = false;
  std::vector<double> z_;
  StatePlanes<T, P> state_;
  std::vector<TenengradScratch> scratch_;
};

// 8-bit frames, Tenengrad, maximum or Gaussian interpolation (the scan default): the fused
// kernel over the compact state (23 bytes per pixel); Finish writes depth, confidence and the
// all-in-focus image into the state's own buffers, so the result adds no memory, and frees the
// rest.
class CompactEngine final : public SffEngine {
 public:
  CompactEngine(const SffOptions& o, cv::Size size) : options_(o), size_(size) {
    state_.Allocate(size.width, size.height, o.use_simd, o.use_avx512);
    threads_ = ResolveThreads(o.threads);
    scratch_.resize(size_t(threads_));
    for (auto& s : scratch_) s.Reserve(o.window_px);
    volumes_.assign(size_t(threads_), std::vector<int32_t>(size_t(kTileW) * kBatchTileH * kFrameChunk));
  }

  // Frames are taken in chunks of kFrameChunk: each state tile is then read and written once
  // per chunk instead of once per frame (the state update is memory-bound), with the batch
  // path's kernels, so the result stays bit-identical. The frames of an open chunk are held
  // by reference (cv::Mat shares the pixels); a Mat over memory it does not own is copied.
  Status PushFrame(const cv::Mat& frame, double z_um) override {
    INSPECT_RETURN_IF_ERROR(CheckPush(frame, z_um, z_, finished_, size_, CV_8UC1));
    pending_.push_back(frame.u != nullptr ? frame : frame.clone());
    z_.push_back(z_um);
    if (int(pending_.size()) == kFrameChunk) ProcessPending();
    return Status::Ok();
  }

  StatusOr<DepthResult> Finish() override {
    const int n = int(z_.size());
    if (finished_) return Status::FailedPrecondition("engine already finished");
    if (n < 3) return Status::InvalidArgument("stack has " + std::to_string(n) + " frames; at least 3 are needed");
    ProcessPending();
    finished_ = true;
    volumes_ = {};
    const std::vector<float> zf(z_.begin(), z_.end());
    std::atomic<size_t> valid{0};
    uint32_t* depth = reinterpret_cast<uint32_t*>(state_.best.data);
    uint32_t* conf = reinterpret_cast<uint32_t*>(state_.sum_idx.data);
    ParallelFor(size_.height, threads_, [&](int y, int) {
      const size_t off = size_t(y) * size_.width;
      valid += FinishCompactRow(state_, off, size_.width, zf, options_, depth + off, conf + off, state_.aif.data + off);
    });
    DepthResult r;
    r.depth_um = state_.best;      // CV_32F, now holding depth_um
    r.confidence = state_.sum_idx;  // CV_32F, now holding the confidence
    r.all_in_focus = state_.aif;
    r.frame_count = n;
    r.valid_fraction = double(valid.load()) / double(size_.area());
    state_ = {};  // the result owns its three buffers; the rest of the state is freed
    return r;
  }

  int frames_pushed() const override { return int(z_.size()); }
  size_t state_bytes() const override { return state_.Bytes(); }

 private:
  // Frames z_.size() - pending_.size() .. z_.size() - 1 over the state, tile by tile.
  void ProcessPending() {
    if (pending_.empty()) return;
    const int k1 = int(z_.size()), k0 = k1 - int(pending_.size());
    const int tiles_x = (size_.width + kTileW - 1) / kTileW, tiles_y = (size_.height + kBatchTileH - 1) / kBatchTileH;
    const size_t slot_stride = size_t(kBatchTileH) * kTileW;
    ParallelFor(tiles_x * tiles_y, threads_, [&](int t, int worker) {
      const int x0 = (t % tiles_x) * kTileW, y0 = (t / tiles_x) * kBatchTileH;
      const int tw = std::min(kTileW, size_.width - x0), th = std::min(kBatchTileH, size_.height - y0);
      TenengradScratch& sc = scratch_[size_t(worker)];
      int32_t* vol = volumes_[size_t(worker)].data();
      for (int k = k0; k < k1; ++k) {
        const int slot = k - k0;
        const cv::Mat* next = slot + 1 < int(pending_.size()) ? &pending_[size_t(slot) + 1] : nullptr;
        if (state_.avx2) FocusRowsToVolumeAvx2(pending_[size_t(slot)], slot, x0, y0, tw, th, options_.window_px, sc, vol, next);
        else FocusRowsToVolumePortable(pending_[size_t(slot)], slot, x0, y0, tw, th, options_.window_px, sc, vol, next);
      }
      for (int y = 0; y < th; ++y) {
        const uint8_t* pix_rows[kFrameChunk];
        for (int k = k0; k < k1; ++k) pix_rows[k - k0] = pending_[size_t(k - k0)].ptr<uint8_t>(y0 + y) + x0;
        // The next row's state is a whole frame row of planes away: the hardware prefetcher
        // follows the planes within a row but not that jump.
        if (y + 1 < th) PrefetchCompactRow(state_.Row(size_t(y0 + y + 1) * size_.width + x0), tw);
        UpdateCompactRow(state_, size_t(y0 + y) * size_.width + x0, tw, k0, k1, k0, vol + size_t(y) * kTileW,
                         slot_stride, pix_rows);
      }
    });
    pending_.clear();
  }

  SffOptions options_;
  cv::Size size_;
  int threads_ = 1;
  bool finished_ = false;
  std::vector<double> z_;
  CompactState state_;
  std::vector<TenengradScratch> scratch_;
  std::vector<std::vector<int32_t>> volumes_;  // per worker: focus rows of one tile x kFrameChunk frames
  std::vector<cv::Mat> pending_;              // frames of the open chunk
};

Status CheckCreate(const SffOptions& options, cv::Size frame_size, int frame_type) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (frame_size.width < 3 || frame_size.height < 3) return Status::InvalidArgument("frame size must be at least 3x3");
  if (frame_type != CV_8UC1 && frame_type != CV_16UC1) {
    return Status::InvalidArgument("frames must be 8- or 16-bit single-channel");
  }
  return Status::Ok();
}

bool UseFused(const SffOptions& o, int frame_type) {
  return frame_type == CV_8UC1 && o.focus_measure == FocusMeasure::kTenengrad;
}

bool UseCompact(const SffOptions& o, int frame_type) {
  return UseFused(o, frame_type) && o.interpolation != DepthInterpolation::kLineFit;
}

}  // namespace

StatusOr<std::unique_ptr<SffEngine>> SffEngine::Create(const SffOptions& options, cv::Size frame_size,
                                                       int frame_type) {
  INSPECT_RETURN_IF_ERROR(CheckCreate(options, frame_size, frame_type));
  if (UseCompact(options, frame_type)) return std::unique_ptr<SffEngine>(new CompactEngine(options, frame_size));
  if (UseFused(options, frame_type)) {
    return std::unique_ptr<SffEngine>(new Engine<int32_t, uint8_t>(options, frame_size, frame_type));
  }
  if (frame_type == CV_8UC1) return std::unique_ptr<SffEngine>(new Engine<float, uint8_t>(options, frame_size, frame_type));
  return std::unique_ptr<SffEngine>(new Engine<float, uint16_t>(options, frame_size, frame_type));
}

StatusOr<DepthResult> SffEngine::ReconstructInMemory(const SffOptions& options, const std::vector<cv::Mat>& frames,
                                                     const std::vector<double>& z_um) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (frames.size() < 3) {
    return Status::InvalidArgument("stack has " + std::to_string(frames.size()) + " frames; at least 3 are needed");
  }
  if (z_um.size() != frames.size()) {
    return Status::InvalidArgument("z_um has " + std::to_string(z_um.size()) + " values for " +
                                   std::to_string(frames.size()) + " frames");
  }
  if (frames[0].empty()) return Status::InvalidArgument("frame 0: empty image");
  const cv::Size size = frames[0].size();
  const int type = frames[0].type();
  if (type != CV_8UC1 && type != CV_16UC1) {
    return Status::InvalidArgument("frame 0: frames must be 8- or 16-bit single-channel");
  }
  for (size_t k = 0; k < frames.size(); ++k) INSPECT_RETURN_IF_ERROR(CheckFrame(frames[k], int(k), size, type));
  for (size_t k = 0; k < z_um.size(); ++k) {
    if (!std::isfinite(z_um[k])) return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um is not finite");
  }
  INSPECT_RETURN_IF_ERROR(CheckMonotonicZ(z_um));
  INSPECT_RETURN_IF_ERROR(CheckCreate(options, size, type));
  if (frames.size() >= 65535) return Status::ResourceExhausted("more than 65535 frames");

  if (!UseFused(options, type)) {
    INSPECT_ASSIGN_OR_RETURN(auto engine, Create(options, size, type));
    for (size_t k = 0; k < frames.size(); ++k) INSPECT_RETURN_IF_ERROR(engine->PushFrame(frames[k], z_um[k]));
    return engine->Finish();
  }

  // Tiles across all frames: each worker keeps one tile's state, runs every frame over it, then
  // interpolates the tile; the same kernels as PushFrame, so the result is bit-identical.
  const int threads = ResolveThreads(options.threads);
  const bool compact = UseCompact(options, type);
  const int j = options.interpolation == DepthInterpolation::kLineFit ? options.linefit_half_width : 1;
  const int tiles_x = (size.width + kTileW - 1) / kTileW, tiles_y = (size.height + kBatchTileH - 1) / kBatchTileH;
  const int n_tiles = tiles_x * tiles_y;
  DepthOutputs out;
  out.depth.create(size, CV_32F);
  out.confidence.create(size, CV_32F);
  out.aif.create(size, type);
  const int workers = std::max(1, std::min(threads, n_tiles));
  std::vector<CompactState> compact_states(compact ? size_t(workers) : 0);
  std::vector<StatePlanes<int32_t, uint8_t>> states(compact ? 0 : size_t(workers));
  std::vector<TenengradScratch> scratch(static_cast<size_t>(workers));
  std::vector<std::vector<int32_t>> volumes(static_cast<size_t>(workers));
  for (int w = 0; w < workers; ++w) {
    if (compact) compact_states[size_t(w)].Allocate(kTileW, kBatchTileH, options.use_simd, options.use_avx512);
    else states[size_t(w)].Allocate(kTileW, kBatchTileH, j, options.use_simd);
    scratch[size_t(w)].Reserve(options.window_px);
    volumes[size_t(w)].resize(size_t(kTileW) * kBatchTileH * kFrameChunk);
  }
  const bool avx2 = options.use_simd && CpuHasAvx2();
  const int n = int(frames.size());
  const std::vector<float> zf(z_um.begin(), z_um.end());
  std::atomic<size_t> valid{0};
  ParallelFor(n_tiles, workers, [&](int t, int worker) {
    int32_t* vol = volumes[size_t(worker)].data();
    if (compact) compact_states[size_t(worker)].Reset();
    const int x0 = (t % tiles_x) * kTileW, y0 = (t / tiles_x) * kBatchTileH;
    const int tw = std::min(kTileW, size.width - x0), th = std::min(kBatchTileH, size.height - y0);
    for (int k0 = 0; k0 < n; k0 += kFrameChunk) {
      const int k1 = std::min(n, k0 + kFrameChunk);
      for (int k = k0; k < k1; ++k) {
        const cv::Mat* next = k + 1 < n ? &frames[size_t(k) + 1] : nullptr;
        if (avx2) FocusRowsToVolumeAvx2(frames[size_t(k)], k - k0, x0, y0, tw, th, options.window_px,
                                        scratch[size_t(worker)], vol, next);
        else FocusRowsToVolumePortable(frames[size_t(k)], k - k0, x0, y0, tw, th, options.window_px,
                                       scratch[size_t(worker)], vol, next);
      }
      // Each state row stays in L1 (compact state with AVX2 / AVX-512: in registers) while the
      // chunk's frames update it, in frame order.
      const size_t slot_stride = size_t(kBatchTileH) * kTileW;
      for (int y = 0; y < th; ++y) {
        const size_t off = size_t(y) * kTileW;
        const int32_t* vol_row = vol + size_t(y) * kTileW;
        const uint8_t* pix_rows[kFrameChunk];
        for (int k = k0; k < k1; ++k) pix_rows[k - k0] = frames[size_t(k)].ptr<uint8_t>(y0 + y) + x0;
        if (compact) {
          UpdateCompactRow(compact_states[size_t(worker)], off, tw, k0, k1, k0, vol_row, slot_stride, pix_rows);
        } else {
          for (int k = k0; k < k1; ++k) {
            UpdateRow(states[size_t(worker)], off, k, vol_row + size_t(k - k0) * slot_stride, pix_rows[k - k0], tw);
          }
        }
      }
    }
    size_t v = 0;
    for (int y = 0; y < th; ++y) {
      const size_t off = size_t(y) * kTileW;
      if (compact) {
        v += FinishCompactRow(compact_states[size_t(worker)], off, tw, zf, options,
                              out.depth.ptr<uint32_t>(y0 + y) + x0, out.confidence.ptr<uint32_t>(y0 + y) + x0,
                              out.aif.ptr<uint8_t>(y0 + y) + x0);
      } else {
        v += FinishExactSpan(states[size_t(worker)], off, tw, z_um, options, out, x0, y0 + y);
      }
    }
    valid += v;
  });
  DepthResult r;
  r.depth_um = out.depth;
  r.confidence = out.confidence;
  r.all_in_focus = out.aif;
  r.frame_count = int(frames.size());
  r.valid_fraction = double(valid.load()) / double(size.area());
  return r;
}

namespace {

struct CopySink {
  cv::Mat* out;
  int x0, tw;
  SFF_INLINE void operator()(int y, const int32_t* f, const uint8_t*) { std::copy_n(f, tw, out->ptr<int32_t>(y) + x0); }
};

template <bool kAvx2>
SFF_INLINE void TenengradMapImpl(const cv::Mat& frame, int window_px, cv::Mat* out) {
  TenengradScratch sc;
  sc.Reserve(window_px);
  for (int y0 = 0; y0 < frame.rows; y0 += kTileH) {
    for (int x0 = 0; x0 < frame.cols; x0 += kTileW) {
      const int tw = std::min(kTileW, frame.cols - x0), th = std::min(kTileH, frame.rows - y0);
      TenengradTile<kAvx2>(frame, x0, y0, tw, th, window_px, sc, CopySink{out, x0, tw});
    }
  }
}
__attribute__((target("avx2"))) void TenengradMapAvx2(const cv::Mat& frame, int window_px, cv::Mat* out) {
  TenengradMapImpl<true>(frame, window_px, out);
}
void TenengradMapPortable(const cv::Mat& frame, int window_px, cv::Mat* out) {
  TenengradMapImpl<false>(frame, window_px, out);
}

}  // namespace

Status ComputeTenengradU8(const cv::Mat& frame, int window_px, cv::Mat* focus, bool use_simd) {
  if (frame.empty() || frame.type() != CV_8UC1) return Status::InvalidArgument("frame must be CV_8UC1");
  if (window_px < 3 || window_px > 31 || window_px % 2 == 0) {
    return Status::InvalidArgument("window_px " + std::to_string(window_px) + " must be odd and between 3 and 31");
  }
  cv::Mat out(frame.size(), CV_32SC1);
  if (use_simd && CpuHasAvx2()) TenengradMapAvx2(frame, window_px, &out);
  else TenengradMapPortable(frame, window_px, &out);
  *focus = out;
  return Status::Ok();
}

StatusOr<DepthResult> ReconstructStack(const std::filesystem::path& dir, const SffOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  INSPECT_ASSIGN_OR_RETURN(StackManifest manifest, ReadStackManifest(dir));
  std::unique_ptr<SffEngine> engine;
  for (size_t k = 0; k < manifest.frames.size(); ++k) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, LoadStackFrame(dir, manifest, k));
    if (!engine) {
      INSPECT_ASSIGN_OR_RETURN(engine, SffEngine::Create(options, frame.size(), frame.type()));
    }
    Status st = engine->PushFrame(frame, manifest.frames[k].z_um);
    if (!st.ok()) return st.WithContext(manifest.frames[k].file + ": ");
  }
  if (!engine) return Status::InvalidArgument("stack.json: frames is empty");
  return engine->Finish();
}

}  // namespace inspection
