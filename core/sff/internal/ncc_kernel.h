// Tile kernel of the correlation focus measure (thesis eq. 5.25-5.26), internal to
// core/sff/ncc_focus.cc: per tile of a frame, the NCC with the template and the focus value over U.
// Kept apart from the engine (state, maximum search, ISFF-FAST) so each reads as one thing.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/sff/ncc_focus.h"

namespace inspection::ncc_kernel {

inline int Reflect101(int p, int len) {
  if (len == 1) return 0;
  while (p < 0 || p >= len) p = p < 0 ? -p : 2 * len - 2 - p;
  return p;
}

// The template's side of eq. 5.25, fixed for the whole stack: the template padded by the patch
// half-width, and per pixel the patch sum and 1 / sqrt(n sum t^2 - (sum t)^2) (0 for a flat
// patch, whose NCC is defined as 0).
struct TemplateStats {
  int hc = 0;
  int n = 0;      // pixels per patch
  cv::Mat t_pad;  // CV_32FC1, (H + 2hc) x (W + 2hc), centred on its mean (NCC ignores offsets)
  cv::Mat t_sum;  // CV_32FC1, H x W
  cv::Mat t_inv;  // CV_32FC1, H x W
};

TemplateStats MakeTemplateStats(const cv::Mat& templ, int correlation_window_px);

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

// The focus values F of the tile T of `frame` and the mean NCC over U: the NCC (eq. 5.25) and
// C sigma_w on the region R = T grown by the U half-width (clipped to the image; U reflects the
// maps at the border), from patches that reflect the frame at the border. fm, nm: T.height x
// T.width, row-major. Any rectangle inside the frame works (ISFF-FAST passes the box of the
// pixels still searching): the patches read the frame around it.
void TileFocus(const cv::Mat& frame, const TemplateStats& ts, int hs, CorrelationFocusValue value, const cv::Rect& T,
               Scratch& s, float* fm, float* nm);

}  // namespace inspection::ncc_kernel
