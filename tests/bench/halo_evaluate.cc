// halo-evaluate: the halo table of issue 34 (halo-free depth and all-in-focus at depth jumps).
// Scenes: bright textured objects in front of darker textured backgrounds from the halo renderer
// (tests/core/halo_scene_synthetic.h, shares no code with devices/sim), and grey natural scenes
// (devices/sim/natural_scene.h). Per set: the depth error and the all-in-focus error in the band
// on the background side of the object's edge (halo scenes: as wide as the object's blur radius at
// the background's focus; natural scenes: within 10 px on the far side of a jump of >= 2 frames),
// before (the engine + the default post-processing) and after SuppressHalos
// (core/sff/halo_suppression.h) between the two; the rest of the frame to show it is left alone.
// The options were chosen on the "tune" set; the "held-out" sets use other seeds, shapes, depths,
// blur rates and brightness ratios. Output: tests/bench/halo_evaluate_output.md.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "core/sff/all_in_focus.h"
#include "core/sff/depth_postprocess.h"
#include "core/sff/halo_suppression.h"
#include "core/sff/sff_engine.h"
#include "devices/sim/natural_scene.h"
#include "tests/core/halo_scene_synthetic.h"

namespace inspection {
namespace {

using testing_halo::HaloScene;
using testing_halo::HaloSceneOptions;
using testing_halo::HaloShape;
using Clock = std::chrono::steady_clock;

// Pixels on the background side within this distance of the edge see the sharp edge itself in
// the focus window (7 px window + the 3x3 Sobel: 4 px): SFF's own edge fattening, not the halo.
constexpr int kEdgePx = 4;

// One scene to score: frames, z (= frame index), the truth and the bands: `edge` within kEdgePx
// of the object on the background side, `halo` from there to band_px.
struct Scene {
  std::vector<cv::Mat> frames;
  std::vector<double> z_um;
  cv::Mat truth_frames, truth_aif, edge, halo;
  double band_px = 0;
};

// Squared-error sums over a mask, pooled over scenes.
struct Pool {
  double depth_sq = 0, aif_sq = 0;
  size_t depth_n = 0, aif_n = 0, total = 0;
  void Add(const cv::Mat& depth, const cv::Mat& aif, const Scene& s, const cv::Mat& mask) {
    for (int y = 0; y < mask.rows; ++y)
      for (int x = 0; x < mask.cols; ++x) {
        if (!mask.at<uint8_t>(y, x)) continue;
        ++total;
        const float d = depth.at<float>(y, x);
        if (std::isfinite(d)) {
          const double e = d - s.truth_frames.at<float>(y, x);
          depth_sq += e * e;
          ++depth_n;
        }
        const double a = double(aif.at<uint8_t>(y, x)) - s.truth_aif.at<uint8_t>(y, x);
        aif_sq += a * a;
        ++aif_n;
      }
  }
  double DepthRmse() const { return depth_n ? std::sqrt(depth_sq / depth_n) : NAN; }
  double AifRmse() const { return aif_n ? std::sqrt(aif_sq / aif_n) : NAN; }
  double ValidPercent() const { return total ? 100.0 * depth_n / total : NAN; }
};

struct SetResult {
  Pool halo_before, halo_after;  // unthresholded engine depth: every halo-band pixel
  Pool post_before, post_after;  // halo band after the default post-processing: pixels with depth
  Pool edge_before, edge_after;  // unthresholded, the edge band
  Pool rest_before, rest_after;  // outside both bands (and a 4 px frame border), post-processed
  double candidates = 0, moved = 0, engine_s = 0, halo_s = 0;
  size_t changed = 0, better = 0, worse = 0;  // moved pixels whose |error| fell / rose by > 1 frame
  int scenes = 0;
  double band_px = 0;
};

Scene FromHalo(const HaloScene& h) {
  cv::Mat not_foreground = ~h.foreground, distance;
  cv::distanceTransform(not_foreground, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  const cv::Mat edge = (distance > 0) & (distance <= kEdgePx);
  const cv::Mat halo = (distance > kEdgePx) & (distance <= h.band_px);
  return {h.frames, h.z_um, h.depth_frames, h.all_in_focus, edge, halo, h.band_px};
}

StatusOr<Scene> FromNatural(uint32_t seed) {
  NaturalSceneOptions o;
  o.size = {256, 256};
  o.frames = 30;
  o.seed = seed;
  o.colour = false;
  INSPECT_ASSIGN_OR_RETURN(NaturalScene n, RenderNaturalScene(o));
  Scene s;
  s.frames = n.frames;
  for (int k = 0; k < o.frames; ++k) s.z_um.push_back(k);
  s.truth_frames = n.depth_frames;
  s.truth_aif = n.all_in_focus;
  // The far side of a jump: a pixel with a surface >= 2 frames nearer within 10 px.
  constexpr int kBand = 10;
  cv::Mat nearest, nearest_edge;
  cv::erode(n.depth_frames, nearest, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * kBand + 1, 2 * kBand + 1}));
  cv::erode(n.depth_frames, nearest_edge,
            cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * kEdgePx + 1, 2 * kEdgePx + 1}));
  s.edge = (n.depth_frames - nearest_edge) >= 2.0;
  s.halo = ((n.depth_frames - nearest) >= 2.0) & ~s.edge;
  s.band_px = kBand;
  return s;
}

