// Chain registration of an imported stack (core/registration/chain_registration.h).
#include "core/registration/chain_registration.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/registration/frame_registration.h"

namespace inspection {

Status ChainRegistrationOptions::Validate() const {
  if (max_side_px < 64) return Status::InvalidArgument("max_side_px must be >= 64");
  if (pyramid_levels < 1 || pyramid_levels > 5) return Status::InvalidArgument("pyramid_levels must be in 1..5");
  if (!(gradient_sigma_px >= 0)) return Status::InvalidArgument("gradient_sigma_px must be >= 0");
  if (max_iterations < 1) return Status::InvalidArgument("max_iterations must be >= 1");
  if (!(epsilon > 0)) return Status::InvalidArgument("epsilon must be > 0");
  if (!(min_correlation >= 0 && min_correlation < 1)) return Status::InvalidArgument("min_correlation must be in [0, 1)");
  if (!(still_false_positive_rate > 0 && still_false_positive_rate < 0.5)) {
    return Status::InvalidArgument("still_false_positive_rate must be in (0, 0.5)");
  }
  if (!(max_pair_outlier_px > 0)) return Status::InvalidArgument("max_pair_outlier_px must be > 0");
  if (!(min_motion_px >= 0)) return Status::InvalidArgument("min_motion_px must be >= 0");
  if (quick_max_side_px < 32) return Status::InvalidArgument("quick_max_side_px must be >= 32");
  if (quick_max_pairs < 3) return Status::InvalidArgument("quick_max_pairs must be >= 3");
  if (threads < 0) return Status::InvalidArgument("threads must be >= 0");
  if (refine_max_side_px < 64) return Status::InvalidArgument("refine_max_side_px must be >= 64");
  if (!(refine_min_correlation >= 0 && refine_min_correlation < 1)) {
    return Status::InvalidArgument("refine_min_correlation must be in [0, 1)");
  }
  if (!(refine_max_change_px > 0)) return Status::InvalidArgument("refine_max_change_px must be > 0");
  return Status::Ok();
}

double StudentTQuantile(double one_sided_alpha, int dof) {
  // Normal quantile (Acklam's rational approximation, |error| < 1.2e-9), then Cornish-Fisher.
  const double p = 1.0 - one_sided_alpha;
  static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
                             1.383577518672690e+02,  -3.066479806614716e+01, 2.506628277459239e+00};
  static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                             6.680131188771972e+01,  -1.328068155288572e+01};
  static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                             -2.549732539343734e+00, 4.374664141464968e+00,  2.938163982698783e+00};
  static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                             3.754408661907416e+00};
  double z;
  if (p > 0.97575) {
    const double q = std::sqrt(-2 * std::log(1 - p));
    z = -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
        ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  } else {
    const double q = p - 0.5, r = q * q;
    z = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
        (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
  }
  const double v = std::max(1, dof), z3 = z * z * z, z5 = z3 * z * z, z7 = z5 * z * z;
  return z + (z3 + z) / (4 * v) + (5 * z5 + 16 * z3 + 3 * z) / (96 * v * v) +
         (3 * z7 + 19 * z5 + 17 * z3 - 15 * z) / (384 * v * v * v);
}

