// Focus-breathing model, its estimate from a stack, and the per-stack warp onto the reference
// frame's grid (core/registration/stack_alignment.h).
#include "core/registration/stack_alignment.h"

#include <algorithm>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "core/util/parallel_for.h"

namespace inspection {

const char* FrameAlignmentName(FrameAlignment a) {
  switch (a) {
    case FrameAlignment::kNone:
      return "none";
    case FrameAlignment::kEstimate:
      return "estimate";
    case FrameAlignment::kCalibrated:
      return "calibrated";
  }
  return "?";
}

StatusOr<FrameAlignment> ParseFrameAlignment(const std::string& name) {
  for (FrameAlignment a : {FrameAlignment::kNone, FrameAlignment::kEstimate, FrameAlignment::kCalibrated})
    if (name == FrameAlignmentName(a)) return a;
  return Status::InvalidArgument("alignment '" + name + "' is unknown (none, estimate, calibrated)");
}

SimilarityTransform FocusBreathingModel::At(double z_um) const {
  const double u = (z_um - reference_z_um) / 100.0;
  SimilarityTransform t;
  t.scale = 1.0 + scale_change_per_100um * u;
  t.rotation_rad = rotation_rad_per_100um * u;
  t.shift_x_px = shift_x_px_per_100um * u;
  t.shift_y_px = shift_y_px_per_100um * u;
  return t;
}

cv::Matx23d FocusBreathingModel::FrameFromReference(double z_um, double reference_frame_z_um) const {
  const cv::Point2d c = centre_px();
  return Compose(inspection::FrameFromReference(At(z_um), c),
                 Invert(inspection::FrameFromReference(At(reference_frame_z_um), c)));
}

Status FocusBreathingModel::Validate() const {
  if (frame_size.width < 32 || frame_size.height < 32) {
    return Status::InvalidArgument("frame_size must be at least 32x32 px");
  }
  const double values[] = {reference_z_um,       scale_change_per_100um, rotation_rad_per_100um,
                           shift_x_px_per_100um, shift_y_px_per_100um,   fit_rms_px};
  for (double v : values)
    if (!std::isfinite(v)) return Status::InvalidArgument("focus breathing model values must be finite");
  if (std::abs(scale_change_per_100um) > 0.5) {
    return Status::InvalidArgument("scale_change_per_100um must be within +-0.5 (50 % per 100 um)");
  }
  if (std::abs(rotation_rad_per_100um) > 0.2) {
    return Status::InvalidArgument("rotation_rad_per_100um must be within +-0.2");
  }
  return Status::Ok();
}

Status StackAlignmentOptions::Validate() const {
  INSPECT_RETURN_IF_ERROR(registration.Validate());
  if (!(max_failed_pair_share >= 0 && max_failed_pair_share < 1)) {
    return Status::InvalidArgument("max_failed_pair_share must be in [0, 1)");
  }
  if (!(max_pair_residual_px > 0)) return Status::InvalidArgument("max_pair_residual_px must be > 0");
  if (threads < 0) return Status::InvalidArgument("threads must be >= 0 (0 = all hardware threads)");
  if (max_pairs < 0 || max_pairs == 1) return Status::InvalidArgument("max_pairs must be 0 (all) or >= 2");
  if (!(min_motion_px >= 0.0)) return Status::InvalidArgument("min_motion_px must be >= 0");
  return Status::Ok();
}

namespace {

double Median(std::vector<double> v) {
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + long(m), v.end());
  if (v.size() % 2) return v[m];
  const double hi = v[m];
  return 0.5 * (hi + *std::max_element(v.begin(), v.begin() + long(m)));
}

// Whether each rate of the model differs from zero by more than its pairs' scatter allows: a
// two-sided Student t test of each median (scale, rotation, x and y shift per 100 um) at 1 % over
// the four (Bonferroni), the median's standard error 1.2533 * 1.4826 MAD / sqrt(n). A linear
// model's rates are constant, so a pair that departs from them is noise to the model, systematic
// or not: defocus makes the apparent scale of a still scene grow and then shrink as the focus
// passes through it (pairs' scale rates that change sign part-way through the stack), which moves
// the median a little off zero with a scatter many times larger; real breathing and drift keep
// one rate through the stack. A rate that is not significant is set to 0; what remains decides
// (StackAligner: still when it moves no frame corner by kNegligibleAlignmentPx). Fewer than 4
// pairs: no test (the rates as measured).
void TestRates(const std::vector<double>& ks, const std::vector<double>& kr, const std::vector<double>& kx,
               const std::vector<double>& ky, FocusBreathingModel* m) {
  const size_t n = ks.size();
  m->still_statistic = m->still_threshold = 0.0;
  if (n < 4) return;
  const boost::math::students_t dist(double(n - 1));
  const double threshold = boost::math::quantile(boost::math::complement(dist, 0.01 / (2.0 * 4.0)));
  double worst = 0.0;
  auto test = [&](const std::vector<double>& v, double* rate) {
    std::vector<double> dev;
    for (double x : v) dev.push_back(std::abs(x - *rate));
    const double se = 1.2533 * 1.4826 * Median(dev) / std::sqrt(double(n));
    const double t = se > 0 ? std::abs(*rate) / se : (*rate != 0.0 ? 1e9 : 0.0);
    worst = std::max(worst, t);
    if (t < threshold) *rate = 0.0;
  };
  test(ks, &m->scale_change_per_100um);
  test(kr, &m->rotation_rad_per_100um);
  test(kx, &m->shift_x_px_per_100um);
  test(ky, &m->shift_y_px_per_100um);
  m->still_statistic = worst;
  m->still_threshold = threshold;
}

// RMS distance between two maps of the frame's corners.
double CornerRms(const cv::Matx23d& a, const cv::Matx23d& b, cv::Size s) {
  double sum = 0;
  for (cv::Point2d p : {cv::Point2d(0, 0), cv::Point2d(s.width - 1, 0), cv::Point2d(0, s.height - 1),
                        cv::Point2d(s.width - 1, s.height - 1)}) {
    const cv::Vec3d q(p.x, p.y, 1.0);
    const cv::Vec2d d = a * q - b * q;
    sum += d.dot(d);
  }
  return std::sqrt(sum / 4);
}

// The estimate on a chain of the stack's frames: chain[j] is a frame index, load and z_um are the
// stack's. Pair j is (chain[j - 1], chain[j]).
StatusOr<FocusBreathingModel> EstimateOnChain(const std::function<StatusOr<cv::Mat>(int)>& stack_load,
                                              const std::vector<double>& stack_z_um, const std::vector<int>& chain,
                                              const StackAlignmentOptions& options) {
  const int n = int(chain.size());
  auto load = [&](int j) { return stack_load(chain[size_t(j)]); };
  std::vector<double> z_um(size_t(n), 0.0);
  for (int j = 0; j < n; ++j) z_um[size_t(j)] = stack_z_um[size_t(chain[size_t(j)])];
  auto PairName = [&](int j) {
    return std::to_string(chain[size_t(j - 1)]) + "->" + std::to_string(chain[size_t(j)]);
  };
  // Registration of each frame to its predecessor: p_i = pair[i](p_{i-1}).
  std::vector<SimilarityTransform> pair_t(static_cast<size_t>(n));
  std::vector<bool> ok(static_cast<size_t>(n), false);
  std::string failures;
  int failed = 0;
  cv::Size size;
  // Takes pair i's registration: its transform, or a counted failure (bad input is returned).
  auto take = [&](int i, const StatusOr<FrameRegistration>& r) -> Status {
    if (r.ok()) {
      pair_t[size_t(i)] = r->transform;
      ok[size_t(i)] = true;
      return Status::Ok();
    }
    if (r.status().code() == StatusCode::kInvalidArgument) return r.status();
    ++failed;
    if (failures.size() < 200) failures += (failures.empty() ? "" : "; ") + PairName(i) + ": " + r.status().message();
    return Status::Ok();
  };
  // Each frame's working images are prepared once and serve both of its pairs.
  // Concurrent pairs: the pairs are cut into one run of neighbours per thread, each run
  // registered in order on its own thread (a run's first frame is prepared twice), then taken in
  // order below exactly as the sequential loop takes them (same errors, failures and model).
  std::vector<std::optional<StatusOr<FrameRegistration>>> registered;
  if (options.threads != 1) {
    registered.resize(size_t(n));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat first, load(0));
    const int runs = std::min(n - 1, ResolveThreads(options.threads));
    if (first.cols >= 32 && first.rows >= 32) ParallelFor(runs, runs, [&](int run, int) {
      const int begin = 1 + (n - 1) * run / runs, end = 1 + (n - 1) * (run + 1) / runs;  // pairs [begin, end)
      std::optional<RegistrationPyramid> previous_pyramid;
      for (int i = begin; i < end; ++i) {
        if (!previous_pyramid) {
          StatusOr<cv::Mat> a = i == 1 ? StatusOr<cv::Mat>(first) : load(i - 1);
          if (!a.ok() || a->size() != first.size()) return;  // the loop below reports it
          StatusOr<RegistrationPyramid> pa = PrepareRegistration(*a, options.registration);
          if (!pa.ok()) {
            registered[size_t(i)] = pa.status();
            return;
          }
          previous_pyramid = std::move(pa).value();
        }
        StatusOr<cv::Mat> b = load(i);
        if (!b.ok() || b->size() != first.size()) return;  // the loop reports it
        StatusOr<RegistrationPyramid> pb = PrepareRegistration(*b, options.registration);
        if (!pb.ok()) {
          registered[size_t(i)] = pb.status();
          return;
        }
        registered[size_t(i)] = RegisterPyramids(*previous_pyramid, *pb, options.registration);
        previous_pyramid = std::move(pb).value();
      }
    });
  }
  std::optional<RegistrationPyramid> previous;
  for (int i = 0; i < n; ++i) {
    if (!registered.empty() && i > 0 && registered[size_t(i)]) {
      // Registered concurrently; frames i-1 and i loaded and of the first frame's size.
      INSPECT_RETURN_IF_ERROR(take(i, *registered[size_t(i)]));
      previous.reset();
      continue;
    }
    if (i > 0 && !previous) {
      INSPECT_ASSIGN_OR_RETURN(cv::Mat before, load(i - 1));  // after concurrent pairs
      INSPECT_ASSIGN_OR_RETURN(previous, PrepareRegistration(before, options.registration));
    }
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, load(i));
    if (i == 0) {
      size = frame.size();
      if (size.width < 32 || size.height < 32) {
        return Status::InvalidArgument("alignment needs frames of at least 32x32 px (frames are " +
                                       std::to_string(size.width) + "x" + std::to_string(size.height) + ")");
      }
    } else if (frame.size() != size) {
      return Status::InvalidArgument("frame " + std::to_string(chain[size_t(i)]) + " differs in size");
    }
    if (i == 0 && !registered.empty() && registered[1]) continue;  // pair 1 ran concurrently
    INSPECT_ASSIGN_OR_RETURN(RegistrationPyramid current, PrepareRegistration(frame, options.registration));
    if (i > 0) INSPECT_RETURN_IF_ERROR(take(i, RegisterPyramids(*previous, current, options.registration)));
    previous = std::move(current);
  }
  const int pairs = n - 1;
  if (pairs - failed < 2 || failed > options.max_failed_pair_share * pairs) {
    return Status::FailedPrecondition("alignment did not converge: " + std::to_string(failed) + " of " +
                                      std::to_string(pairs) + " neighbouring frame pairs could not be registered (" +
                                      failures + ")");
  }

  FocusBreathingModel m;
  m.reference_z_um = z_um.front();
  m.frame_size = size;
  m.frames = int(stack_z_um.size());
  const cv::Point2d c = m.centre_px();
  // Per pair, the change of each model quantity per 100 um. The pair's transform is
  // F(z_i) F(z_{i-1})^-1, so its scale is s_i / s_{i-1} and its shift d_i - A_i A_{i-1}^-1 d_{i-1}:
  // undoing that coupling needs the model itself, hence two passes (the second is exact to well
  // below the registration noise).
  std::vector<double> ks, kr, kx, ky;
  for (int pass = 0; pass < 2; ++pass) {
    ks.clear(), kr.clear(), kx.clear(), ky.clear();
    for (int i = 1; i < n; ++i) {
      if (!ok[size_t(i)]) continue;
      const double dz = (z_um[size_t(i)] - z_um[size_t(i - 1)]) / 100.0;
      if (dz == 0.0) continue;
      const SimilarityTransform prev = m.At(z_um[size_t(i - 1)]), cur = m.At(z_um[size_t(i)]);
      const SimilarityTransform& t = pair_t[size_t(i)];
      ks.push_back(prev.scale * (t.scale - 1.0) / dz);
      kr.push_back(t.rotation_rad / dz);
      // d_i - d_{i-1} = shift + (A_i A_{i-1}^-1 - I) d_{i-1}
      const double ratio = cur.scale / prev.scale, dr = cur.rotation_rad - prev.rotation_rad;
      const double a = ratio * std::cos(dr) - 1.0, b = ratio * std::sin(dr);
      kx.push_back((t.shift_x_px + a * prev.shift_x_px - b * prev.shift_y_px) / dz);
      ky.push_back((t.shift_y_px + b * prev.shift_x_px + a * prev.shift_y_px) / dz);
    }
    if (ks.size() < 2) return Status::FailedPrecondition("alignment needs frames at distinct z");
    m.scale_change_per_100um = Median(ks);
    m.rotation_rad_per_100um = Median(kr);
    m.shift_x_px_per_100um = Median(kx);
    m.shift_y_px_per_100um = Median(ky);
  }
  // Fit check, pair by pair: a pair whose measured transform disagrees with the model's by more
  // than max_pair_residual_px at the corners registered wrongly (e.g. a blurred edge taken for
  // structure). Its vote was outvoted by the medians; too many of them mean the stack does not
  // follow one model, and aligning with it would smear the depth map.
  double sum = 0;
  int agreeing = 0, disagreeing = 0;
  std::string worst;
  for (int i = 1; i < n; ++i) {
    if (!ok[size_t(i)]) continue;
    const double e = CornerRms(FrameFromReference(pair_t[size_t(i)], c),
                               m.FrameFromReference(z_um[size_t(i)], z_um[size_t(i - 1)]), size);
    if (e > options.max_pair_residual_px) {
      ++disagreeing;
      if (worst.size() < 120) worst += (worst.empty() ? "" : ", ") + PairName(i);
      continue;
    }
    sum += e * e;
    ++agreeing;
  }
  m.fit_rms_px = agreeing > 0 ? std::sqrt(sum / agreeing) : 0.0;
  m.measured_corner_px = ks.size() >= 4 ? MaxCornerDisplacementPx(m, stack_z_um) : 0.0;
  TestRates(ks, kr, kx, ky, &m);
  INSPECT_RETURN_IF_ERROR(m.Validate().WithContext("alignment: the estimated model is implausible"));
  if (agreeing < 2 || failed + disagreeing > options.max_failed_pair_share * pairs) {
    return Status::FailedPrecondition(
        "alignment did not converge: the frames do not follow one scale/drift model through z (" +
        std::to_string(failed) + " pairs failed to register, " + std::to_string(disagreeing) + " of " +
        std::to_string(pairs) + " disagree with the model by more than " +
        cv::format("%g", options.max_pair_residual_px) + " px: " + worst + ")");
  }
  return m;
}

}  // namespace

