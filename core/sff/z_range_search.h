// One feature, one name in code: "z range search" (this file, server/procedures/z_range_search.h,
// ZRange* types). The stable API keeps its own names for it: ScanRequest.z_range_search and
// ZRangeSearchResult in the proto, `inspectctl scan --auto-range` on the CLI, "automatic z range"
// in the user documentation.
//
// Automatic z range (the focus measure of thesis eq. 3.14 and the three-point peak of 3.3.3
// applied to a coarse sweep): where a specimen's focus lies, from a few frames far apart.
//
// Method: every coarse frame is reduced by `downsample` (area average), its Tenengrad energy
// summed over a window (eq. 3.14) gives one focus curve per reduced pixel. A reduced pixel sees the
// texture's coarser components, whose focus curve is wider than the full-resolution one, so
// frames several depths of field apart still sample its flanks. Per reduced pixel: the frame of
// the maximum, the sub-step vertex of the defocus parabola through F^-1/2 (depth_interpolation.h;
// exact for a flat-spectrum texture whatever the step) and whether the peak is resolved (it
// stands out of the pixel's own floor by min_peak_ratio). The specimen's range is the
// [tail, 100 - tail] percentile of the resolved peaks; the caller adds its margin.
// No device I/O: the server's scan procedure (server/procedures/z_range_search.h) captures.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

// Checkerboard cell of the search pattern the coarse sweep projects, projector pixels.
inline constexpr int kSearchCellProjectorPx = 2;

// The coarse step the search pattern's focus curve allows, from the optics: the pattern's
// fundamental (period P = 2 cells, camera px) is blurred twice by the shared objective (on its
// way to the specimen and back), each time by a PSF of sigma r/2 = k dz/2 (k: blur-circle radius
// per um of defocus, camera px), so its Tenengrad falls as exp(-2 pi^2 k^2 dz^2 / P^2). The step
// is the one at whose half that is 1/e^2: S = 2 P / (pi k). Every surface then has a frame within
// S/2 of its focus holding >= 14 % of its peak energy, and the frames either side sample the
// curve's flanks. Rounded down to whole um (half um below 2 um). Thesis rig (NA 0.3, 0.74 um px:
// k = 0.425; 3.4 camera px per projector px): 20.4 -> 20 um, 4 of its 5.06 um steps.
// k <= 0 or a scale <= 0: 0 (unknown).
double SearchPatternCoarseStepUm(double blur_radius_px_per_um, double camera_px_per_projector_px);

// What a scan request asks of the automatic z range (ScanRequest.z_range_search).
struct ZRangeSearchSettings {
  double window_start_um = 0.0;  // search window, stage z (either order; normalised low..high)
  double window_end_um = 0.0;
  double coarse_step_um = 0.0;  // distance between two coarse frames
  double margin_um = 0.0;       // added below and above the found range
};

struct ZRangeSearchOptions {
  int downsample = 4;  // frames reduced by this factor (INTER_AREA) before the focus measure
  int window_px = 5;   // Tenengrad window at the reduced scale (odd, 3..15)
  // A reduced pixel's peak is resolved when its maximum is at least this multiple of the lowest
  // value of its curve: texture brought into focus, not noise (a flat curve has ratio ~1).
  double min_peak_ratio = 3.0;
  double min_sharpness = 4.0;
  double tail_percent = 0.5;  // range = [P(tail), P(100 - tail)] of the resolved peaks
  // Below this share of resolved reduced pixels the sweep found no focus (textureless specimen or
  // focus outside the window): FAILED_PRECONDITION instead of a guess.
  double min_resolved_percent = 2.0;
  // A reduced pixel whose window is more than this share saturated in the frame of its maximum
  // is not resolved: a clipped area is flat at focus and its "peak" is the edge of a defocused
  // highlight passing by (polished lands, mirror-like fields).
  double max_saturated_share = 0.2;
  // The range is taken over the clusters of peak heights, not single peaks: peaks binned at a
  // quarter of the coarse step, a cluster is a run of bins each holding >= min_bin_percent / 4
  // of the resolved peaks (min_bin_percent per coarse step of height) plus the sparser bin on
  // either side (the partial bin at a surface's end). Clusters
  // holding >= min_cluster_percent are kept, and the largest always: a part's surfaces (also
  // plateaus far apart) are each a large cluster; spurious peaks far from focus (halos of
  // defocused highlights) are sparse and apart from them.
  double min_bin_percent = 1.0;
  // A resolved peak further than one coarse step from the median of the resolved peaks within
  // this radius (reduced pixels) is dropped as inconsistent.
  int consistency_radius = 3;
  double min_cluster_percent = 5.0;
  // The sweep may end early (ZRangeAccumulator::SettledPercent) once this share of the
  // reduced field has a focus peak the sweep has passed by two frames; 0 = never, sweep the whole
  // window. A depth map is single-valued: a pixel whose peak has been passed has no second
  // surface further on, so once (almost) the whole field has settled the rest of the window can
  // only hold the few unsettled pixels' focus, and a surface that small is dropped by the
  // clustering above anyway (< min_cluster_percent). Textured parts settle to 98.7-100 % two
  // frames after their last peak (image borders and steep flanks stay unsettled); parts with
  // large dark, clipped or textureless areas (cutter, coin: 30-45 %) never reach it and sweep
  // the whole window.
  double stop_settled_percent = 98.0;
  Status Validate() const;
};