namespace {

// A frame as its pairs register it: the registration image's pyramid (finest first), and the
// frame at the working size it was made from (for a second attempt on another image).
struct Pyramid {
  cv::Mat working;
  std::vector<cv::Mat> levels;
  bool empty() const { return levels.empty(); }
};

// The registration image (options.image) of the working-size frame, and its pyramid.
Pyramid PyramidOf(const cv::Mat& working, const ChainRegistrationOptions& o) {
  cv::Mat small;
  if (o.gradient_sigma_px > 0) {
    cv::GaussianBlur(working, small, cv::Size(), o.gradient_sigma_px);
  } else {
    small = working.clone();
  }
  using Image = ChainRegistrationOptions::Image;
  cv::Mat mag;
  if (o.image == Image::kGradient || o.image == Image::kNormalisedGradient) {
    cv::Mat gx, gy;
    cv::Sobel(small, gx, CV_32F, 1, 0);
    cv::Sobel(small, gy, CV_32F, 0, 1);
    cv::magnitude(gx, gy, mag);
  } else {
    mag = small;
  }
  if (o.image == Image::kNormalisedGradient) {
    cv::Mat local;
    cv::GaussianBlur(mag, local, cv::Size(), o.normalise_sigma_px);
    cv::Scalar mean = cv::mean(local);
    cv::divide(mag, local + 1e-3 * (mean[0] + 1e-6), mag);
  } else if (o.image == Image::kNormalisedIntensity) {
    cv::Mat mu, sq, var;
    cv::GaussianBlur(mag, mu, cv::Size(), o.normalise_sigma_px);
    cv::GaussianBlur(mag.mul(mag), sq, cv::Size(), o.normalise_sigma_px);
    var = sq - mu.mul(mu);
    cv::max(var, 0.0, var);
    cv::sqrt(var, var);
    cv::Scalar mean = cv::mean(var);
    cv::divide(mag - mu, var + 1e-2 * (mean[0] + 1e-6), mag);
  }
  Pyramid p;
  p.working = working;
  p.levels.push_back(mag);
  for (int k = 1; k < o.pyramid_levels && p.levels.back().cols >= 64 && p.levels.back().rows >= 64; ++k) {
    cv::Mat down;
    cv::pyrDown(p.levels.back(), down);
    p.levels.push_back(down);
  }
  return p;
}

// The frame shrunk by f (INTER_AREA), as float, and its pyramid.
Pyramid ShrunkPyramid(const cv::Mat& frame, double f, const ChainRegistrationOptions& o) {
  cv::Mat grey;
  frame.convertTo(grey, CV_32F);
  cv::Mat small;
  if (f < 1.0) {
    cv::resize(grey, small, cv::Size(), f, f, cv::INTER_AREA);
  } else {
    small = grey;
  }
  return PyramidOf(small, o);
}

cv::Matx23d Identity() { return cv::Matx23d(1, 0, 0, 0, 1, 0); }

// ECC from coarse to fine, started at `start` (finest-level coordinates): template = previous frame,
// input = this frame, so the warp maps previous-frame pixels to this frame's. border_px > 0
// (finest level, halved per level): template pixels that map within that many px of the input's
// edge do not count.
bool RegisterPair(const Pyramid& previous, const Pyramid& current, cv::Matx23d start,
                  const ChainRegistrationOptions& o, cv::Matx23d* out, double* correlation, int border_px = 0) {
  const int levels = int(std::min(previous.levels.size(), current.levels.size()));
  cv::Matx23d w = start;
  const double down = std::ldexp(1.0, -(levels - 1));
  w(0, 2) *= down;
  w(1, 2) *= down;
  double rho = 0;
  for (int k = levels - 1; k >= 0; --k) {
    cv::Mat warp(w, true);
    warp.convertTo(warp, CV_32F);
    cv::Mat mask;
    if (border_px > 0) {
      const cv::Size s = current.levels[size_t(k)].size();
      const int b = std::max(1, border_px >> k);
      mask = cv::Mat::zeros(s, CV_8U);
      if (s.width > 2 * b && s.height > 2 * b) mask(cv::Rect(b, b, s.width - 2 * b, s.height - 2 * b)).setTo(1);
    }
    try {
      rho = cv::findTransformECC(previous.levels[size_t(k)], current.levels[size_t(k)], warp, cv::MOTION_AFFINE,
                                 cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, o.max_iterations,
                                                  o.epsilon),
                                 mask, 1);  // an empty mask: every pixel
    } catch (const cv::Exception&) {
      return false;
    }
    cv::Mat wd;
    warp.convertTo(wd, CV_64F);
    w = cv::Matx23d(wd.ptr<double>());
    if (k > 0) {
      w(0, 2) *= 2;
      w(1, 2) *= 2;
    }
  }
  if (!std::isfinite(rho)) return false;
  *out = w;
  *correlation = rho;
  return true;
}

