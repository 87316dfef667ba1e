// chain-evaluate: the chain registration of imported stacks (core/registration/chain_registration.h)
//   chain-evaluate pcb <dir>      per-frame scale / shift on a real focus-rail stack beside an
//                                 independent full-resolution registration (ORB features + RANSAC
//                                 similarity, no ECC, no pyramid)
//   chain-evaluate still <count> [seed]  false-positive rate of the still test on still stacks of a
//                                 renderer of its own (band-limited noise surface, per-pixel
//                                 depth-dependent Gaussian defocus, sensor noise; no devices/sim code)
//   chain-evaluate drift <count> <px> [seed]  detection rate on the same renderer's stacks drifting px in total
//   chain-evaluate renderers <count> [seed]  the still test on still and moving stacks of four
//                                 renderers sharing no code: the simulated rig (devices/sim), the
//                                 natural-scene renderer (devices/sim/natural_scene), the lens
//                                 renderer (chain_lens_renderer.h) and the noise renderer above;
//                                 a table of stacks warped (false positives) and moving ones detected
//   chain-evaluate speed [frames] [width] [height]  what the alignment costs against the engine in
//                                 the same run: a still and a moving stack of the lens renderer,
//                                 reconstructed with alignment none and with the default estimate
//   chain-evaluate moving <count> [seed]  large motion against the truth: lens-renderer stacks with
//                                 5-20 % scale (non-linear), 50-300 px shift, up to 10 mrad rotation,
//                                 20-40 frames at 1600x1200 (CHAIN_MOVING_SIZE=WxH; the shift is
//                                 scaled with the width); per frame the chain's transform against the
//                                 truth, and the depth RMSE of the product path (--alignment estimate),
//                                 of an oracle warping with the true transforms and of no alignment
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <functional>
#include <memory>
#include <cstdio>
#include <filesystem>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "core/registration/chain_registration.h"
#include "core/registration/frame_registration.h"
#include "core/sff/depth_postprocess.h"
#include "core/sff/stack_reconstruct.h"
#include "devices/sim/natural_scene.h"
#include "devices/sim/simulated_rig.h"
#include "tests/bench/chain_lens_renderer.h"

using namespace inspection;

namespace {

// Still (or drifting) stack: a surface z(x, y) of smooth noise, texture of band-limited noise;
// frame k focused at z_k, each pixel blurred by sigma = |z - z_k| * 2.5 px (blend of 6 blur levels).
std::vector<cv::Mat> RenderStack(unsigned seed, int n, cv::Size size, double drift_px_total) {
  cv::RNG rng(seed);
  cv::Mat tex(size, CV_32F), height(size / 16, CV_32F);
  rng.fill(tex, cv::RNG::NORMAL, 0, 1);
  cv::GaussianBlur(tex, tex, cv::Size(), 1.2 + rng.uniform(0.0, 1.5));
  cv::normalize(tex, tex, 20 + rng.uniform(0, 40), 230 - rng.uniform(0, 40), cv::NORM_MINMAX);
  rng.fill(height, cv::RNG::UNIFORM, 0, 1);
  cv::resize(height, height, size, 0, 0, cv::INTER_CUBIC);
  cv::GaussianBlur(height, height, cv::Size(), 20);
  cv::normalize(height, height, 0, 1, cv::NORM_MINMAX);
  std::vector<cv::Mat> blurred;
  const double sig[] = {0, 0.8, 1.6, 2.4, 3.2, 4.0};
  for (double s : sig) {
    cv::Mat b;
    if (s == 0) b = tex.clone(); else cv::GaussianBlur(tex, b, cv::Size(), s);
    blurred.push_back(b);
  }
  std::vector<cv::Mat> frames;
  const double noise_sd = rng.uniform(0.5, 3.0);
  for (int k = 0; k < n; ++k) {
    const double zk = double(k) / (n - 1);
    cv::Mat f(size, CV_32F);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const double s = std::min(4.0, std::abs(height.at<float>(y, x) - zk) * 8.0) / 0.8;
        const int i = std::min(4, int(s));
        const double w = s - i;
        f.at<float>(y, x) = float((1 - w) * blurred[size_t(i)].at<float>(y, x) + w * blurred[size_t(i + 1)].at<float>(y, x));
      }
    if (drift_px_total != 0) {
      const double d = drift_px_total * zk;
      cv::warpAffine(f, f, cv::Matx23d(1, 0, d, 0, 1, 0.5 * d), size, cv::INTER_CUBIC | cv::WARP_INVERSE_MAP,
                     cv::BORDER_REFLECT_101);
    }
    cv::Mat noise(size, CV_32F);
    rng.fill(noise, cv::RNG::NORMAL, 0, noise_sd);
    cv::Mat out;
    cv::Mat(f + noise).convertTo(out, CV_8U);
    frames.push_back(out);
  }
  return frames;
}

ChainRegistrationOptions ChainOptionsFromEnvironment();