struct ZRangeEstimate {
  double z_low_um = 0.0;  // percentiles of the resolved peak positions
  double z_high_um = 0.0;
  double resolved_percent = 0.0;   // share of reduced pixels with a resolved peak
  double clustered_percent = 0.0;  // share of the resolved peaks inside the cluster the range comes from
  // Share of the field whose maximum is at the first / last coarse frame: focus at or beyond the
  // window's end (or a halo growing towards it). Not part of the range; a large share says the
  // specimen may extend beyond the window.
  double at_first_frame_percent = 0.0;
  double at_last_frame_percent = 0.0;
  cv::Mat peak_z_um;  // CV_32FC1 on the reduced grid; NaN where unresolved
};

// Accumulates the coarse frames' focus curves. Not thread-safe; one per sweep.
class ZRangeAccumulator {
 public:
  // bit_depth: significant bits of the frames (8..16), for the saturation level.
  static StatusOr<ZRangeAccumulator> Create(const ZRangeSearchOptions& options, cv::Size frame_size,
                                                int bit_depth);
  // CV_8UC1 or CV_16UC1 frames of frame_size; z strictly monotonic over the pushes.
  Status PushFrame(const cv::Mat& frame, double z_um);
  int frames() const { return int(z_um_.size()); }
  // Share (percent) of the reduced pixels whose focus curve, so far, has a peak that stands out
  // of its floor (min_peak_ratio), is unclipped and has fallen by min_sharpness two frames after
  // it: the sweep has passed their focus. 0 before 3 frames. O(reduced pixels): the running
  // maximum, its frame and the minimum are kept per pixel as frames arrive.
  double SettledPercent() const;
  // Needs >= 3 frames. FAILED_PRECONDITION when fewer than min_resolved_percent of the reduced
  // pixels resolve a peak (the message gives the share and the likely causes).
  StatusOr<ZRangeEstimate> Finish() const;

  // Refining the range's ends. A focus curve narrower than the coarse step (a polished field
  // under the search pattern) has its two neighbour samples on its tails, where a floor of
  // halos and noise holds them up and the parabola's vertex is drawn towards the frame of the
  // maximum: up to half a coarse step (the coin's field, 10 um low at 20 um steps). The fine
  // scan needs the range's ends, so after the sweep, frames half-way between the coarse frame
  // nearest each end of a first estimate and its two neighbours sample the curves there at
  // twice the density: 2 frames for a flat part (both ends at one frame), at most 4. Returns
  // the positions to capture, inside the sweep, ascending, and remembers the coarse frames they
  // are centred on. Call once, after the sweep.
  std::vector<double> PlanRefinement(const ZRangeEstimate& first);
  static constexpr int kMaxRefinementFrames = 4;
  // A frame at one of PlanRefinement's positions, each once (FAILED_PRECONDITION before the
  // plan, INVALID_ARGUMENT at another z or a second time). In Finish, a resolved pixel whose coarse maximum is on a frame the
  // refinement is centred on takes its vertex from the largest of its samples there (the three
  // coarse ones and the refinement frames between them) and that sample's neighbours; it is
  // dropped when those samples do not fall away from the largest (a halo over the surface: two
  // sources of focus energy within one coarse step) or the largest is clipped. Pixels whose
  // maximum is on another frame keep their coarse vertex: a refinement frame on one side only
  // would skew it.
  Status PushRefinementFrame(const cv::Mat& frame, double z_um);
  int refinement_frames() const { return int(refine_z_um_.size()); }

 private:
  ZRangeSearchOptions options_;
  cv::Size frame_size_;
  int bit_depth_ = 8;
  std::vector<double> z_um_;
  std::vector<cv::Mat> saturated_;  // CV_32FC1 share of saturated pixels in each window
  // Whether reduced pixel (r, c)'s maximum so far is a focus peak: out of its floor, sharp,
  // unclipped (Finish and SettledPercent).
  bool PeakIsFocus(int r, int c) const;
  // The frame's reduced focus measure and saturated share (CV_32FC1), for PushFrame and
  // PushRefinementFrame; `name` for the errors.
  Status Reduce(const cv::Mat& frame, double z_um, const std::string& name, cv::Mat* energy,
                cv::Mat* saturated) const;
  // Pixel (r, c)'s peak position; NaN when its refined samples reject it. best: coarse frame of
  // the maximum, 0 < best < frames() - 1.
  float PeakZ(int r, int c, int best) const;

  std::vector<cv::Mat> focus_;      // CV_32FC1 reduced focus measure per frame
  cv::Mat max_, min_;               // CV_32FC1 running maximum / minimum of each pixel's curve
  cv::Mat argmax_;                  // CV_32SC1 frame of the maximum (the first, on ties)
  // Refinement frames, in the order pushed, and the coarse frames they are centred on
  // (PlanRefinement).
  std::vector<int> refine_centres_;
  std::vector<double> refine_planned_z_um_, refine_z_um_;
  std::vector<cv::Mat> refine_focus_, refine_saturated_;
};

// The coarse z positions covering [window low, window high] at coarse_step_um, including both
// ends (the last step may be shorter). INVALID_ARGUMENT naming the field (prefix + name) when the
// window is empty or inverted, outside [travel_min_um, travel_max_um], the step <= 0, larger
// than the window, or the sweep would need more than max_frames frames.
StatusOr<std::vector<double>> CoarseSweepZ(const ZRangeSearchSettings& s, double travel_min_um, double travel_max_um,
                                           int max_frames, const std::string& field_prefix);

// The fine scan's range: [z_low - margin, z_high + margin] widened evenly on both sides to a
// whole number of fine steps and at least min_frames (>= 3) frames, shifted into the stage travel.
struct FineRange {
  double z_start_um = 0.0;
  double z_end_um = 0.0;
};
FineRange ChooseFineRange(const ZRangeEstimate& estimate, double fine_step_um, double margin_um, int min_frames,
                          double travel_min_um, double travel_max_um);

}  // namespace inspection
