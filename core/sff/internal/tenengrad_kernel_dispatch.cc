// Run-time choice of the fused Tenengrad kernel's instruction set (core/sff/internal/tenengrad_kernel.h), and
// ComputeTenengradU8 (core/sff/focus_measure.h): thesis eq. 3.13-3.14 on the same kernel.
#include <string>

#include "core/util/cpu_features.h"
#include "core/sff/focus_measure.h"
#include "core/sff/internal/tenengrad_kernel.h"

namespace inspection {
namespace sff_internal {

using Portable = TenengradKernels<Isa::kPortable>;
using Avx2 = TenengradKernels<Isa::kAvx2>;
using Avx512 = TenengradKernels<Isa::kAvx512>;

void FusedTileFrame(const cv::Mat& frame, int k, int x0, int y0, int tw, int th, int window, TenengradScratch& sc,
                    StatePlanes<int32_t, uint8_t>& st, int sx, int sy, const cv::Mat* next) {
  if (st.simd)
    Avx2::FusedTileFrame(frame, k, x0, y0, tw, th, window, sc, st, sx, sy, next);
  else
    Portable::FusedTileFrame(frame, k, x0, y0, tw, th, window, sc, st, sx, sy, next);
}

void FocusRowsToVolume(bool avx2, const cv::Mat& frame, int slot, int x0, int y0, int tw, int th, int window,
                       TenengradScratch& sc, int32_t* vol, const cv::Mat* next) {
  if (avx2)
    Avx2::FocusRowsToVolume(frame, slot, x0, y0, tw, th, window, sc, vol, next);
  else
    Portable::FocusRowsToVolume(frame, slot, x0, y0, tw, th, window, sc, vol, next);
}

void UpdateExactRowFrames(StatePlanes<int32_t, uint8_t>& st, size_t off, int n, int k_begin, int k_end,
                          const int32_t* vol_row, size_t slot_stride, const uint8_t* const* pix_rows) {
  if (st.simd)
    Avx2::ExactRowFrames(st, off, n, k_begin, k_end, vol_row, slot_stride, pix_rows);
  else
    Portable::ExactRowFrames(st, off, n, k_begin, k_end, vol_row, slot_stride, pix_rows);
}

void UpdateExactRowsFromFocus(StatePlanes<float, uint8_t>& st, int k, const cv::Mat& focus, int focus_y0,
                              const cv::Mat& frame, int y_begin, int y_end) {
  if (st.simd)
    Avx2::ExactRowsFromFocus(st, k, focus, focus_y0, frame, y_begin, y_end);
  else
    Portable::ExactRowsFromFocus(st, k, focus, focus_y0, frame, y_begin, y_end);
}

void UpdateExactRowsFromFocus(StatePlanes<float, uint16_t>& st, int k, const cv::Mat& focus, int focus_y0,
                              const cv::Mat& frame, int y_begin, int y_end) {
  if (st.simd)
    Avx2::ExactRowsFromFocus(st, k, focus, focus_y0, frame, y_begin, y_end);
  else
    Portable::ExactRowsFromFocus(st, k, focus, focus_y0, frame, y_begin, y_end);
}

void UpdateCompactRow(CompactState& st, size_t off, int n, int k_begin, int k_end, int slot0, const int32_t* vol_row,
                      size_t slot_stride, const uint8_t* const* pix_rows) {
  const CompactPtrs s = st.Row(off);
  int x = 0;
  if (st.avx512 && n >= 16) {
    x = n & ~15;
    Avx512::UpdateCompact(s, 0, x, k_begin, k_end, slot0, vol_row, slot_stride, pix_rows);
  }
  if (st.avx2 && n - x >= 8) {
    const int x8 = x + ((n - x) & ~7);
    Avx2::UpdateCompact(s, x, x8, k_begin, k_end, slot0, vol_row, slot_stride, pix_rows);
    x = x8;
  }
  if (x < n) Portable::UpdateCompact(s, x, n, k_begin, k_end, slot0, vol_row, slot_stride, pix_rows);
}

size_t FinishCompactRow(CompactState& st, size_t off, int count, const std::vector<float>& zf, const SffOptions& o,
                        uint32_t* depth, uint32_t* conf, uint8_t* aif) {
  const CompactPtrs s = st.Row(off);
  const int n = int(zf.size());
  const float min_confidence = float(o.min_confidence);
  const int n8 = st.avx2 ? (count & ~7) : 0;
  size_t valid = 0;
  if (n8 > 0) valid = Avx2::FinishCompact(s, 0, n8, zf.data(), n, o.interpolation, min_confidence, depth, conf, aif);
  return valid + Portable::FinishCompact(s, n8, count, zf.data(), n, o.interpolation, min_confidence, depth, conf, aif);
}

}  // namespace sff_internal

Status ComputeTenengradU8(const cv::Mat& frame, int window_px, cv::Mat* focus, bool use_simd) {
  if (frame.empty() || frame.type() != CV_8UC1) return Status::InvalidArgument("frame must be CV_8UC1");
  if (window_px < 3 || window_px > 31 || window_px % 2 == 0) {
    return Status::InvalidArgument("window_px " + std::to_string(window_px) + " must be odd and between 3 and 31");
  }
  cv::Mat out(frame.size(), CV_32SC1);
  if (use_simd && CpuHasAvx2())
    sff_internal::Avx2::TenengradMap(frame, window_px, &out);
  else
    sff_internal::Portable::TenengradMap(frame, window_px, &out);
  *focus = out;
  return Status::Ok();
}

}  // namespace inspection