int Pcb(const std::string& dir) {
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().extension() == ".jpg" && e.path().filename().string().rfind("pcb_", 0) == 0) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::vector<cv::Mat> grey;
  for (const auto& f : files) grey.push_back(cv::imread(f.string(), cv::IMREAD_GRAYSCALE));
  const int n = int(grey.size());
  const auto t0 = std::chrono::steady_clock::now();
  auto r = RegisterChain([&](int i) -> StatusOr<cv::Mat> { return grey[size_t(i)]; }, n, ChainOptionsFromEnvironment());
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!r.ok()) {
    std::printf("chain failed: %s\n", r.status().ToString().c_str());
    return 1;
  }
  std::printf("chain: %d frames %dx%d, %.2f s, still=%d (statistic %.1f, threshold %.1f), max corner %.1f px\n", n,
              grey[0].cols, grey[0].rows, secs, int(r->still), r->still_statistic, r->still_threshold,
              r->max_corner_displacement_px);
  // Independent: ORB at full resolution, RANSAC similarity of each frame to the reference frame's
  // neighbour chain (pairs, accumulated the same way, so the comparison is per frame).
  auto orb = cv::ORB::create(8000);
  std::vector<std::vector<cv::KeyPoint>> kp(static_cast<size_t>(n));
  std::vector<cv::Mat> desc(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) orb->detectAndCompute(grey[size_t(i)], cv::noArray(), kp[size_t(i)], desc[size_t(i)]);
  cv::BFMatcher matcher(cv::NORM_HAMMING, true);
  std::vector<cv::Matx23d> pair(size_t(n), cv::Matx23d(1, 0, 0, 0, 1, 0));
  for (int i = 1; i < n; ++i) {
    std::vector<cv::DMatch> m;
    matcher.match(desc[size_t(i - 1)], desc[size_t(i)], m);
    std::vector<cv::Point2f> a, b;
    for (const auto& d : m) a.push_back(kp[size_t(i - 1)][size_t(d.queryIdx)].pt), b.push_back(kp[size_t(i)][size_t(d.trainIdx)].pt);
    std::vector<uchar> inl;
    cv::Mat h = cv::estimateAffinePartial2D(a, b, inl, cv::RANSAC, 1.0, 5000, 0.999, 50);
    // Refine on the inliers with least squares.
    std::vector<cv::Point2f> ai, bi;
    for (size_t k = 0; k < inl.size(); ++k) if (inl[k]) ai.push_back(a[k]), bi.push_back(b[k]);
    h = cv::estimateAffinePartial2D(ai, bi, cv::noArray(), cv::LMEDS);
    pair[size_t(i)] = cv::Matx23d(h.ptr<double>());
  }
  const int ref = r->reference_frame;
  std::vector<cv::Matx23d> ind(size_t(n), cv::Matx23d(1, 0, 0, 0, 1, 0));
  for (int i = ref + 1; i < n; ++i) ind[size_t(i)] = Compose(pair[size_t(i)], ind[size_t(i - 1)]);
  for (int i = ref - 1; i >= 0; --i) ind[size_t(i)] = Compose(Invert(pair[size_t(i + 1)]), ind[size_t(i + 1)]);
  const cv::Point2d c((grey[0].cols - 1) * 0.5, (grey[0].rows - 1) * 0.5);
  std::printf("frame  chain: scale  shift_x  shift_y  rot_mrad | ORB+RANSAC: scale  shift_x  shift_y | d_scale_%%  d_shift_px  ECC_corr\n");
  double worst_s = 0, worst_d = 0;
  for (int i = 0; i < n; ++i) {
    const SimilarityTransform a = SimilarityOf(r->frame_from_reference[size_t(i)], c), b = SimilarityOf(ind[size_t(i)], c);
    const double ds = 100 * std::abs(a.scale / b.scale - 1), dd = std::hypot(a.shift_x_px - b.shift_x_px, a.shift_y_px - b.shift_y_px);
    worst_s = std::max(worst_s, ds), worst_d = std::max(worst_d, dd);
    std::printf("%5d  %.5f %8.2f %8.2f %8.2f | %.5f %8.2f %8.2f | %8.3f %10.2f %8.3f\n", i, a.scale, a.shift_x_px,
                a.shift_y_px, 1e3 * a.rotation_rad, b.scale, b.shift_x_px, b.shift_y_px, ds, dd,
                r->pair_correlation[size_t(i)]);
  }
  std::printf("worst: %.3f %% scale, %.2f px shift\n", worst_s, worst_d);
  return 0;
}

int Rate(int count, double drift_px, unsigned seed_base) {
  int moving = 0, failed = 0;
  double seconds = 0, worst_stat = 0;
  for (int s = 0; s < count; ++s) {
    const unsigned seed = seed_base + unsigned(s);
    cv::RNG rng(seed * 7919u);
    const int n = 8 + rng.uniform(0, 33);
    const cv::Size size(320 + 32 * rng.uniform(0, 10), 240 + 24 * rng.uniform(0, 10));
    const std::vector<cv::Mat> frames = RenderStack(seed, n, size, drift_px);
    const auto t0 = std::chrono::steady_clock::now();
    auto r = RegisterChain([&](int i) -> StatusOr<cv::Mat> { return frames[size_t(i)]; }, n, {});
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!r.ok()) {
      ++failed;
      std::printf("seed %u: %s\n", seed, r.status().ToString().c_str());
      continue;
    }
    worst_stat = std::max(worst_stat, r->still_statistic / r->still_threshold);
    if (!r->still) ++moving;
    if (!r->still && drift_px == 0) std::printf("seed %u n %d: statistic %.1f threshold %.1f corner %.2f px\n", seed, n, r->still_statistic, r->still_threshold, r->max_corner_displacement_px);
  }
  std::printf("%d stacks (8-40 frames, 320-608 x 240-456 px), drift %.2f px: %d called moving (%.1f %%), %d failed, "
              "max statistic/threshold %.2f, %.3f s per stack\n",
              count, drift_px, moving, 100.0 * moving / count, failed, worst_stat, seconds / count);
  return 0;
}

// ---- renderers: false positives on still stacks and detection on moving ones, per renderer.

// Motion applied to a stack: total scale change, shift (x, y px) and rotation over the stack.
struct Motion {
  double scale = 0, sx = 0, sy = 0, rot = 0;
  bool any() const { return scale != 0 || sx != 0 || sy != 0 || rot != 0; }
};

// Frames resampled as a camera moving by `m` (non-linear in the frame index) would see them;
// for renderers without motion of their own (the noise already in the frames moves with them).
void Move(std::vector<cv::Mat>* frames, const Motion& m) {
  if (!m.any()) return;
  const int n = int(frames->size());
  const cv::Point2d c(((*frames)[0].cols - 1) * 0.5, ((*frames)[0].rows - 1) * 0.5);
  for (int k = 0; k < n; ++k) {
    const double u = double(k) / (n - 1);
    SimilarityTransform t;
    t.scale = 1 + m.scale * std::pow(u, 1.3);
    t.rotation_rad = m.rot * u;
    t.shift_x_px = m.sx * u;
    t.shift_y_px = m.sy * u;
    cv::Mat out;
    cv::warpAffine((*frames)[size_t(k)], out, FrameFromReference(t, c), (*frames)[size_t(k)].size(),
                   cv::INTER_CUBIC | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT_101);
    (*frames)[size_t(k)] = out;
  }
}

