// chain-evaluate: the chain registration of imported stacks (core/registration/chain_registration.h)
//   chain-evaluate pcb <dir>      per-frame scale / shift on a real focus-rail stack beside an
//                                 independent full-resolution registration (ORB features + RANSAC
//                                 similarity, no ECC, no pyramid)
//   chain-evaluate still <count> [seed]  false-positive rate of the still test on still stacks of a
//                                 renderer of its own (band-limited noise surface, per-pixel
//                                 depth-dependent Gaussian defocus, sensor noise; no devices/sim code)
//   chain-evaluate drift <count> <px> [seed]  detection rate on the same renderer's stacks drifting px in total
#include <chrono>
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

int Pcb(const std::string& dir) {
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().extension() == ".jpg" && e.path().filename().string().rfind("pcb_", 0) == 0) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::vector<cv::Mat> grey;
  for (const auto& f : files) grey.push_back(cv::imread(f.string(), cv::IMREAD_GRAYSCALE));
  const int n = int(grey.size());
  const auto t0 = std::chrono::steady_clock::now();
  auto r = RegisterChain([&](int i) -> StatusOr<cv::Mat> { return grey[size_t(i)]; }, n, {});
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

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (mode == "pcb" && argc > 2) return Pcb(argv[2]);
  if (mode == "still" && argc > 2) return Rate(std::atoi(argv[2]), 0.0, argc > 3 ? unsigned(std::atoi(argv[3])) : 1000u);
  if (mode == "drift" && argc > 3) return Rate(std::atoi(argv[2]), std::atof(argv[3]), argc > 4 ? unsigned(std::atoi(argv[4])) : 1000u);
  std::fprintf(stderr, "usage: chain-evaluate pcb <dir> | still <count> | drift <count> <px>\n");
  return 2;
}