Status Score(const Scene& s, const HaloSuppressionOptions& halo, SetResult* r) {
  SffOptions sff;
  sff.min_confidence = 0.0;  // the post-processing thresholds (as the server runs it)
  sff.threads = 1;
  const auto t0 = Clock::now();
  INSPECT_ASSIGN_OR_RETURN(DepthResult raw, SffEngine::ReconstructInMemory(sff, s.frames, s.z_um));
  const auto t1 = Clock::now();
  HaloSuppressionFigures f;
  INSPECT_ASSIGN_OR_RETURN(DepthResult fixed,
                           SuppressHalos(raw, [&](int i) -> StatusOr<cv::Mat> { return s.frames[size_t(i)]; }, s.z_um,
                                         sff, halo, &f));
  const auto t2 = Clock::now();
  const DepthPostProcessOptions post;
  INSPECT_ASSIGN_OR_RETURN(DepthResult before, PostProcessDepth(raw, s.z_um, sff.window_px, post));
  INSPECT_ASSIGN_OR_RETURN(DepthResult after, PostProcessDepth(fixed, s.z_um, sff.window_px, post));
  r->halo_before.Add(raw.depth_um, raw.all_in_focus, s, s.halo);
  r->halo_after.Add(fixed.depth_um, fixed.all_in_focus, s, s.halo);
  r->post_before.Add(before.depth_um, before.all_in_focus, s, s.halo);
  r->post_after.Add(after.depth_um, after.all_in_focus, s, s.halo);
  r->edge_before.Add(raw.depth_um, raw.all_in_focus, s, s.edge);
  r->edge_after.Add(fixed.depth_um, fixed.all_in_focus, s, s.edge);
  cv::Mat rest = ~(s.halo | s.edge);
  constexpr int kBorder = 4;
  rest.rowRange(0, kBorder).setTo(0);
  rest.rowRange(rest.rows - kBorder, rest.rows).setTo(0);
  rest.colRange(0, kBorder).setTo(0);
  rest.colRange(rest.cols - kBorder, rest.cols).setTo(0);
  r->rest_before.Add(before.depth_um, before.all_in_focus, s, rest);
  r->rest_after.Add(after.depth_um, after.all_in_focus, s, rest);
  for (int y = 0; y < raw.depth_um.rows; ++y)
    for (int x = 0; x < raw.depth_um.cols; ++x) {
      const float a = raw.depth_um.at<float>(y, x), b = fixed.depth_um.at<float>(y, x);
      if (a == b || !std::isfinite(a) || !std::isfinite(b)) continue;
      const float t = s.truth_frames.at<float>(y, x);
      ++r->changed;
      const float gain = std::abs(a - t) - std::abs(b - t);
      r->better += gain > 1.f ? 1 : 0;
      r->worse += gain < -1.f ? 1 : 0;
    }
  r->candidates += f.candidate_fraction;
  r->moved += f.reassigned_fraction;
  r->engine_s += std::chrono::duration<double>(t1 - t0).count();
  r->halo_s += std::chrono::duration<double>(t2 - t1).count();
  r->band_px += s.band_px;
  ++r->scenes;
  return Status::Ok();
}

