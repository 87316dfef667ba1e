// Natural-looking focal stacks with ground truth (beyond the microscope of thesis 4.3: a camera
// focused through a layered scene), for evaluating shape from focus where most users meet it:
// macro photography, colour microscope cameras, public focal-stack data sets.
//
// Model (every number below is drawn from the seed; docs/reconstruction.md: natural-evaluate):
// - Scene: a background layer covering the frame (a tilted, gently undulating surface) and 2..4
//   object layers in front of it (irregular blobs, ellipses, rounded boxes, poles crossing the
//   frame), each a complete layer: its colour and depth exist also where a nearer layer hides
//   it, so a blurred foreground edge reveals the right background behind it.
// - Depth: each layer's depth is a smooth function (plane + dome) in frame units: the frame index
//   k (fractional) at which that surface is sharpest. Frame 0 focuses nearest. The background
//   lies in roughly [0.45, 0.92] N, objects in disjoint bands of [0.06, 0.46] N nearer than
//   everything behind them, so occlusion order and depth order agree.
// - Materials (linear RGB radiance): dead leaves (discs and boxes with radii ~ r^-3 from 1.5 px
//   to a fifth of the frame: edges at every scale, a 1/f spectrum), 1/f ("pink") noise with
//   chroma, text-like strokes (Hershey-font words of 6..22 px on signs and posters), and flat
//   textureless paint / sky (colour + a gradient far wider than any focus window). Texture
//   contrast varies per material (low-contrast surfaces included). A smooth shading multiplies
//   everything.
// - Defocus: thin lens with focus steps uniform in dioptres, so a surface at depth d seen in
//   frame k is blurred by a disc of radius blur_radius_px_per_frame * |d - k| (DefocusModel of
//   devices/sim/defocus.h: Gaussian core in_focus_sigma_px near focus, pillbox far from it).
//   Within a layer the blur varies per pixel (gather from a ladder of blurred copies, mixed to
//   keep the PSF variance exact).
// - Occlusion: per frame, layers are composited back to front with the "over" operator on their
//   blurred premultiplied colour and blurred alpha: C = K*(a c) + (1 - K*a) C_behind. A
//   defocused foreground thus spreads over the background and becomes semi-transparent at its
//   edges; an in-focus foreground edge stays sharp over a blurred background.
// - Camera: shot noise (full_well_electrons at radiance 1) and read noise per channel, sRGB
//   transfer curve, 8- or 16-bit BGR (or grey: BT.709 luminance of the same radiance).
// Not modelled: focus breathing (magnification change with focus), lens aberrations, vignetting,
// Bayer demosaicing, JPEG artefacts.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

struct NaturalSceneOptions {
  cv::Size size{256, 256};  // 64..2048 per side
  int frames = 30;          // 5..100
  uint32_t seed = 1;
  // Blur-circle radius per frame of defocus (pixels). <= 0: drawn from the seed in [0.5, 1.2].
  double blur_radius_px_per_frame = 0.0;
  double in_focus_sigma_px = 0.5;       // lens + sensor PSF at focus (Gaussian sigma)
  double full_well_electrons = 6000.0;  // at linear radiance 1: shot noise
  double read_noise_electrons = 5.0;
  int bit_depth = 8;   // 8 -> CV_8U, 16 -> CV_16U frames
  bool colour = true;  // false: grey frames (BT.709 luminance)

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

struct NaturalScene {
  std::vector<cv::Mat> frames;  // frame k focused at depth k; CV_8UC3/CV_16UC3 (BGR) or 1 channel
  cv::Mat depth_frames;         // CV_32FC1 truth: depth of the visible surface (frontmost alpha >= 0.5)
  cv::Mat all_in_focus;         // every layer at its own focus, noise-free, type of the frames
  cv::Mat textured;             // CV_8UC1: 255 where the visible surface carries texture, 0 on flat paint / sky
  cv::Mat occlusion_edge;       // CV_8UC1: 255 within 3 px of a depth jump of more than 1 frame
  double blur_radius_px_per_frame = 0.0;
  std::string description;  // one line: layers, materials, depth ranges
};

StatusOr<NaturalScene> RenderNaturalScene(const NaturalSceneOptions& options);

}  // namespace inspection