StatusOr<std::vector<cv::Mat>> RigStack(unsigned seed, const Motion& m) {
  cv::RNG rng(seed * 7919u + 3u);
  SimulatedRigOptions o;
  static const char* kSpecimens[] = {"skew5", "skew10", "step1um", "wedge", "chamfer", "cutter", "lens", "coin"};
  o.seed = seed;
  o.camera_size = cv::Size(320 + 32 * rng.uniform(0, 8), 240 + 24 * rng.uniform(0, 8));
  if (const char* e = std::getenv("CHAIN_RIG_NA")) o.numerical_aperture = std::atof(e);
  o.point_spread_imaging = std::getenv("CHAIN_SCATTER") != nullptr;  // each point spreads by its own defocus
  // Rig motion is its own: magnification and drift per 100 um of z (the scan's span is
  // 60..200 um, so scale/100 um = m.scale over ~100 um).
  o.focus_breathing_percent_per_100um = 100.0 * m.scale;
  o.lateral_drift_x_px_per_100um = m.sx;
  o.lateral_drift_y_px_per_100um = m.sy;
  std::unique_ptr<Rig> rig;
  for (int tries = 0; tries < 6; ++tries) {
    o.specimen = kSpecimens[(seed + unsigned(tries)) % 8];
    auto r = CreateSimulatedRig(o);
    if (r.ok()) {
      rig = std::move(r).value();
      if (std::getenv("CHAIN_VERBOSE")) std::printf("    specimen %s\n", o.specimen.c_str());
      break;
    }
  }
  if (!rig) return Status::Internal("no simulated specimen could be created");
  const ScanDefaults d = rig->scan_defaults();
  INSPECT_RETURN_IF_ERROR(rig->projector().ShowUniform(128));
  std::vector<cv::Mat> frames;
  for (double z = d.z_start_um; z <= d.z_end_um + 1e-9 && frames.size() < 60; z += d.z_step_um) {
    INSPECT_RETURN_IF_ERROR(rig->stage().MoveTo(z));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, rig->camera().Capture());
    frames.push_back(f);
  }
  return frames;
}

StatusOr<std::vector<cv::Mat>> NaturalStack(unsigned seed, const Motion& m) {
  cv::RNG rng(seed * 104729u + 5u);
  NaturalSceneOptions o;
  o.seed = seed;
  o.size = cv::Size(320 + 32 * rng.uniform(0, 8), 240 + 24 * rng.uniform(0, 8));
  o.frames = 8 + rng.uniform(0, 33);
  o.colour = false;
  INSPECT_ASSIGN_OR_RETURN(NaturalScene s, RenderNaturalScene(o));
  Move(&s.frames, m);
  return s.frames;
}

StatusOr<std::vector<cv::Mat>> LensStackOf(unsigned seed, const Motion& m) {
  cv::RNG rng(seed * 15485863u + 11u);
  chain_bench::LensStackOptions o;
  o.seed = seed;
  o.size = cv::Size(320 + 32 * rng.uniform(0, 10), 240 + 24 * rng.uniform(0, 10));
  o.frames = 8 + rng.uniform(0, 33);
  o.scale_total = m.scale;
  o.shift_x_total_px = m.sx;
  o.shift_y_total_px = m.sy;
  o.rotation_total_rad = m.rot;
  o.scatter = std::getenv("CHAIN_SCATTER") != nullptr;
  return chain_bench::RenderLensStack(o).frames;
}

StatusOr<std::vector<cv::Mat>> NoiseStack(unsigned seed, const Motion& m) {
  cv::RNG rng(seed * 7919u);
  const int n = 8 + rng.uniform(0, 33);
  const cv::Size size(320 + 32 * rng.uniform(0, 10), 240 + 24 * rng.uniform(0, 10));
  std::vector<cv::Mat> frames = RenderStack(seed, n, size, 0.0);
  Move(&frames, m);
  return frames;
}

// CHAIN_IMAGE = gradient | intensity | ngradient | nintensity, CHAIN_SIGMA, CHAIN_NORM_SIGMA:
// the registration's image, for comparing them on the same stacks.
ChainRegistrationOptions ChainOptionsFromEnvironment() {
  ChainRegistrationOptions o;
  if (const char* e = std::getenv("CHAIN_IMAGE")) {
    const std::string v = e;
    using Image = ChainRegistrationOptions::Image;
    o.image = v == "intensity" ? Image::kIntensity
              : v == "ngradient" ? Image::kNormalisedGradient
              : v == "nintensity" ? Image::kNormalisedIntensity
                                  : Image::kGradient;
  }
  if (const char* e = std::getenv("CHAIN_SIGMA")) o.gradient_sigma_px = std::atof(e);
  if (const char* e = std::getenv("CHAIN_NORM_SIGMA")) o.normalise_sigma_px = std::atof(e);
  if (const char* e = std::getenv("CHAIN_QUICK")) o.quick_still_check = std::atoi(e) != 0;
  if (const char* e = std::getenv("CHAIN_EPS")) o.epsilon = std::atof(e);
  if (const char* e = std::getenv("CHAIN_ITER")) o.max_iterations = std::atoi(e);
  if (const char* e = std::getenv("CHAIN_MAX_SIDE")) o.max_side_px = std::atoi(e);
  if (const char* e = std::getenv("CHAIN_LEVELS")) o.pyramid_levels = std::atoi(e);
  if (const char* e = std::getenv("CHAIN_REFINE")) o.refine_to_reference = std::atoi(e) != 0;
  if (const char* e = std::getenv("CHAIN_REFINE_SIDE")) o.refine_max_side_px = std::atoi(e);
  if (const char* e = std::getenv("CHAIN_REFINE_MIN_CORR")) o.refine_min_correlation = std::atof(e);
  return o;
}

