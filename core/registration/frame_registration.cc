// Similarity registration of two frames (core/registration/frame_registration.h): forward-additive
// Gauss-Newton on 4 geometric + 2 photometric parameters (gain, offset: the frames of a focus
// stack differ in contrast with defocus), coarse to fine, from a phase-correlation start.
#include "core/registration/frame_registration.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "core/registration/internal/gauss_newton_kernel.h"

namespace inspection {

cv::Matx23d FrameFromReference(const SimilarityTransform& t, cv::Point2d c) {
  const double a = t.scale * std::cos(t.rotation_rad), b = t.scale * std::sin(t.rotation_rad);
  // p' = c + [a -b; b a](p - c) + shift
  return cv::Matx23d(a, -b, c.x - a * c.x + b * c.y + t.shift_x_px,  //
                     b, a, c.y - b * c.x - a * c.y + t.shift_y_px);
}

SimilarityTransform SimilarityOf(const cv::Matx23d& m, cv::Point2d c) {
  const double a = 0.5 * (m(0, 0) + m(1, 1)), b = 0.5 * (m(1, 0) - m(0, 1));
  SimilarityTransform t;
  t.scale = std::hypot(a, b);
  t.rotation_rad = std::atan2(b, a);
  // The image of the centre minus the centre.
  t.shift_x_px = m(0, 0) * c.x + m(0, 1) * c.y + m(0, 2) - c.x;
  t.shift_y_px = m(1, 0) * c.x + m(1, 1) * c.y + m(1, 2) - c.y;
  return t;
}

cv::Matx23d Compose(const cv::Matx23d& a, const cv::Matx23d& b) {
  const cv::Matx33d A(a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2), 0, 0, 1);
  const cv::Matx33d B(b(0, 0), b(0, 1), b(0, 2), b(1, 0), b(1, 1), b(1, 2), 0, 0, 1);
  const cv::Matx33d C = A * B;
  return cv::Matx23d(C(0, 0), C(0, 1), C(0, 2), C(1, 0), C(1, 1), C(1, 2));
}

cv::Matx23d Invert(const cv::Matx23d& m) {
  cv::Matx23d inv;
  cv::invertAffineTransform(m, inv);
  return inv;
}

Status FrameRegistrationOptions::Validate() const {
  if (max_side_px < 32 || max_side_px > 8192) return Status::InvalidArgument("max_side_px must be in [32, 8192]");
  if (pyramid_levels < 1 || pyramid_levels > 5) return Status::InvalidArgument("pyramid_levels must be in [1, 5]");
  if (!(smoothing_sigma_px >= 0 && smoothing_sigma_px <= 10)) {
    return Status::InvalidArgument("smoothing_sigma_px must be in [0, 10]");
  }
  if (max_iterations < 1 || max_iterations > 1000)
    return Status::InvalidArgument("max_iterations must be in [1, 1000]");
  if (!(convergence_px > 0)) return Status::InvalidArgument("convergence_px must be > 0");
  if (!(min_correlation >= -1 && min_correlation < 1)) {
    return Status::InvalidArgument("min_correlation must be in [-1, 1)");
  }
  return Status::Ok();
}