// Working-size transform -> full-resolution: x_w = f x + (f - 1) / 2 (INTER_AREA's pixel centres).
cv::Matx23d ToFullResolution(const cv::Matx23d& w, double f) {
  const double b = 0.5 * f - 0.5;
  const cv::Matx23d s(f, 0, b, 0, f, b);
  return Compose(Invert(s), Compose(w, s));
}

cv::Matx23d ToWorking(const cv::Matx23d& m, double f) {
  const double b = 0.5 * f - 0.5;
  const cv::Matx23d s(f, 0, b, 0, f, b);
  return Compose(s, Compose(m, Invert(s)));
}

std::array<double, 8> CornerDisplacement(const cv::Matx23d& m, cv::Size s) {
  std::array<double, 8> d{};
  int k = 0;
  for (cv::Point2d p : {cv::Point2d(0, 0), cv::Point2d(s.width - 1, 0), cv::Point2d(0, s.height - 1),
                        cv::Point2d(s.width - 1, s.height - 1)}) {
    const cv::Vec2d q = m * cv::Vec3d(p.x, p.y, 1);
    d[size_t(k++)] = q[0] - p.x;
    d[size_t(k++)] = q[1] - p.y;
  }
  return d;
}

double Median(std::vector<double> v) {
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + long(m), v.end());
  return v[m];
}

// One chain of frames (indices idx, in order) registered pair by pair at working factor f.
struct ChainPass {
  std::vector<cv::Matx23d> pair;   // full resolution, pair[j]: frame idx[j-1] -> idx[j] (pair[0] identity)
  std::vector<double> correlation;  // pair[0]: 1
  int failures = 0;
  std::string failed;  // "a->b (...)" of the failed pairs
};

std::string FrameSizeError(int i, cv::Size got, cv::Size want) {
  return "frame " + std::to_string(i) + " is " + std::to_string(got.width) + "x" + std::to_string(got.height) +
         ", frame 0 is " + std::to_string(want.width) + "x" + std::to_string(want.height) +
         ": a stack's frames must have one size";
}

// Registers pairs j in [begin, end) of idx (pair j: idx[j-1] -> idx[j]), each started from the
// previous pair's result (the run's first from the identity). `first` is idx[begin-1]'s pyramid
// when the caller has it (else it is loaded).
Status RunPairs(const std::function<StatusOr<cv::Mat>(int)>& load, const std::vector<int>& idx, size_t begin,
                size_t end, cv::Size size, double f, const ChainRegistrationOptions& o,
                Pyramid first, ChainPass* pass) {
  Pyramid previous = std::move(first);
  if (previous.empty()) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, load(idx[begin - 1]));
    if (frame.size() != size) return Status::InvalidArgument(FrameSizeError(idx[begin - 1], frame.size(), size));
    previous = ShrunkPyramid(frame, f, o);
  }
  cv::Matx23d start = Identity();  // working-size coordinates
  for (size_t j = begin; j < end; ++j) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, load(idx[j]));
    if (frame.channels() != 1) return Status::InvalidArgument("frame " + std::to_string(idx[j]) + " is not grey");
    if (frame.size() != size) return Status::InvalidArgument(FrameSizeError(idx[j], frame.size(), size));
    Pyramid current = ShrunkPyramid(frame, f, o);
    cv::Matx23d w;
    double rho = 0;
    bool ok = RegisterPair(previous, current, start, o, &w, &rho);
    if ((!ok || rho < o.min_correlation) && start != Identity()) {
      double rho_identity = 0;
      cv::Matx23d w_identity;
      if (RegisterPair(previous, current, Identity(), o, &w_identity, &rho_identity) &&
          rho_identity > (ok ? rho : -1.0)) {
        ok = true, w = w_identity, rho = rho_identity;
      }
    }
    if ((!ok || rho < o.min_correlation) && o.image != ChainRegistrationOptions::Image::kGradient) {
      // The contrast-normalised intensity's basin is narrower than the gradient magnitude's
      // (pairs 8 px apart at the working size do not converge): the gradient magnitude finds
      // the pair, the registration image refines it.
      ChainRegistrationOptions g = o;
      g.image = ChainRegistrationOptions::Image::kGradient;
      cv::Matx23d w_gradient;
      double rho_gradient = 0;
      if (RegisterPair(PyramidOf(previous.working, g), PyramidOf(current.working, g), Identity(), g, &w_gradient,
                       &rho_gradient) &&
          rho_gradient >= o.min_correlation) {
        cv::Matx23d w_refined;
        double rho_refined = 0;
        if (RegisterPair(previous, current, w_gradient, o, &w_refined, &rho_refined) &&
            rho_refined >= o.min_correlation) {
          ok = true, w = w_refined, rho = rho_refined;
        } else {
          ok = true, w = w_gradient, rho = rho_gradient;
        }
      }
    }
    if (!ok || rho < o.min_correlation) {
      pass->pair[j] = cv::Matx23d::zeros();  // marks the failure for RunChain
      pass->correlation[j] = ok ? rho : 0.0;
    } else {
      pass->pair[j] = ToFullResolution(w, f);
      pass->correlation[j] = rho;
      start = w;
    }
    previous = std::move(current);
  }
  return Status::Ok();
}

