// Storage of the compact SFF state, and the read-out of the exact state at Finish: depth
// interpolation (thesis 3.1.4, eq. 3.23-3.34) and confidence per pixel (core/sff/sff_state.h).
#include "core/sff/sff_state.h"

#include <limits>

#include "core/sff/depth_interpolation.h"

namespace inspection::sff_internal {

void CompactState::Allocate(int w, int h, bool use_simd, bool use_avx512) {
  avx2 = use_simd && CpuHasAvx2();
  avx512 = avx2 && use_avx512 && CpuHasAvx512();
  width = w;
  height = h;
  const size_t n = size_t(w) * h;
  best.create(h, w, CV_32F);
  sum_idx.create(h, w, CV_32F);
  aif.create(h, w, CV_8U);
  kept_idx.resize(n);
  for (auto* v : {&last, &last2, &before, &after, &pending}) v->resize(n);
  Reset();
}

void CompactState::Reset() {
  const size_t n = size_t(width) * height;
  std::fill_n(reinterpret_cast<int32_t*>(best.data), n, std::numeric_limits<int32_t>::min());
  std::fill_n(reinterpret_cast<uint32_t*>(sum_idx.data), n, 0u);
  std::fill_n(aif.data, n, uint8_t(0));
  std::fill(kept_idx.begin(), kept_idx.end(), 0u);
  for (auto* v : {&last, &last2, &before, &after, &pending}) std::fill(v->begin(), v->end(), uint16_t(0));
}

size_t CompactState::Bytes() const {
  return best.total() * best.elemSize() + sum_idx.total() * sum_idx.elemSize() + aif.total() * aif.elemSize() +
         kept_idx.size() * 4 + 2 * (last.size() + last2.size() + before.size() + after.size() + pending.size());
}

template <typename T, typename P>
size_t FinishExactSpan(const StatePlanes<T, P>& st, size_t off, int count, const std::vector<double>& z,
                       const SffOptions& o, DepthOutputs& out, int ox, int oy) {
  const int n = int(z.size());
  const int J = st.j;
  float* depth = out.depth.ptr<float>(oy) + ox;
  float* conf = out.confidence.ptr<float>(oy) + ox;
  P* aif = out.aif.ptr<P>(oy) + ox;
  size_t valid = 0;
  double zw[2 * kMaxJ + 1], fw[2 * kMaxJ + 1];
  for (int x = 0; x < count; ++x) {
    const size_t i = off + x;
    const uint32_t w = st.idx_aif[i];
    const int m = st.IndexOf(w);
    const int before = std::min(J, m), after = std::min(J, n - 1 - m);
    const double best = ToFloat(st.best[i]);
    zw[before] = z[m];
    fw[before] = best;
    for (int t = 1; t <= before; ++t) {
      zw[before - t] = z[m - t];
      fw[before - t] = ToFloat(st.before[t - 1][i]);
    }
    for (int t = 1; t <= after; ++t) {
      zw[before + t] = z[m + t];
      fw[before + t] = ToFloat(st.after[t - 1][i]);
    }
    FocusCurveSummary s;
    s.peak = best;
    s.mean = double(st.sum[i]) / n;
    // Second differences t_k, k = 2..n-1; those with m in {k-2, k-1, k} involve the maximum.
    const int excluded = std::max(0, std::min(n - 1, m + 2) - std::max(2, m) + 1);
    s.curvature_sq_sum = double(st.curv_all[i]) - double(st.curv_excl[i]);
    s.curvature_count = std::max(0, n - 2) - excluded;
    s.peak_at_end = m == 0 || m == n - 1;
    s.flank_terms = FlankTermCount(m, n);
    const float c = FocusConfidence(s);
    conf[x] = c;
    if (c >= o.min_confidence) {
      // Only kept pixels are interpolated (the logarithms are the costly part).
      double z_um;
      if (IsThreePointMethod(o.interpolation) && before == 1 && after == 1) {
        z_um = ThreePointPeakZ(o.interpolation, zw[0], zw[1], zw[2], fw[0], fw[1], fw[2]);
      } else {
        z_um = InterpolatePeak(o.interpolation, zw, fw, before, after).z_um;
      }
      depth[x] = float(z_um);
      ++valid;
    } else {
      depth[x] = std::numeric_limits<float>::quiet_NaN();
    }
    aif[x] = P(st.GreyOf(w));
  }
  return valid;
}

// The three exact-state cases: fused 8-bit Tenengrad (line fit), other measures on 8 and 16 bits.
template size_t FinishExactSpan(const StatePlanes<int32_t, uint8_t>&, size_t, int, const std::vector<double>&,
                                const SffOptions&, DepthOutputs&, int, int);
template size_t FinishExactSpan(const StatePlanes<float, uint8_t>&, size_t, int, const std::vector<double>&,
                                const SffOptions&, DepthOutputs&, int, int);
template size_t FinishExactSpan(const StatePlanes<float, uint16_t>&, size_t, int, const std::vector<double>&,
                                const SffOptions&, DepthOutputs&, int, int);

}  // namespace inspection::sff_internal