namespace {

// Zero mean, unit standard deviation: the photometric parameters then start at gain 1, offset 0
// and the normal equations are well scaled whatever the bit depth.
cv::Mat Standardised(const cv::Mat& f) {
  cv::Scalar mean, sd;
  cv::meanStdDev(f, mean, sd);
  cv::Mat out;
  f.convertTo(out, CV_32F, 1.0 / std::max(sd[0], 1e-6), -mean[0] / std::max(sd[0], 1e-6));
  return out;
}

struct Level {
  cv::Mat reference, frame;  // CV_32FC1, standardised, smoothed
};

// Geometric parameters about the level's centre c: p' = c + (1 + a)(p - c) + b perp(p - c) + t,
// with a, b in units of 1 / half_side so that all four are in pixels at the image edge.
struct Params {
  double a = 0, b = 0, tx = 0, ty = 0, gain = 1, offset = 0;
};

cv::Matx23d MatrixOf(const Params& p, cv::Point2d c, double half_side) {
  const double s = 1.0 + p.a / half_side, r = p.b / half_side;
  return cv::Matx23d(s, -r, c.x - s * c.x + r * c.y + p.tx, r, s, c.y - r * c.x - s * c.y + p.ty);
}

struct IterationResult {
  bool solved = false;
  double step_px = 0;  // largest displacement the update causes at the level's border
  double correlation = 0;
  double valid_share = 0;
};

// One Gauss-Newton step; updates p. Residual r = gain * I(W(x)) + offset - T(x).
IterationResult Iterate(const Level& L, Params& p, bool use_simd) {
  const int w = L.reference.cols, h = L.reference.rows;
  const cv::Point2d c((w - 1) * 0.5, (h - 1) * 0.5);
  const double half = 0.5 * std::max(w, h);
  const cv::Matx23d m = MatrixOf(p, c, half);
  cv::Mat warped;
  cv::warpAffine(L.frame, warped, m, L.reference.size(), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_REPLICATE);
  // Normal equations, row by row, by the kernel for this CPU (the AVX2 one sums blocks of 8
  // pixels in float lanes).
  registration_internal::NormalSums sums;
  const registration_internal::GaussNewtonRowFn row_sums = registration_internal::PickGaussNewtonRow(use_simd);
  for (int y = 1; y < h - 1; ++y) {
    const float* wr = warped.ptr<float>(y);
    const float* up = warped.ptr<float>(y - 1);
    const float* dn = warped.ptr<float>(y + 1);
    const float* tr = L.reference.ptr<float>(y);
    const double v = (y - c.y) / half;
    // Only pixels whose source and its neighbours lie inside the frame. The source is affine in
    // x, so those pixels are one run [x0, x1] of the row: found from the bounds, then settled
    // with the exact per-pixel test at both ends (no test inside the run).
    auto inside = [&](int x) {
      const double sx = m(0, 0) * x + m(0, 1) * y + m(0, 2), sy = m(1, 0) * x + m(1, 1) * y + m(1, 2);
      return !(sx < 1.0 || sy < 1.0 || sx > w - 2.0 || sy > h - 2.0);
    };
    double lo = 1.0, hi = w - 2.0;
    for (int r = 0; r < 2; ++r) {
      const double a = m(r, 0), b = m(r, 1) * y + m(r, 2), top = (r == 0 ? w : h) - 2.0;
      if (a > 0) {
        lo = std::max(lo, (1.0 - b) / a), hi = std::min(hi, (top - b) / a);
      } else if (a < 0) {
        lo = std::max(lo, (top - b) / a), hi = std::min(hi, (1.0 - b) / a);
      } else if (b < 1.0 || b > top) {
        lo = 1.0, hi = 0.0;
      }
    }
    if (!(lo <= hi)) continue;
    int x0 = std::max(1, int(std::ceil(lo))), x1 = std::min(w - 2, int(std::floor(hi)));
    while (x0 <= x1 && !inside(x0)) ++x0;
    while (x0 > 1 && inside(x0 - 1)) --x0;
    while (x1 >= x0 && !inside(x1)) --x1;
    while (x1 < w - 2 && x1 >= x0 && inside(x1 + 1)) ++x1;
    row_sums({wr, up, dn, tr, x0, x1, c.x, half, v, p.gain, p.offset}, &sums);
  }
  const auto& hs = sums.hs;
  const auto& gs = sums.gs;
  const auto& s5 = sums.s5;
  const long n = sums.n;
  IterationResult out;
  out.valid_share = double(n) / std::max(1, (w - 2) * (h - 2));
  if (n < 64) return out;
  cv::Matx<double, 6, 6> H;
  cv::Matx<double, 6, 1> g;
  for (int i = 0; i < 6; ++i) {
    g(i) = gs[i];
    for (int k = 0; k < 6; ++k) H(i, k) = k >= i ? hs[i][k] : hs[k][i];
  }
  const double sw = s5[0], st = s5[1], sww = s5[2], stt = s5[3], swt = s5[4];
  const double cov = swt / n - (sw / n) * (st / n);
  const double vw = sww / n - (sw / n) * (sw / n), vt = stt / n - (st / n) * (st / n);
  out.correlation = vw > 0 && vt > 0 ? cov / std::sqrt(vw * vt) : 0.0;
  cv::Matx<double, 6, 1> d;
  if (!cv::solve(H, g, d, cv::DECOMP_CHOLESKY)) return out;
  for (int i = 0; i < 6; ++i)
    if (!std::isfinite(d(i))) return out;
  p.a -= d(0), p.b -= d(1), p.tx -= d(2), p.ty -= d(3), p.gain -= d(4), p.offset -= d(5);
  out.solved = true;
  out.step_px = std::abs(d(0)) + std::abs(d(1)) + std::hypot(d(2), d(3));
  return out;
}

}  // namespace