void PrintHeader() {
  std::printf(
      "| set | scenes | halo band px | halo band: depth RMSE, frames | AIF RMS, grey | depth RMSE post-processed | valid "
      "%% post | edge band (<= %d px): depth RMSE | AIF RMS | rest: depth RMSE post | AIF RMS | candidates %% | moved %% "
      "| moved: better / worse %% | halo pass / engine time |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
      kEdgePx);
}

void PrintRow(const char* name, const SetResult& r) {
  auto pair = [](double a, double b) {
    char buf[48];
    std::snprintf(buf, sizeof(buf), "%.2f -> %.2f", a, b);
    return std::string(buf);
  };
  std::printf("| %s | %d | %.1f | %s | %s | %s | %s | %s | %s | %s | %s | %.1f | %.2f | %.0f / %.0f | %.2f |\n", name,
              r.scenes,
              r.band_px / r.scenes, pair(r.halo_before.DepthRmse(), r.halo_after.DepthRmse()).c_str(),
              pair(r.halo_before.AifRmse(), r.halo_after.AifRmse()).c_str(),
              pair(r.post_before.DepthRmse(), r.post_after.DepthRmse()).c_str(),
              pair(r.post_before.ValidPercent(), r.post_after.ValidPercent()).c_str(),
              pair(r.edge_before.DepthRmse(), r.edge_after.DepthRmse()).c_str(),
              pair(r.edge_before.AifRmse(), r.edge_after.AifRmse()).c_str(),
              pair(r.rest_before.DepthRmse(), r.rest_after.DepthRmse()).c_str(),
              pair(r.rest_before.AifRmse(), r.rest_after.AifRmse()).c_str(), 100.0 * r.candidates / r.scenes,
              100.0 * r.moved / r.scenes, r.changed ? 100.0 * r.better / r.changed : 0.0,
              r.changed ? 100.0 * r.worse / r.changed : 0.0, r.halo_s / r.engine_s);
  std::fflush(stdout);
}

// The tuning set: ellipses, one geometry of depths and blur, seeds 1..4.
std::vector<HaloSceneOptions> TuneSet() {
  std::vector<HaloSceneOptions> set;
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    HaloSceneOptions o;
    o.seed = seed;
    set.push_back(o);
  }
  return set;
}

// Held out: other seeds, boxes and poles, depths, blur rates and brightness drawn per scene.
// reversed: a dark object in front of a bright background (no halo to remove: a control).
// first_seed 101: the held-out set the defaults were chosen on (with --sweep); 201: fresh.
std::vector<HaloSceneOptions> HeldOutSet(bool reversed, uint32_t first_seed = 101) {
  std::vector<HaloSceneOptions> set;
  cv::RNG rng((reversed ? 4242 : 2024) + first_seed);
  for (uint32_t seed = first_seed; seed < first_seed + 8; ++seed) {
    HaloSceneOptions o;
    o.seed = seed + (reversed ? 100 : 0);
    o.shape = seed % 2 ? HaloShape::kRoundedBox : HaloShape::kPole;
    o.foreground_frame = rng.uniform(3.0, 10.0);
    o.background_frame = rng.uniform(17.0, 27.0);
    o.blur_px_per_frame = rng.uniform(0.6, 1.0);
    o.foreground_radiance = rng.uniform(0.35, 0.6);
    o.background_radiance = rng.uniform(0.03, 0.12);
    o.background_contrast = rng.uniform(0.2, 0.45);
    if (reversed) std::swap(o.foreground_radiance, o.background_radiance);
    set.push_back(o);
  }
  return set;
}