struct Tally {
  int stacks = 0, moving = 0, failed = 0;
  int chained = 0;  // CHAIN_DEFAULT: stacks the default registered as a chain after the linear model
  double worst_ratio = 0, seconds = 0;
};

// CHAIN_DEFAULT=1: what the product's default (no --alignment) decides for an imported stack
// (stack.json without illumination, z nominal at 1 um a frame): the linear-in-z estimate first,
// the chain where that model does not fit (core/sff/stack_reconstruct.cc), through the same
// ReconstructStackFrames call the server makes. A warp (not still, not none) of a still stack
// counts as a false positive.
void DecideAsTheDefault(const std::vector<cv::Mat>& frames, const Motion& m, Tally* t, const char* name,
                        unsigned seed) {
  StackManifest manifest;
  for (size_t i = 0; i < frames.size(); ++i) manifest.frames.push_back({"f" + std::to_string(i), double(i), 0.0, ""});
  StackFrameSource source;
  source.frame = [&](int i) -> StatusOr<cv::Mat> { return frames[size_t(i)]; };
  StackFolderAlignment a;
  a.alignment = FrameAlignment::kEstimate;
  a.fall_back_to_none = true;
  a.options.threads = 0;
  const std::atomic<bool> cancel{false};
  AlignmentFigures figures;
  const auto t0 = std::chrono::steady_clock::now();
  auto r = ReconstructStackFrames(manifest, source, SffOptions{}, {}, cancel, a, &figures);
  t->seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!r.ok()) {
    ++t->failed;
    std::printf("  %s seed %u (%zu frames%s): default failed: %s\n", name, seed, frames.size(),
                m.any() ? ", moving" : ", still", r.status().ToString().c_str());
    return;
  }
  const bool warped = figures.alignment != FrameAlignment::kNone && !figures.still;
  if (warped) ++t->moving;
  if (figures.method == "chain") ++t->chained;
  if (warped && !m.any()) {
    std::printf("  %s seed %u (%zu frames): still stack warped by the default (method %s%s): scale %.3f %%, shift "
                "%.2f px, corner %.2f px\n",
                name, seed, frames.size(), figures.method.c_str(), figures.decision.empty() ? "" : ", after the linear model",
                figures.max_scale_change_percent, figures.max_shift_px, figures.max_corner_displacement_px);
    if (!figures.frame_from_reference.empty()) {  // the ends of the stack: what the model moves
      const cv::Point2d c((frames[0].cols - 1) * 0.5, (frames[0].rows - 1) * 0.5);
      const SimilarityTransform first = SimilarityOf(figures.frame_from_reference.front(), c),
                                last = SimilarityOf(figures.frame_from_reference.back(), c);
      std::printf("    statistic %.2f threshold %.2f; first frame scale %+.4f %% rotation %+.3f mrad shift %+.2f %+.2f px; "
                  "last frame scale %+.4f %% rotation %+.3f mrad shift %+.2f %+.2f px\n",
                  figures.still_statistic, figures.still_threshold, 100 * (first.scale - 1), 1e3 * first.rotation_rad,
                  first.shift_x_px, first.shift_y_px, 100 * (last.scale - 1), 1e3 * last.rotation_rad, last.shift_x_px,
                  last.shift_y_px);
    }
  }
  if (!warped && !figures.decision.empty() && std::getenv("CHAIN_VERBOSE")) std::printf("    why: %s\n", figures.decision.c_str());
  if (!warped && m.any()) {
    std::printf("  %s seed %u (%zu frames): moving stack not warped by the default (%s%s)\n", name, seed,
                frames.size(), figures.still ? "still" : "none", figures.fallback_reason.empty() ? "" : ": fell back");
  }
}

void Decide(const std::function<StatusOr<std::vector<cv::Mat>>(unsigned, const Motion&)>& render, unsigned seed,
            const Motion& m, Tally* t, const char* name) {
  auto frames = render(seed, m);
  ++t->stacks;
  if (!frames.ok()) {
    ++t->failed;
    std::printf("  %s seed %u: render failed: %s\n", name, seed, frames.status().ToString().c_str());
    return;
  }
  if (std::getenv("CHAIN_DEFAULT")) {  // the product's default for an imported stack instead of the chain alone
    DecideAsTheDefault(*frames, m, t, name, seed);
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  auto r = RegisterChain([&](int i) -> StatusOr<cv::Mat> { return (*frames)[size_t(i)]; }, int(frames->size()),
                         ChainOptionsFromEnvironment());
  t->seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!r.ok()) {
    ++t->failed;
    std::printf("  %s seed %u (%zu frames%s): %s\n", name, seed, frames->size(), m.any() ? ", moving" : ", still",
                r.status().ToString().c_str());
    return;
  }
  t->worst_ratio = std::max(t->worst_ratio, r->still_statistic / r->still_threshold);
  if (std::getenv("CHAIN_VERBOSE")) {  // per pair: scale change, shift of the centre, correlation
    const cv::Point2d c(((*frames)[0].cols - 1) * 0.5, ((*frames)[0].rows - 1) * 0.5);
    for (size_t i = 1; i < r->pair.size(); ++i) {
      const SimilarityTransform p = SimilarityOf(r->pair[i], c);
      std::printf("    pair %zu: scale %+.4f %% shift %+.3f %+.3f px corr %.3f\n", i, 100 * (p.scale - 1),
                  p.shift_x_px, p.shift_y_px, r->pair_correlation[i]);
    }
  }
  if (!r->still) ++t->moving;
  if (!r->still && !m.any()) {
    std::printf("  %s seed %u (%zu frames): still stack warped: statistic %.2f threshold %.2f corner %.2f px\n", name,
                seed, frames->size(), r->still_statistic, r->still_threshold, r->max_corner_displacement_px);
  }
  if (r->still && m.any()) {
    std::printf("  %s seed %u (%zu frames): moving stack called still: statistic %.2f threshold %.2f corner %.2f px\n",
                name, seed, frames->size(), r->still_statistic, r->still_threshold, r->max_corner_displacement_px);
  }
}