StatusOr<RegistrationPyramid> PrepareRegistration(const cv::Mat& frame, const FrameRegistrationOptions& o) {
  INSPECT_RETURN_IF_ERROR(o.Validate());
  const int t = frame.type();
  if (frame.empty() || (t != CV_8UC1 && t != CV_16UC1 && t != CV_32FC1)) {
    return Status::InvalidArgument("frames to register must be CV_8UC1, CV_16UC1 or CV_32FC1");
  }
  if (frame.cols < 32 || frame.rows < 32) {
    return Status::InvalidArgument("frames are " + std::to_string(frame.cols) + "x" + std::to_string(frame.rows) +
                                   " px; registration needs at least 32x32");
  }
  // Working size: the frame scaled so its longer side is at most max_side_px.
  const double shrink = std::min(1.0, double(o.max_side_px) / std::max(frame.cols, frame.rows));
  const cv::Size work(std::max(16, int(std::lround(frame.cols * shrink))),
                      std::max(16, int(std::lround(frame.rows * shrink))));
  RegistrationPyramid out;
  out.frame_size = frame.size();
  // An integer part of the shrink is done first on the frame as stored: cv::resize's exact k x k
  // area average of 8- or 16-bit pixels is several times cheaper than converting the whole frame
  // to float (most of a large frame's preparation time). Pixel centres stay aligned (block j
  // covers [jk, jk + k)); the fractional rest is averaged in float as before.
  int k = int(1.0 / shrink);
  while (k > 1 && (frame.cols % k != 0 || frame.rows % k != 0)) --k;
  cv::Mat source = frame;
  if (k > 1 && frame.depth() != CV_32F) {
    cv::resize(frame, source, cv::Size(frame.cols / k, frame.rows / k), 0, 0, cv::INTER_AREA);
  }
  cv::Mat f;
  cv::resize(Standardised(source), f, work, 0, 0, cv::INTER_AREA);
  for (int k = 0; k < o.pyramid_levels; ++k) {
    const cv::Size s(int(std::lround(work.width / std::pow(2.0, k))), int(std::lround(work.height / std::pow(2.0, k))));
    if (k > 0 && (s.width < 16 || s.height < 16)) break;
    cv::Mat level;
    cv::resize(f, level, s, 0, 0, cv::INTER_AREA);
    if (o.smoothing_sigma_px > 0) cv::GaussianBlur(level, level, cv::Size(), o.smoothing_sigma_px);
    out.levels.push_back(std::move(level));
  }
  return out;
}

StatusOr<FrameRegistration> RegisterFrame(const cv::Mat& reference, const cv::Mat& frame,
                                          const FrameRegistrationOptions& o) {
  INSPECT_RETURN_IF_ERROR(o.Validate());
  for (const cv::Mat* f : {&reference, &frame}) {
    const int t = f->type();
    if (f->empty() || (t != CV_8UC1 && t != CV_16UC1 && t != CV_32FC1)) {
      return Status::InvalidArgument("frames to register must be CV_8UC1, CV_16UC1 or CV_32FC1");
    }
  }
  if (reference.size() != frame.size()) return Status::InvalidArgument("frames to register differ in size");
  INSPECT_ASSIGN_OR_RETURN(RegistrationPyramid r, PrepareRegistration(reference, o));
  INSPECT_ASSIGN_OR_RETURN(RegistrationPyramid f, PrepareRegistration(frame, o));
  return RegisterPyramids(r, f, o);
}