StatusOr<FocusBreathingModel> EstimateFocusBreathing(const std::function<StatusOr<cv::Mat>(int)>& load,
                                                     const std::vector<double>& z_um,
                                                     const StackAlignmentOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  const int n = int(z_um.size());
  if (n < 3) {
    return Status::InvalidArgument("alignment needs at least 3 frames to estimate scale and drift through z (got " +
                                   std::to_string(n) + ")");
  }
  // Long stacks: frames `stride` apart, and the last frame (see max_pairs).
  const int stride = options.max_pairs > 0 ? std::max(1, (n - 1 + options.max_pairs - 1) / options.max_pairs) : 1;
  std::vector<int> chain;
  for (int i = 0; i < n; i += stride) chain.push_back(i);
  if (chain.back() != n - 1) chain.push_back(n - 1);
  if (options.coarse_first && options.registration.max_side_px >= 64) {
    StackAlignmentOptions coarse = options;
    coarse.registration.max_side_px = options.registration.max_side_px / 2;
    coarse.registration.pyramid_levels = std::max(1, options.registration.pyramid_levels - 1);
    StatusOr<FocusBreathingModel> m = EstimateOnChain(load, z_um, chain, coarse);
    if (m.ok() && MaxCornerDisplacementPx(*m, z_um) < options.min_motion_px) return m;
    // Moving, or no answer at that size (errors included): the full estimate decides and words it.
  }
  return EstimateOnChain(load, z_um, chain, options);
}