// The chain over idx at factor f with `levels` pyramid levels, cut into runs over threads.
Status RunChain(const std::function<StatusOr<cv::Mat>(int)>& load, const std::vector<int>& idx, cv::Size size,
                double f, const ChainRegistrationOptions& o, const Pyramid& first_pyramid,
                ChainPass* pass) {
  const size_t m = idx.size() - 1;
  pass->pair.assign(idx.size(), Identity());
  pass->correlation.assign(idx.size(), 1.0);
  int threads = o.threads == 0 ? std::max(1, cv::getNumberOfCPUs()) : o.threads;
  threads = int(std::min<size_t>(size_t(std::max(1, threads)), std::max<size_t>(1, m / 4)));  // runs of >= 4 pairs
  std::vector<ChainPass> parts(size_t(threads), *pass);
  std::vector<Status> status(size_t(threads), Status::Ok());
  auto run = [&](int t) {
    const size_t begin = 1 + m * size_t(t) / size_t(threads), end = 1 + m * size_t(t + 1) / size_t(threads);
    status[size_t(t)] = RunPairs(load, idx, begin, end, size, f, o, t == 0 ? first_pyramid : Pyramid(),
                                 &parts[size_t(t)]);
  };
  if (threads == 1) {
    run(0);
  } else {
    cv::parallel_for_(cv::Range(0, threads), [&](const cv::Range& r) {
      for (int t = r.start; t < r.end; ++t) run(t);
    }, threads);
  }
  for (int t = 0; t < threads; ++t) INSPECT_RETURN_IF_ERROR(status[size_t(t)]);
  for (int t = 0; t < threads; ++t) {
    const size_t begin = 1 + m * size_t(t) / size_t(threads), end = 1 + m * size_t(t + 1) / size_t(threads);
    for (size_t j = begin; j < end; ++j) {
      pass->pair[j] = parts[size_t(t)].pair[j];
      pass->correlation[j] = parts[size_t(t)].correlation[j];
      if (pass->pair[j] == cv::Matx23d::zeros()) {
        pass->pair[j] = Identity();
        ++pass->failures;
        if (pass->failed.size() < 200) {
          pass->failed += (pass->failed.empty() ? "" : ", ") + std::to_string(idx[j - 1]) + "->" +
                          std::to_string(idx[j]) +
                          (pass->correlation[j] > 0 ? " (correlation " + std::to_string(pass->correlation[j]).substr(0, 5) + ")"
                                                     : " (did not converge)");
        }
      }
    }
  }
  return Status::Ok();
}