// --dump DIR: the first tuning scene's frames, truth and depth maps as PNGs, and the focus curves
// of a row of pixels leaving the object's edge (to see what the focus measure peaks on).
int Dump(const std::string& dir) {
  const HaloScene h = testing_halo::RenderHaloScene(TuneSet().front());
  SffOptions sff;
  sff.min_confidence = 0.0;
  auto raw = SffEngine::ReconstructInMemory(sff, h.frames, h.z_um);
  if (!raw.ok()) return 1;
  auto fixed = SuppressHalos(*raw, [&](int i) -> StatusOr<cv::Mat> { return h.frames[size_t(i)]; }, h.z_um, sff, {});
  if (!fixed.ok()) return 1;
  for (int k : {0, 6, 10, 14, 18, 22, 29}) cv::imwrite(dir + "/frame_" + std::to_string(k) + ".png", h.frames[size_t(k)]);
  auto depth_png = [](const cv::Mat& d) {
    cv::Mat out;
    d.convertTo(out, CV_8U, 8.0);
    return out;
  };
  cv::imwrite(dir + "/truth.png", depth_png(h.depth_frames));
  cv::imwrite(dir + "/raw.png", depth_png(raw->depth_um));
  cv::imwrite(dir + "/fixed.png", depth_png(fixed->depth_um));
  cv::imwrite(dir + "/aif_truth.png", h.all_in_focus);
  cv::imwrite(dir + "/aif_raw.png", raw->all_in_focus);
  cv::imwrite(dir + "/aif_fixed.png", fixed->all_in_focus);
  cv::imwrite(dir + "/band.png", h.background_band);
  cv::imwrite(dir + "/fixed_aif_diff.png", cv::abs(fixed->all_in_focus - raw->all_in_focus) * 4);
  const int y = h.frames[0].rows / 2;
  int edge = -1;
  for (int x = h.frames[0].cols - 1; x > 0; --x)
    if (h.foreground.at<uint8_t>(y, x)) {
      edge = x;
      break;
    }
  std::printf("row %d, foreground edge at x %d\n", y, edge);
  std::vector<cv::Mat> scores;
  for (const cv::Mat& f : h.frames) {
    cv::Mat s;
    (void)FocusScore(f, sff.focus_measure, sff.window_px, &s);
    scores.push_back(s);
  }
  for (int dx : {-6, -2, 1, 3, 6, 9, 12, 16, 20, 26}) {
    const int x = edge + dx;
    if (x < 0 || x >= h.frames[0].cols) continue;
    std::printf("dx %+3d truth %4.1f raw %5.2f conf %.2f fixed %5.2f |", dx, h.depth_frames.at<float>(y, x),
                raw->depth_um.at<float>(y, x), raw->confidence.at<float>(y, x), fixed->depth_um.at<float>(y, x));
    for (const cv::Mat& s : scores) std::printf(" %.3g", double(s.at<int32_t>(y, x)));
    std::printf("\n");
  }
  return 0;
}