int Renderers(int count, unsigned seed_base) {
  struct Renderer {
    const char* name;
    std::function<StatusOr<std::vector<cv::Mat>>(unsigned, const Motion&)> render;
  };
  const std::vector<Renderer> renderers = {
      {"simulated rig", RigStack}, {"natural scene", NaturalStack}, {"lens (own)", LensStackOf}, {"noise (own)", NoiseStack}};
  // Small: a few px at the corners over the stack; typical: a focus rail's breathing and drift.
  // The rig's motion is per 100 um of z (its scans span ~60..200 um).
  const Motion small{0.002, 2.0, -1.0, 0.0}, typical{0.03, 30.0, -12.0, 0.002};
  std::printf("| renderer | still stacks | warped (false positive) | still failed | max statistic/threshold | "
              "small motion detected | typical motion detected | moving failed | s per stack |\n|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  std::vector<std::string> rows;
  const char* only = std::getenv("CHAIN_RENDERER");  // a substring of the renderer's name
  for (const Renderer& r : renderers) {
    if (only && std::string(r.name).find(only) == std::string::npos) continue;
    Tally still, little, big;
    for (int i = 0; i < count; ++i) {
      const unsigned seed = seed_base + unsigned(i);
      Decide(r.render, seed, Motion{}, &still, r.name);
      if (std::getenv("CHAIN_STILL_ONLY")) continue;
      Decide(r.render, seed, small, &little, r.name);
      Decide(r.render, seed, typical, &big, r.name);
    }
    char row[512];
    std::snprintf(row, sizeof row, "| %s | %d | %d (%.1f %%) | %d | %.2f | %d/%d | %d/%d | %d | %.2f |", r.name,
                  still.stacks, still.moving, 100.0 * still.moving / std::max(1, still.stacks), still.failed,
                  still.worst_ratio, little.moving, little.stacks, big.moving, big.stacks, little.failed + big.failed,
                  (still.seconds + little.seconds + big.seconds) / std::max(1, 3 * count));
    rows.push_back(row);
    std::printf("%s\n", row);
    if (std::getenv("CHAIN_DEFAULT")) {
      std::printf("  the default registered as a chain after the linear model: still %d, small %d, typical %d\n",
                  still.chained, little.chained, big.chained);
    }
    std::fflush(stdout);
  }
  std::printf("\nseeds %u..%u; small motion: scale 0.2 %%, shift (2, -1) px over the stack (rig: per 100 um of z); "
              "typical: scale 3 %%, shift (30, -12) px, rotation 2 mrad (rig: no rotation)\n",
              seed_base, seed_base + unsigned(count) - 1);
  for (const auto& row : rows) std::printf("%s\n", row.c_str());
  return 0;
}

// ---- speed: the alignment decision and the warp against the engine, same run.

int Speed(int n, cv::Size size) {
  std::printf("lens renderer, %d x %dx%d, 8-bit grey, frames in memory\n", n, size.width, size.height);
  std::printf("| stack | engine, alignment none (s) | default estimate (s) | chain registration alone (s) | extra | decision |\n|---|---|---|---|---|---|\n");
  for (int moving = 0; moving < 2; ++moving) {
    chain_bench::LensStackOptions o;
    o.size = size;
    o.frames = n;
    o.seed = 77;
    if (const char* e = std::getenv("CHAIN_SPEED_SEED")) o.seed = unsigned(std::atoi(e));  // e2e-bench's is 1
    o.scatter = std::getenv("CHAIN_SCATTER") != nullptr;
    if (moving) o.scale_total = 0.03, o.shift_x_total_px = 30, o.shift_y_total_px = -12;
    const chain_bench::LensStack s = chain_bench::RenderLensStack(o);
    StackManifest manifest;
    for (int i = 0; i < n; ++i) manifest.frames.push_back({"frame_" + std::to_string(i) + ".png", double(i), 0.0, ""});
    StackFrameSource source;
    source.frame = [&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; };
    const std::atomic<bool> cancel{false};
    SffOptions sff;
    StackFolderAlignment none, estimate;
    estimate.alignment = FrameAlignment::kEstimate;
    estimate.fall_back_to_none = true;
    estimate.options.threads = 0;  // as the server runs it on frames held in memory
    estimate.chain = ChainOptionsFromEnvironment();
    if (moving && std::getenv("CHAIN_SPEED_STILL_ONLY")) break;
    if (std::getenv("CHAIN_SPEED_CHAIN_ONLY")) {  // the chain's decision and time alone
      ChainRegistrationOptions chain = estimate.chain;
      chain.threads = 0;
      const auto t0 = std::chrono::steady_clock::now();
      auto c = RegisterChain([&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; }, n, chain);
      const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (!c.ok()) return 1;
      std::printf("chain alone %.3f s: still %d quick %d stride %d corner %.2f px\n", t, int(c->still), int(c->quick),
                  c->quick_stride, c->max_corner_displacement_px);
      continue;
    }
    double t_none = 1e9, t_est = 1e9, t_chain = 1e9;
    AlignmentFigures figures;
    for (int rep = 0; rep < 2; ++rep) {  // best of two, alternating
      auto t0 = std::chrono::steady_clock::now();
      auto a = ReconstructStackFrames(manifest, source, sff, {}, cancel, none, nullptr);
      t_none = std::min(t_none, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      t0 = std::chrono::steady_clock::now();
      auto b = ReconstructStackFrames(manifest, source, sff, {}, cancel, estimate, &figures);
      t_est = std::min(t_est, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      t0 = std::chrono::steady_clock::now();
      ChainRegistrationOptions chain = estimate.chain;
      chain.threads = 0;
      auto c = RegisterChain([&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; }, n, chain);
      t_chain = std::min(t_chain, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      if (!a.ok() || !b.ok() || !c.ok()) {
        std::printf("failed: %s %s %s\n", a.status().ToString().c_str(), b.status().ToString().c_str(),
                    c.status().ToString().c_str());
        return 1;
      }
    }
    std::printf("| %s | %.3f | %.3f | %.3f | %+.1f %% | %s, max scale change %.3f %%, max shift %.2f px |\n",
                moving ? "moving (3 %, 30/-12 px)" : "still", t_none, t_est, t_chain, 100.0 * (t_est - t_none) / t_none,
                figures.still ? "still" : (figures.alignment == FrameAlignment::kNone ? "none" : "warped"),
                figures.max_scale_change_percent, figures.max_shift_px);
    std::fflush(stdout);
  }
  return 0;
}


// ---- moving: large motion against the truth.

// Per frame: the recovered transform against the truth, about the image centre and at the corners.
struct TransformError {
  double scale_percent = 0, centre_px = 0, corner_px = 0;
};

TransformError ErrorOf(const cv::Matx23d& estimate, const cv::Matx23d& truth, cv::Size size) {
  const cv::Point2d c((size.width - 1) * 0.5, (size.height - 1) * 0.5);
  TransformError e;
  e.scale_percent = 100 * std::abs(SimilarityOf(estimate, c).scale / SimilarityOf(truth, c).scale - 1);
  auto at = [&](const cv::Matx23d& m, cv::Point2d p) { return m * cv::Vec3d(p.x, p.y, 1); };
  e.centre_px = cv::norm(at(estimate, c) - at(truth, c));
  for (cv::Point2d p : {cv::Point2d(0, 0), cv::Point2d(size.width - 1, 0), cv::Point2d(0, size.height - 1),
                        cv::Point2d(size.width - 1, size.height - 1)}) {
    e.corner_px = std::max(e.corner_px, cv::norm(at(estimate, p) - at(truth, p)));
  }
  return e;
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[size_t(std::min<double>(double(v.size() - 1), std::round(q * double(v.size() - 1))))];
}

int Moving(int count, unsigned seed_base) {
  cv::Size size(1600, 1200);
  if (const char* e = std::getenv("CHAIN_MOVING_SIZE")) std::sscanf(e, "%dx%d", &size.width, &size.height);
  const double shift_factor = size.width / 1600.0;  // 50-300 px at 1600 px wide
  // The product's path for an imported stack with an explicit --alignment estimate; the engine
  // unthresholded and the post-processing's defaults (dense off unless CHAIN_MOVING_DENSE=1:
  // the RMSE is then over measured pixels only), the same for all three.
  SffOptions sff;
  sff.min_confidence = 0.0;
  DepthPostProcessOptions post;
  post.min_confidence = SffOptions{}.min_confidence;
  post.dense = std::getenv("CHAIN_MOVING_DENSE") != nullptr && std::atoi(std::getenv("CHAIN_MOVING_DENSE")) != 0;
  std::printf("lens renderer, %dx%d, scale 5-20 %% (1 + s u^1.4), shift %.0f-%.0f px, rotation <= 10 mrad, 20-40 frames; "
              "post-processing dense %d\n",
              size.width, size.height, 50 * shift_factor, 300 * shift_factor, int(post.dense));
  std::printf("| seed | frames | scale %% | shift px | rot mrad | worst scale err %% | worst centre err px | worst corner err px | "
              "RMSE chain | RMSE oracle | RMSE none | chain/oracle | pixels %% (chain+oracle / +none) | product s |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  std::vector<double> all_scale, all_centre, all_corner, ratios;
  std::vector<double> seed_scale, seed_centre, seed_corner;
  std::vector<double> oracle_over_none, true_corners;  // oracle over none on the same pixels
  double sum_bc = 0, sum_c_same = 0, sum_abs_b = 0, sum_abs_c = 0;
  double sum_a = 0, sum_b = 0, sum_c = 0;
  int failed = 0, within = 0, ratio_ok = 0;
  for (int s = 0; s < count; ++s) {
    const unsigned seed = seed_base + unsigned(s);
    cv::RNG rng(seed * 49979687u + 23u);
    chain_bench::LensStackOptions o;
    o.seed = seed;
    o.size = size;
    o.frames = rng.uniform(20, 41);
    o.scale_total = rng.uniform(0.05, 0.20);
    const double shift = rng.uniform(50.0, 300.0) * shift_factor, direction = rng.uniform(0.0, 2 * CV_PI);
    o.shift_x_total_px = shift * std::cos(direction);
    o.shift_y_total_px = shift * std::sin(direction);
    o.rotation_total_rad = rng.uniform(-0.01, 0.01);
    o.scene_covers_motion = true;
    if (const char* e = std::getenv("CHAIN_MOVING_BLUR")) o.blur_px_per_frame = std::atof(e);  // diagnosis
    if (const char* e = std::getenv("CHAIN_MOVING_PRNU")) o.prnu = std::atof(e);  // diagnosis
    if (std::getenv("CHAIN_MOVING_STILL")) o.scale_total = o.shift_x_total_px = o.shift_y_total_px = o.rotation_total_rad = 0;
    // Small motion, for where warping starts to pay: the scale over the stack and the shift (px),
    // in the seed's direction, no rotation.
    if (const char* e = std::getenv("CHAIN_MOVING_SCALE")) o.scale_total = std::atof(e), o.rotation_total_rad = 0;
    if (const char* e = std::getenv("CHAIN_MOVING_SHIFT")) {
      o.shift_x_total_px = std::atof(e) * std::cos(direction), o.shift_y_total_px = std::atof(e) * std::sin(direction);
      o.rotation_total_rad = 0;
    }
    if (std::getenv("CHAIN_SCATTER")) o.scatter = true;
    const chain_bench::LensStack stack = chain_bench::RenderLensStack(o);
    const int n = int(stack.frames.size());
    StackManifest manifest;  // imported: no illumination, z nominal
    std::vector<double> z_um;
    for (int i = 0; i < n; ++i) {
      manifest.frames.push_back({"frame_" + std::to_string(i) + ".png", double(i), 0.0, ""});
      z_um.push_back(double(i));
    }
    const std::atomic<bool> cancel{false};
    StackFrameSource plain;
    plain.frame = [&](int i) -> StatusOr<cv::Mat> { return stack.frames[size_t(i)]; };
    auto finish = [&](StatusOr<DepthResult> raw) -> StatusOr<DepthResult> {
      if (!raw.ok()) return raw.status();
      return PostProcessDepth(*raw, z_um, sff.window_px, post);
    };
    // (a) the product: --alignment estimate on an imported stack (the chain).
    StackFolderAlignment estimate;
    estimate.alignment = FrameAlignment::kEstimate;
    estimate.fall_back_to_none = false;
    estimate.chain_for_imported_stacks = true;
    estimate.options.threads = 0;  // frames in memory, as the server's decoded path
    estimate.chain = ChainOptionsFromEnvironment();
    // (b) the oracle: the true transforms through the same aligner, engine and post-processing.
    StatusOr<StackAligner> truth = StackAligner::FromTransforms(stack.frame_from_reference, (n - 1) / 2,
                                                                FrameAlignment::kEstimate, size, true);
    if (!truth.ok()) return 1;
    StackFrameSource warped;
    warped.frame = [&](int i) -> StatusOr<cv::Mat> { return truth->Warp(stack.frames[size_t(i)], i); };
    StatusOr<DepthResult> b_raw = ReconstructStackFrames(manifest, warped, sff, {}, cancel, {}, nullptr);
    if (b_raw.ok()) MaskUnseenPixels(*truth, &*b_raw);
    StatusOr<DepthResult> b = finish(std::move(b_raw));
    // CHAIN_MOVING_ORACLE_ONLY=1: the oracle against none only (where warping starts to pay); the
    // product's columns then repeat the oracle's.
    AlignmentFigures figures;
    const bool oracle_only = std::getenv("CHAIN_MOVING_ORACLE_ONLY") != nullptr;
    const auto t0 = std::chrono::steady_clock::now();
    StatusOr<DepthResult> a =
        oracle_only ? b : finish(ReconstructStackFrames(manifest, plain, sff, {}, cancel, estimate, &figures));
    if (oracle_only) figures.frame_from_reference = stack.frame_from_reference;
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // (c) no alignment.
    StatusOr<DepthResult> c = finish(ReconstructStackFrames(manifest, plain, sff, {}, cancel, {}, nullptr));
    if (!a.ok() || !b.ok() || !c.ok()) {
      ++failed;
      std::printf("| %u | %d | %.1f | %.0f | %.1f | failed: %s / %s / %s |\n", seed, n, 100 * o.scale_total, shift,
                  1e3 * o.rotation_total_rad, a.status().ToString().c_str(), b.status().ToString().c_str(),
                  c.status().ToString().c_str());
      std::fflush(stdout);
      continue;
    }
    TransformError worst;
    // The motion itself: the true transforms' largest corner displacement from the middle frame.
    double true_corner_px = 0;
    for (int i = 0; i < n; ++i)
      true_corner_px = std::max(true_corner_px, ErrorOf(cv::Matx23d(1, 0, 0, 0, 1, 0), stack.frame_from_reference[size_t(i)], size).corner_px);
    for (int i = 0; i < n; ++i) {
      const cv::Matx23d est = figures.frame_from_reference.empty() ? cv::Matx23d(1, 0, 0, 0, 1, 0)
                                                                   : figures.frame_from_reference[size_t(i)];
      const TransformError e = ErrorOf(est, stack.frame_from_reference[size_t(i)], size);
      all_scale.push_back(e.scale_percent), all_centre.push_back(e.centre_px), all_corner.push_back(e.corner_px);
      worst.scale_percent = std::max(worst.scale_percent, e.scale_percent);
      worst.centre_px = std::max(worst.centre_px, e.centre_px);
      worst.corner_px = std::max(worst.corner_px, e.corner_px);
    }
    seed_scale.push_back(worst.scale_percent), seed_centre.push_back(worst.centre_px), seed_corner.push_back(worst.corner_px);
    if (worst.scale_percent <= 0.1 && worst.centre_px <= 0.5) ++within;
    // Pixels the true transforms say every frame saw, with a depth in the chain's and the
    // oracle's results (and, for none, in its result too: none leaves more pixels unmeasured).
    double se_a = 0, se_b = 0, se_c = 0;
    // The oracle and none on the same pixels (both have a depth): RMSE and mean |error|.
    double se_bc = 0, ae_bc = 0, ae_c = 0;
    long pixels = 0, pixels_c = 0;
    const cv::Mat& seen = truth->seen_by_every_frame();
    // CHAIN_MOVING_MARGIN=<px>: only pixels at least this far from the seen region's edge (all three).
    cv::Mat inner = seen;
    if (const char* e = std::getenv("CHAIN_MOVING_MARGIN")) {
      const int r = std::atoi(e);
      cv::Mat padded;
      cv::copyMakeBorder(seen, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(0));
      cv::erode(padded, padded, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * r + 1, 2 * r + 1)),
                cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
      inner = padded(cv::Rect(1, 1, size.width, size.height)).clone();
    }
    for (int y = 0; y < size.height; ++y) {
      const float *da = a->depth_um.ptr<float>(y), *db = b->depth_um.ptr<float>(y), *dc = c->depth_um.ptr<float>(y),
                  *dt = stack.depth_reference.ptr<float>(y);
      const uchar* m = inner.ptr<uchar>(y);
      for (int x = 0; x < size.width; ++x) {
        if (!m[x] || !std::isfinite(da[x]) || !std::isfinite(db[x])) continue;
        se_a += double(da[x] - dt[x]) * (da[x] - dt[x]);
        se_b += double(db[x] - dt[x]) * (db[x] - dt[x]);
        ++pixels;
        if (!std::isfinite(dc[x])) continue;
        se_c += double(dc[x] - dt[x]) * (dc[x] - dt[x]);
        se_bc += double(db[x] - dt[x]) * (db[x] - dt[x]);
        ae_bc += std::abs(double(db[x] - dt[x]));
        ae_c += std::abs(double(dc[x] - dt[x]));
        ++pixels_c;
      }
    }
    const double ra = std::sqrt(se_a / std::max(1L, pixels)), rb = std::sqrt(se_b / std::max(1L, pixels)),
                 rc = std::sqrt(se_c / std::max(1L, pixels_c));
    sum_a += ra, sum_b += rb, sum_c += rc;
    ratios.push_back(ra / rb);
    const double rbc = std::sqrt(se_bc / std::max(1L, pixels_c));
    oracle_over_none.push_back(rbc / rc);
    sum_bc += rbc, sum_c_same += rc, sum_abs_b += ae_bc / std::max(1L, pixels_c), sum_abs_c += ae_c / std::max(1L, pixels_c);
    true_corners.push_back(true_corner_px);
    std::printf("  seed %u: true corner motion %.3f px, on the same pixels oracle %.4f none %.4f (RMSE), %.4f %.4f (mean |error|), "
                "product %s\n", seed, true_corner_px, rbc, rc, ae_bc / std::max(1L, pixels_c), ae_c / std::max(1L, pixels_c),
                oracle_only ? "not run" : figures.still ? "still" : figures.alignment == FrameAlignment::kNone ? "none" : "warped");
    if (ra / rb <= 1.10) ++ratio_ok;
    std::printf("| %u | %d | %.1f | %.0f | %+.1f | %.3f | %.2f | %.2f | %.3f | %.3f | %.3f | %.3f | %.1f / %.1f | %.1f |\n",
                seed, n, 100 * o.scale_total, shift, 1e3 * o.rotation_total_rad, worst.scale_percent, worst.centre_px,
                worst.corner_px, ra, rb, rc, ra / rb, 100.0 * double(pixels) / double(size.area()),
                100.0 * double(pixels_c) / double(size.area()), seconds);
    if (std::getenv("CHAIN_VERBOSE")) {
      // The chain alone once more, for its refinement's figures (the product's result has none).
      auto r = RegisterChain([&](int i) -> StatusOr<cv::Mat> { return stack.frames[size_t(i)]; }, n, estimate.chain);
      if (r.ok()) {
        std::printf("    refined %d of %d frames; correlation:", r->refined_frames, n - 1);
        for (double v : r->refine_correlation) std::printf(" %.2f", v);
        std::printf("\n");
      }
      for (int i = 0; i < n; ++i) {
        const TransformError e = ErrorOf(figures.frame_from_reference[size_t(i)], stack.frame_from_reference[size_t(i)], size);
        std::printf("    frame %d: scale err %.4f %% centre %.3f px corner %.3f px\n", i, e.scale_percent, e.centre_px,
                    e.corner_px);
      }
    }
    std::fflush(stdout);
  }
  const int done = count - failed;
  std::printf("\nseeds %u..%u: %d stacks, %d failed\n", seed_base, seed_base + unsigned(count) - 1, count, failed);
  std::printf("per-frame transform error over all frames: scale %% max %.4f median %.4f; centre px max %.3f median %.3f; "
              "corner px max %.3f median %.3f\n",
              Percentile(all_scale, 1), Percentile(all_scale, 0.5), Percentile(all_centre, 1), Percentile(all_centre, 0.5),
              Percentile(all_corner, 1), Percentile(all_corner, 0.5));
  std::printf("per-stack worst: scale %% median %.4f; centre px median %.3f; corner px median %.3f\n",
              Percentile(seed_scale, 0.5), Percentile(seed_centre, 0.5), Percentile(seed_corner, 0.5));
  std::printf("stacks within 0.1 %% / 0.5 px (every frame): %d/%d\n", within, done);
  std::printf("depth RMSE (frames) mean over stacks: chain %.4f oracle %.4f none %.4f; chain/oracle max %.3f median %.3f; "
              "<= 1.10: %d/%d\n",
              sum_a / std::max(1, done), sum_b / std::max(1, done), sum_c / std::max(1, done), Percentile(ratios, 1),
              Percentile(ratios, 0.5), ratio_ok, done);
  std::printf("on the same pixels (oracle and none both have a depth), mean over stacks: RMSE oracle %.4f none %.4f, "
              "mean |error| oracle %.4f none %.4f; oracle/none RMSE median %.3f min %.3f max %.3f; true corner motion px "
              "median %.3f max %.3f\n",
              sum_bc / std::max(1, done), sum_c_same / std::max(1, done), sum_abs_b / std::max(1, done),
              sum_abs_c / std::max(1, done), Percentile(oracle_over_none, 0.5), Percentile(oracle_over_none, 0),
              Percentile(oracle_over_none, 1), Percentile(true_corners, 0.5), Percentile(true_corners, 1));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (mode == "pcb" && argc > 2) return Pcb(argv[2]);
  if (mode == "still" && argc > 2) return Rate(std::atoi(argv[2]), 0.0, argc > 3 ? unsigned(std::atoi(argv[3])) : 1000u);
  if (mode == "drift" && argc > 3) return Rate(std::atoi(argv[2]), std::atof(argv[3]), argc > 4 ? unsigned(std::atoi(argv[4])) : 1000u);
  if (mode == "renderers" && argc > 2) return Renderers(std::atoi(argv[2]), argc > 3 ? unsigned(std::atoi(argv[3])) : 9000u);
  if (mode == "dump" && argc > 3) {  // the still rig stack of a seed, as PNGs
    auto f = RigStack(unsigned(std::atoi(argv[2])), Motion{});
    if (!f.ok()) return 1;
    for (size_t i = 0; i < f->size(); ++i) cv::imwrite(std::string(argv[3]) + "/f" + std::to_string(100 + i) + ".png", (*f)[i]);
    return 0;
  }
  if (mode == "moving" && argc > 2) return Moving(std::atoi(argv[2]), argc > 3 ? unsigned(std::atoi(argv[3])) : 100u);
  if (mode == "speed") {
    return Speed(argc > 2 ? std::atoi(argv[2]) : 60,
                 cv::Size(argc > 3 ? std::atoi(argv[3]) : 1600, argc > 4 ? std::atoi(argv[4]) : 1200));
  }
  std::fprintf(stderr,
               "usage: chain-evaluate pcb <dir> | still <count> | drift <count> <px> | renderers <count> [seed] | "
               "speed [frames] [width] [height] | moving <count> [seed]\n");
  return 2;
}