// Pairs whose corner motion is far from the median pair's ("a->b, ..."; empty when none).
std::string Outliers(const std::vector<std::array<double, 8>>& d, const std::vector<int>& idx,
                     const ChainRegistrationOptions& o) {
  std::string outliers;
  const size_t m = d.size();
  for (int k = 0; k < 8; ++k) {
    std::vector<double> v;
    for (const auto& e : d) v.push_back(e[size_t(k)]);
    const double med = Median(v);
    std::vector<double> dev;
    for (double x : v) dev.push_back(std::abs(x - med));
    const double limit = o.max_pair_outlier_px + 6 * 1.4826 * Median(dev);
    for (size_t j = 0; j < m; ++j) {
      const std::string name = std::to_string(idx[j]) + "->" + std::to_string(idx[j + 1]);
      if (std::abs(v[j] - med) > limit && outliers.find(name) == std::string::npos && outliers.size() < 200) {
        outliers += (outliers.empty() ? "" : ", ") + name;
      }
    }
  }
  return outliers;
}

// Still test: is the mean pair motion distinguishable from zero given the pairs' spread? The
// pairs' noise from successive differences (von Neumann's mean square successive difference): a
// stack's motion varies smoothly from pair to pair (non-linear breathing), so the plain spread of
// the pairs would count that variation as noise and hide a moving stack.
double StillStatistic(const std::vector<std::array<double, 8>>& d) {
  const int m = int(d.size());
  double statistic = 0;
  for (int k = 0; k < 8; ++k) {
    double mean = 0, mssd = 0;
    for (const auto& e : d) mean += e[size_t(k)];
    mean /= m;
    for (int j = 1; j < m; ++j) mssd += std::pow(d[size_t(j)][size_t(k)] - d[size_t(j - 1)][size_t(k)], 2);
    const double sd = std::sqrt(mssd / (2.0 * std::max(1, m - 1)));
    const double se = sd / std::sqrt(double(m));
    const double t = se > 0 ? std::abs(mean) / se : (mean != 0 ? 1e9 : 0.0);
    statistic = std::max(statistic, t);
  }
  return statistic;
}

// Pair transforms of the chain over idx composed onto idx[ref]: idx[j]'s frame_from_reference.
std::vector<cv::Matx23d> Accumulate(const std::vector<cv::Matx23d>& pair, size_t ref) {
  std::vector<cv::Matx23d> out(pair.size(), Identity());
  for (size_t j = ref + 1; j < pair.size(); ++j) out[j] = Compose(pair[j], out[j - 1]);
  for (size_t j = ref; j-- > 0;) out[j] = Compose(Invert(pair[j + 1]), out[j + 1]);
  return out;
}

double MaxCorner(const std::vector<cv::Matx23d>& t, cv::Size size) {
  double worst = 0;
  for (const cv::Matx23d& m : t) {
    const auto c = CornerDisplacement(m, size);
    for (size_t k = 0; k < 8; k += 2) worst = std::max(worst, std::hypot(c[k], c[k + 1]));
  }
  return worst;
}

