// A focal-stack renderer of its own for chain-evaluate's still test, sharing no code with the
// simulated rig (devices/sim/image_formation), the natural-scene renderer (devices/sim/
// natural_scene) or chain-evaluate's noise renderer, so that a still decision tuned on those
// cannot pass here by sharing their assumptions:
// - Scene: a terraced height map (a tilted plane with 2..5 raised or sunk rectangles; depth in
//   frame units) carrying an albedo of 2..6 oriented gratings, 40..400 filled ellipses and a few
//   straight strokes, some seeds at low contrast.
// - Defocus: thin lens, blur radius blur_px_per_frame * |depth - k| in frame k, applied through a
//   Gaussian pyramid (level j = j times pyrDown then pyrUp back: blur ~ 2^j px), per pixel the two
//   levels around log2(1 + radius) blended; no per-frame filtering, so it is fast at 1600x1200.
// - Camera: per-frame exposure flicker (+-1 %), cos^4 vignetting and photo-response
//   non-uniformity fixed across frames, Poisson shot noise (normal approximation) at full_well
//   electrons for albedo 1, read noise, gamma 1/2.2, 8-bit.
// - Motion (optional): frame k's grid is the scene's under scale 1 + scale_total u^1.4,
//   rotation rotation_total u, shift (shift_x_total, shift_y_total) u, u = k / (n - 1), applied
//   before the camera noise; truth is the reference (middle) grid -> frame k matrix. By default
//   the scene is the frame's size and frames moving past its edge see it mirrored;
//   scene_covers_motion renders a scene large enough that every frame sees scene only.
// - Depth truth: depth_reference, the scene's depth on the reference grid in frame units (the
//   frame index at which the pixel is sharpest, blur 0).
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

namespace chain_bench {

struct LensStackOptions {
  cv::Size size{480, 360};
  int frames = 20;
  uint32_t seed = 1;
  double blur_px_per_frame = 0.0;  // <= 0: drawn from the seed in [0.4, 1.5]
  double full_well = 0.0;          // <= 0: drawn in [2000, 20000] electrons
  double read_noise_electrons = 6.0;
  double prnu = 0.005;  // relative pixel gain spread
  double scale_total = 0.0;
  double rotation_total_rad = 0.0;
  double shift_x_total_px = 0.0;
  double shift_y_total_px = 0.0;
  // The scene extends past the frame by as much as the motion needs (no mirrored content; the
  // albedo's ellipses keep their density and size). Slower to render only for large motion.
  bool scene_covers_motion = false;
  // Defocus as a thin lens forms it: each scene point spreads by its own depth's blur (its level
  // weights applied to the albedo before the blur, then summed). The default (false) lets each
  // output pixel pick the blur of its own depth instead, the usual cheap approximation; where
  // the blur varies across the image (a tilted surface) that moves defocused content by about
  // d(sigma^2)/dx, a motion the scene does not make.
  bool scatter = false;
};

struct LensStack {
  std::vector<cv::Mat> frames;                 // CV_8UC1
  std::vector<cv::Matx23d> frame_from_reference;  // truth: reference (middle) grid px -> frame k px
  cv::Mat depth_reference;  // CV_32FC1 on the reference grid: frame index of best focus (truth)
};

LensStack RenderLensStack(const LensStackOptions& options);

}  // namespace chain_bench