StatusOr<FrameRegistration> RegisterPyramids(const RegistrationPyramid& ref_pyramid,
                                             const RegistrationPyramid& frame_pyramid,
                                             const FrameRegistrationOptions& o) {
  INSPECT_RETURN_IF_ERROR(o.Validate());
  if (ref_pyramid.frame_size != frame_pyramid.frame_size ||
      ref_pyramid.levels.size() != frame_pyramid.levels.size() || ref_pyramid.levels.empty()) {
    return Status::InvalidArgument("frames to register differ in size");
  }
  const cv::Size reference = ref_pyramid.frame_size;
  std::vector<Level> levels(ref_pyramid.levels.size());
  for (size_t k = 0; k < levels.size(); ++k) {
    if (ref_pyramid.levels[k].size() != frame_pyramid.levels[k].size()) {
      return Status::InvalidArgument("frames to register were prepared with different options");
    }
    levels[k].reference = ref_pyramid.levels[k];
    levels[k].frame = frame_pyramid.levels[k];
  }
  // The coarsest level is copied: cv::phaseCorrelate below multiplies its inputs by the window in
  // place when their size is already a DFT size (e.g. 128 x 96), and the prepared pyramids are
  // shared with the frames' other pair. The coarse iterations then see what they always saw.
  levels.back().reference = levels.back().reference.clone();
  levels.back().frame = levels.back().frame.clone();
  // Start: translation from phase correlation on the coarsest level (large drifts), else zero.
  Params p;
  {
    const Level& top = levels.back();
    cv::Mat window;
    cv::createHanningWindow(window, top.reference.size(), CV_32F);
    double response = 0;
    const cv::Point2d shift = cv::phaseCorrelate(top.reference, top.frame, window, &response);
    if (response > 0.05 && std::isfinite(shift.x) && std::isfinite(shift.y)) p.tx = shift.x, p.ty = shift.y;
  }
  FrameRegistration out;
  IterationResult last;
  for (int k = int(levels.size()) - 1; k >= 0; --k) {
    const Level& L = levels[size_t(k)];
    bool converged = false;
    for (int it = 0; it < o.max_iterations; ++it) {
      last = Iterate(L, p, o.use_simd);
      ++out.iterations;
      if (!last.solved) {
        return Status::FailedPrecondition(last.valid_share < 0.25
                                              ? "registration failed: the frames no longer overlap"
                                              : "registration failed: the frames have too little structure");
      }
      if (last.step_px < o.convergence_px) {
        converged = true;
        break;
      }
    }
    // Frames at different defocus leave a residual the steps can hover on at a few hundredths
    // of a pixel: that is converged for any use here; a step ten times the limit is not.
    if (k == 0 && !converged && last.step_px > 10 * o.convergence_px) {
      return Status::FailedPrecondition("registration did not converge in " + std::to_string(o.max_iterations) +
                                        " iterations (last update " + std::to_string(last.step_px) + " px)");
    }
    if (k > 0) {  // to the next finer level: a, b are size-free, the translation scales
      const Level& F = levels[size_t(k - 1)];
      const double fx = double(F.reference.cols) / L.reference.cols, fy = double(F.reference.rows) / L.reference.rows;
      const double ratio =
          0.5 * std::max(F.reference.cols, F.reference.rows) / (0.5 * std::max(L.reference.cols, L.reference.rows));
      p.tx *= fx, p.ty *= fy, p.a *= ratio, p.b *= ratio;
    }
  }
  // The correlation of the last evaluation at the finest level, before its update: that update
  // moved no corner by more than ten times convergence_px (checked above), which changes the NCC
  // of the aligned pair in its fourth decimal; a further evaluation only for it cost a quarter of
  // a registration.
  out.correlation = last.correlation;
  if (!(out.correlation >= o.min_correlation)) {
    return Status::FailedPrecondition("registration failed: correlation " + std::to_string(out.correlation) +
                                      " of the aligned frames is below " + std::to_string(o.min_correlation));
  }
  // Working level -> full frame: the centres coincide (resize keeps pixel centres aligned).
  const Level& L0 = levels[0];
  const cv::Point2d c0((L0.reference.cols - 1) * 0.5, (L0.reference.rows - 1) * 0.5);
  const SimilarityTransform w = SimilarityOf(MatrixOf(p, c0, 0.5 * std::max(L0.reference.cols, L0.reference.rows)), c0);
  out.transform = w;
  out.transform.shift_x_px = w.shift_x_px * double(reference.width) / L0.reference.cols;
  out.transform.shift_y_px = w.shift_y_px * double(reference.height) / L0.reference.rows;
  return out;
}

}  // namespace inspection