// Each frame but the reference registered directly against the reference at refine_max_side_px,
// started from r->frame_from_reference (the chain's): replaces the transforms that pass.
Status RefineToReference(const std::function<StatusOr<cv::Mat>(int)>& load, int n, cv::Size size,
                         const ChainRegistrationOptions& options, ChainRegistration* r) {
  ChainRegistrationOptions o = options;
  o.pyramid_levels = 1;
  const double f = std::min(1.0, double(options.refine_max_side_px) / std::max(size.width, size.height));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat reference_frame, load(r->reference_frame));
  const Pyramid reference = ShrunkPyramid(reference_frame, f, o);
  reference_frame.release();
  std::vector<cv::Matx23d> refined = r->frame_from_reference;
  std::vector<char> replaced(size_t(n), 0);
  std::vector<double> correlation(size_t(n), 0.0);
  correlation[size_t(r->reference_frame)] = 1.0;
  std::vector<Status> status(size_t(n), Status::Ok());
  auto refine = [&](int i) {
    if (i == r->reference_frame) return;
    StatusOr<cv::Mat> frame = load(i);
    if (!frame.ok()) {
      status[size_t(i)] = frame.status();
      return;
    }
    const Pyramid current = ShrunkPyramid(*frame, f, o);
    const cv::Matx23d chain = r->frame_from_reference[size_t(i)];
    cv::Matx23d w;
    double rho = 0;
    // The frame's own edge: its registration image's smoothing and local normalisation reach
    // ~3 sigma in from it, and frames far from the reference are shifted and scaled against it
    // by tens of px, so the edge bands do not coincide as a neighbour's do.
    const int border = int(std::ceil(3 * (o.gradient_sigma_px + o.normalise_sigma_px))) + 2;
    if (!RegisterPair(reference, current, ToWorking(chain, f), o, &w, &rho, border)) return;
    correlation[size_t(i)] = rho;
    if (rho < o.refine_min_correlation) return;
    const cv::Matx23d full = ToFullResolution(w, f);
    const std::array<double, 8> a = CornerDisplacement(full, size), b = CornerDisplacement(chain, size);
    for (size_t k = 0; k < 8; k += 2) {
      if (std::hypot(a[k] - b[k], a[k + 1] - b[k + 1]) > o.refine_max_change_px) return;
    }
    refined[size_t(i)] = full;
    replaced[size_t(i)] = 1;
  };
  const int threads = options.threads == 0 ? std::max(1, cv::getNumberOfCPUs()) : options.threads;
  if (threads == 1) {
    for (int i = 0; i < n; ++i) {
      refine(i);
      INSPECT_RETURN_IF_ERROR(status[size_t(i)]);
    }
  } else {
    cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& range) {
      for (int i = range.start; i < range.end; ++i) refine(i);
    }, threads);
    for (int i = 0; i < n; ++i) INSPECT_RETURN_IF_ERROR(status[size_t(i)]);
  }
  r->frame_from_reference = refined;
  r->refined_frames = int(std::count(replaced.begin(), replaced.end(), 1));
  r->refine_correlation = correlation;
  return Status::Ok();
}

}  // namespace