double MaxCornerDisplacementPx(const FocusBreathingModel& model, const std::vector<double>& z_um) {
  if (z_um.empty()) return 0.0;
  const double z_ref = z_um[(z_um.size() - 1) / 2];
  const cv::Size s = model.frame_size;
  double worst = 0;
  for (double z : z_um) {
    const cv::Matx23d m = model.FrameFromReference(z, z_ref);
    for (cv::Vec3d p : {cv::Vec3d(0, 0, 1), cv::Vec3d(s.width - 1, 0, 1), cv::Vec3d(0, s.height - 1, 1),
                        cv::Vec3d(s.width - 1, s.height - 1, 1)}) {
      const cv::Vec2d q = m * p;
      worst = std::max(worst, std::hypot(q[0] - p[0], q[1] - p[1]));
    }
  }
  return worst;
}

StatusOr<StackAligner> StackAligner::Create(const FocusBreathingModel& model, FrameAlignment alignment,
                                            const std::vector<double>& z_um, cv::Size frame_size,
                                            double min_motion_px) {
  if (!(min_motion_px >= 0.0)) return Status::InvalidArgument("min_motion_px must be >= 0");
  INSPECT_RETURN_IF_ERROR(model.Validate());
  if (model.frame_size != frame_size) {
    return Status::FailedPrecondition("the focus-breathing model was measured on " +
                                      std::to_string(model.frame_size.width) + "x" +
                                      std::to_string(model.frame_size.height) + " frames; these are " +
                                      std::to_string(frame_size.width) + "x" + std::to_string(frame_size.height));
  }
  if (z_um.empty()) return Status::InvalidArgument("alignment needs the frames' z");
  const int n = int(z_um.size());
  const int ref = (n - 1) / 2;
  std::vector<cv::Matx23d> maps;
  for (int i = 0; i < n; ++i) maps.push_back(model.FrameFromReference(z_um[size_t(i)], z_um[size_t(ref)]));
  INSPECT_ASSIGN_OR_RETURN(StackAligner a, FromTransforms(maps, ref, alignment, frame_size,
                                                          MaxCornerDisplacementPx(model, z_um) >= min_motion_px));
  a.figures_.method = "model";
  a.figures_.still_statistic = model.still_statistic;
  a.figures_.still_threshold = model.still_threshold;
  a.figures_.max_corner_displacement_px =
      model.still_threshold > 0 ? model.measured_corner_px : MaxCornerDisplacementPx(model, z_um);
  return a;
}