int Run(int argc, char** argv) {
  bool quick = false, sweep = false;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) {
      quick = true;
    } else if (std::strcmp(argv[i], "--sweep") == 0) {
      sweep = true;
    } else if (std::strcmp(argv[i], "--dump") == 0 && i + 1 < argc) {
      return Dump(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: halo-evaluate [--quick | --sweep | --dump DIR]\n  --quick: the tuning set only; --sweep: min_own_peak_ratio x depth_from_surface_without_peak on every set\n");
      return 2;
    }
  }
  auto run_set = [&](const char* name, const std::vector<Scene>& scenes, const HaloSuppressionOptions& o) -> bool {
    SetResult r;
    for (const Scene& s : scenes) {
      if (Status st = Score(s, o, &r); !st.ok()) {
        std::fprintf(stderr, "%s: %s\n", name, st.ToString().c_str());
        return false;
      }
    }
    PrintRow(name, r);
    return true;
  };
  std::vector<Scene> tune;
  for (const HaloSceneOptions& o : TuneSet()) tune.push_back(FromHalo(testing_halo::RenderHaloScene(o)));

  std::printf("Tuning set (ellipses, foreground frame 6, background 22, blur 0.8 px/frame; seeds 1-4):\n\n");
  PrintHeader();
  const HaloSuppressionOptions defaults;
  for (int radius : {8, 15, 25}) {
    for (double other : {0.1, 0.2, 0.4}) {
      HaloSuppressionOptions o = defaults;
      o.band_radius_px = radius;
      o.max_other_layer_ratio = other;
      const bool is_default = radius == defaults.band_radius_px && other == defaults.max_other_layer_ratio;
      char name[96];
      std::snprintf(name, sizeof(name), "tune R %d, occluder ratio < %.2f%s", radius, other,
                    is_default ? " (default)" : "");
      if (!run_set(name, tune, o)) return 1;
    }
  }
  {
    HaloSuppressionOptions o = defaults;
    o.all_in_focus_from_occluder_focus = !defaults.all_in_focus_from_occluder_focus;
    const std::string name = std::string("tune defaults, AIF from ") +
                             (o.all_in_focus_from_occluder_focus ? "the occluder's focus" : "the pixel's layer");
    if (!run_set(name.c_str(), tune, o)) return 1;
  }
  if (quick) return 0;

  std::printf("\nHeld out (defaults):\n\n");
  PrintHeader();
  std::vector<Scene> held, reversed, natural;
  for (const HaloSceneOptions& o : HeldOutSet(false)) held.push_back(FromHalo(testing_halo::RenderHaloScene(o)));
  for (const HaloSceneOptions& o : HeldOutSet(true)) reversed.push_back(FromHalo(testing_halo::RenderHaloScene(o)));
  for (uint32_t seed = 11; seed <= 16; ++seed) {
    auto s = FromNatural(seed);
    if (!s.ok()) {
      std::fprintf(stderr, "natural scene %u: %s\n", seed, s.status().ToString().c_str());
      return 1;
    }
    natural.push_back(std::move(s).value());
  }
  if (sweep) {
    for (double own : {0.0, 0.5, 1.0, 2.0}) {
     for (bool fill : {true, false}) {
      HaloSuppressionOptions o = defaults;
      o.min_own_peak_ratio = own;
      o.depth_from_surface_without_peak = fill;
      std::string tag = " own " + std::to_string(own).substr(0, 3) + (fill ? " fill" : " nofill");
      run_set(("tune" + tag).c_str(), tune, o);
      run_set(("held" + tag).c_str(), held, o);
      run_set(("control" + tag).c_str(), reversed, o);
      run_set(("natural" + tag).c_str(), natural, o);
     }
    }
    return 0;
  }
  if (!run_set("held-out A bright on dark (boxes, poles; seeds 101-108)", held, defaults)) return 1;
  if (!run_set("held-out A dark on bright (control)", reversed, defaults)) return 1;
  if (!run_set("natural scenes 11-16, 10 px band", natural, defaults)) return 1;
  // Fresh scenes, seen by no choice of an option (the defaults were picked with --sweep on the
  // sets above).
  std::vector<Scene> fresh, fresh_reversed, fresh_natural;
  for (const HaloSceneOptions& o : HeldOutSet(false, 201)) fresh.push_back(FromHalo(testing_halo::RenderHaloScene(o)));
  for (const HaloSceneOptions& o : HeldOutSet(true, 201)) {
    fresh_reversed.push_back(FromHalo(testing_halo::RenderHaloScene(o)));
  }
  for (uint32_t seed = 21; seed <= 26; ++seed) {
    auto s = FromNatural(seed);
    if (!s.ok()) {
      std::fprintf(stderr, "natural scene %u: %s\n", seed, s.status().ToString().c_str());
      return 1;
    }
    fresh_natural.push_back(std::move(s).value());
  }
  if (!run_set("fresh B bright on dark (seeds 201-208)", fresh, defaults)) return 1;
  if (!run_set("fresh B dark on bright (control)", fresh_reversed, defaults)) return 1;
  if (!run_set("fresh natural scenes 21-26, 10 px band", fresh_natural, defaults)) return 1;
  return 0;
}

}  // namespace
}  // namespace inspection

int main(int argc, char** argv) { return inspection::Run(argc, argv); }