StatusOr<ChainRegistration> RegisterChain(const std::function<StatusOr<cv::Mat>(int)>& load, int n,
                                          const ChainRegistrationOptions& options, int* registered_pairs) {
  if (registered_pairs) *registered_pairs = 0;
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (n < 3) {
    return Status::InvalidArgument("alignment needs at least 3 frames to register a stack (got " + std::to_string(n) +
                                   ")");
  }
  ChainRegistration r;
  r.reference_frame = (n - 1) / 2;
  r.pair.assign(size_t(n), Identity());
  r.pair_correlation.assign(size_t(n), 1.0);
  INSPECT_ASSIGN_OR_RETURN(cv::Mat frame0, load(0));
  if (frame0.channels() != 1) return Status::InvalidArgument("frame 0 is not grey");
  const cv::Size size = frame0.size();
  if (size.width < 32 || size.height < 32) {
    return Status::InvalidArgument("alignment needs frames of at least 32x32 px (frame 0 is " +
                                   std::to_string(size.width) + "x" + std::to_string(size.height) + ")");
  }
  const double f = std::min(1.0, double(options.max_side_px) / std::max(size.width, size.height));
  const int m = n - 1;

  // Quick pass: sampled frames, smaller working size; its "still" is the answer.
  ChainRegistrationOptions quick = options;
  quick.pyramid_levels = std::max(1, options.pyramid_levels - 1);
  const double fq = std::min(f, double(options.quick_max_side_px) / std::max(size.width, size.height));
  const int stride = (m + options.quick_max_pairs - 1) / std::max(1, options.quick_max_pairs);
  if (options.quick_still_check && (stride > 1 || fq < f)) {
    std::vector<int> idx;
    for (int i = 0; i < n; i += stride) idx.push_back(i);
    if (idx.back() != n - 1) idx.push_back(n - 1);
    ChainPass pass;
    INSPECT_RETURN_IF_ERROR(RunChain(load, idx, size, fq, quick, ShrunkPyramid(frame0, fq, quick), &pass));
    if (pass.failures == 0 && idx.size() >= 4) {
      std::vector<std::array<double, 8>> d;
      for (size_t j = 1; j < idx.size(); ++j) d.push_back(CornerDisplacement(pass.pair[j], size));
      if (Outliers(d, idx, options).empty()) {
        const double statistic = StillStatistic(d);
        const double threshold = StudentTQuantile(options.still_false_positive_rate / 16.0, int(d.size()) - 1);
        // The sampled frame nearest the middle is the quick chain's reference.
        size_t ref = 0;
        for (size_t j = 0; j < idx.size(); ++j)
          if (std::abs(idx[j] - r.reference_frame) < std::abs(idx[ref] - r.reference_frame)) ref = j;
        const std::vector<cv::Matx23d> sampled = Accumulate(pass.pair, ref);
        const double corner = MaxCorner(sampled, size);
        // Only the floor decides here: the quick pass's few, noisier pairs give the t-test little
        // power, and a stack it cannot tell from still at several px of accumulated motion is
        // for the full chain to decide.
        if (corner < options.min_motion_px) {
          r.still = true;
          r.quick = true;
          r.quick_stride = stride;
          r.still_statistic = statistic;
          r.still_threshold = threshold;
          r.max_corner_displacement_px = corner;
          // Per frame: the sampled frames' transforms, interpolated between them.
          r.frame_from_reference.assign(size_t(n), Identity());
          for (size_t j = 0; j + 1 < idx.size(); ++j) {
            for (int i = idx[j]; i <= idx[j + 1]; ++i) {
              const double t = double(i - idx[j]) / double(idx[j + 1] - idx[j]);
              r.frame_from_reference[size_t(i)] = sampled[j] * (1 - t) + sampled[j + 1] * t;
            }
          }
          if (registered_pairs) *registered_pairs = m;
          return r;
        }
      }
    }
    r.quick_stride = stride;
  }

  std::vector<int> all(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) all[size_t(i)] = i;
  ChainPass pass;
  INSPECT_RETURN_IF_ERROR(RunChain(load, all, size, f, options, ShrunkPyramid(frame0, f, options), &pass));
  if (registered_pairs) *registered_pairs = m - pass.failures;
  if (pass.failures > 0) {
    return Status::FailedPrecondition("alignment could not register " + std::to_string(pass.failures) + " of " +
                                      std::to_string(m) + " neighbouring frame pairs: " + pass.failed +
                                      " (too featureless or unrelated; --alignment none reconstructs unaligned)");
  }
  r.pair = pass.pair;
  r.pair_correlation = pass.correlation;

  std::vector<std::array<double, 8>> d;
  for (int i = 1; i < n; ++i) d.push_back(CornerDisplacement(r.pair[size_t(i)], size));
  const std::string outliers = Outliers(d, all, options);
  if (!outliers.empty()) {
    return Status::FailedPrecondition("alignment: frame pairs " + outliers +
                                      " disagree with the rest of the chain (their motion is far from the other "
                                      "pairs'; a frame out of line or mis-registered)");
  }
  r.still_threshold = StudentTQuantile(options.still_false_positive_rate / 16.0, m - 1);
  r.still_statistic = StillStatistic(d);
  r.still = r.still_statistic < r.still_threshold;
  r.frame_from_reference = Accumulate(r.pair, size_t(r.reference_frame));
  r.max_corner_displacement_px = MaxCorner(r.frame_from_reference, size);
  if (r.max_corner_displacement_px < options.min_motion_px) r.still = true;
  if (!r.still && options.refine_to_reference) {
    INSPECT_RETURN_IF_ERROR(RefineToReference(load, n, size, options, &r));
    r.max_corner_displacement_px = MaxCorner(r.frame_from_reference, size);
  }
  return r;
}

}  // namespace inspection