StatusOr<StackAligner> StackAligner::FromTransforms(const std::vector<cv::Matx23d>& frame_from_reference,
                                                    int reference_frame, FrameAlignment alignment, cv::Size frame_size,
                                                    bool warps) {
  if (frame_from_reference.empty()) return Status::InvalidArgument("alignment needs the frames' transforms");
  if (frame_size.width < 1 || frame_size.height < 1) return Status::InvalidArgument("alignment needs a frame size");
  const int n = int(frame_from_reference.size());
  const int ref = reference_frame;
  StackAligner a;
  a.size_ = frame_size;
  a.figures_.alignment = alignment;
  a.figures_.reference_frame = ref;
  const cv::Point2d c((frame_size.width - 1) * 0.5, (frame_size.height - 1) * 0.5);
  // Per row, the x interval every frame sees (source inside [0, w-1] x [0, h-1]).
  std::vector<double> lo(size_t(frame_size.height), 0.0), hi(size_t(frame_size.height), frame_size.width - 1.0);
  const double w1 = frame_size.width - 1.0, h1 = frame_size.height - 1.0;
  for (int i = 0; i < n; ++i) {
    const cv::Matx23d m = frame_from_reference[size_t(i)];
    a.maps_.push_back(m);
    const SimilarityTransform t = SimilarityOf(m, c);
    a.figures_.max_scale_change_percent = std::max(a.figures_.max_scale_change_percent, 100 * std::abs(t.scale - 1));
    a.figures_.max_shift_px = std::max(a.figures_.max_shift_px, std::hypot(t.shift_x_px, t.shift_y_px));
    for (int y = 0; y < frame_size.height; ++y) {
      // s = m(k,0) x + m(k,1) y + m(k,2) within [0, limit] for k = 0 (x) and 1 (y).
      for (int k = 0; k < 2; ++k) {
        const double slope = m(k, 0), base = m(k, 1) * y + m(k, 2), limit = k == 0 ? w1 : h1;
        double& l = lo[size_t(y)];
        double& h = hi[size_t(y)];
        if (std::abs(slope) < 1e-12) {
          if (base < -1e-9 || base > limit + 1e-9) l = 1, h = 0;
          continue;
        }
        double x0 = (0 - base) / slope, x1 = (limit - base) / slope;
        if (x0 > x1) std::swap(x0, x1);
        l = std::max(l, x0 - 1e-9);
        h = std::min(h, x1 + 1e-9);
      }
    }
  }
  a.seen_ = cv::Mat(frame_size, CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < frame_size.height; ++y) {
    const int x0 = std::max(0, int(std::ceil(lo[size_t(y)]))),
              x1 = std::min(frame_size.width - 1, int(std::floor(hi[size_t(y)])));
    if (x1 >= x0) a.seen_.row(y).colRange(x0, x1 + 1).setTo(255);
  }
  a.figures_.seen_by_every_frame_percent = 100.0 * cv::countNonZero(a.seen_) / double(frame_size.area());
  a.warps_ = warps;
  a.figures_.still = !warps;
  a.figures_.frame_from_reference = a.maps_;
  a.figures_.frame_size = frame_size;
  if (!a.warps_) {
    a.seen_.setTo(255);
    a.figures_.seen_by_every_frame_percent = 100.0;
  }
  return a;
}

StatusOr<cv::Mat> StackAligner::Warp(const cv::Mat& frame, int index) const {
  if (index < 0 || index >= int(maps_.size())) {
    return Status::InvalidArgument("frame " + std::to_string(index) + " is beyond the " + std::to_string(maps_.size()) +
                                   " frames the alignment was set up for");
  }
  if (frame.size() != size_) return Status::InvalidArgument("frame " + std::to_string(index) + " differs in size");
  if (!warps_) return frame;
  cv::Mat out;
  cv::warpAffine(frame, out, maps_[size_t(index)], size_, cv::INTER_LANCZOS4 | cv::WARP_INVERSE_MAP,
                 cv::BORDER_REPLICATE);
  return out;
}

}  // namespace inspection
