// Registration of an imported stack as a chain: each frame registered to its neighbour (ECC on
// gradient-magnitude images, coarse to fine, each pair started from the previous pair's result)
// and the pair transforms accumulated onto the middle frame. Unlike the focus-breathing model
// (stack_alignment.h) nothing is assumed about z: an imported stack's z is nominal or unknown, and
// a real focus rail's scale and shift need not be linear in it.
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

struct ChainRegistrationOptions {
  // The registration runs on frames shrunk to at most this many pixels on the longer side; the
  // transforms are scaled back to full resolution.
  int max_side_px = 512;
  int pyramid_levels = 3;  // 1..5, each halves the working size
  // Gaussian smoothing of the working-size frame before the registration image is made (px):
  // neighbours at different defocus differ mostly in their finest detail.
  double gradient_sigma_px = 1.5;
  // What ECC registers: the gradient magnitude, the smoothed intensity, or either divided by its
  // local mean / standard deviation (contrast-normalised over normalise_sigma_px of the working
  // size), so that the frame's sharp band, which moves across a tilted or stepped surface from
  // frame to frame, does not weigh more than the rest. The contrast-normalised intensity: on
  // still stacks of chain-evaluate's tuning seeds it called 2 of 10 natural-scene stacks moving
  // where the gradient magnitude called 8 (rig 5 vs 6, lens 0 vs 1, noise 0 vs 0), and it put the
  // PCB stack closer to ORB + RANSAC (docs/alignment.md). A gradient magnitude's apparent edge
  // moves with the blur's change across a slope; an intensity edge does not, to first order.
  enum class Image { kGradient, kIntensity, kNormalisedGradient, kNormalisedIntensity };
  Image image = Image::kNormalisedIntensity;
  double normalise_sigma_px = 8.0;
  int max_iterations = 30;        // ECC iterations per level
  double epsilon = 1e-4;          // ECC convergence
  double min_correlation = 0.5;   // ECC correlation of a registered pair; below = not registered
  // Still test: the stack is called still when no corner displacement of the pair transforms
  // differs from zero at this false-positive rate (two-sided, Bonferroni over the 8 corner
  // coordinates, Student t of the pairs' own spread); a still stack is left unwarped.
  double still_false_positive_rate = 0.01;
  // A pair whose corner displacement is further than this from the median pair's (plus 6 robust
  // sigmas of the pairs' spread) disagrees with the chain: FAILED_PRECONDITION naming it.
  double max_pair_outlier_px = 8.0;
  // A stack whose motion is statistically significant but whose accumulated transforms move no
  // frame corner by this much is still left unwarped: neighbours at different defocus register
  // with a small systematic bias (~0.01 px per pair on still stacks of chain-evaluate's renderer,
  // up to 0.3 px accumulated over 40 frames) that no statistic on the pairs can tell from motion,
  // and a warp that small gains nothing measurable in depth accuracy (with the true transforms,
  // docs/alignment.md). An imported stack's default raises it to kImportedWarpPaysPx.
  double min_motion_px = 1.0;
  // Most stacks do not move, and their decision should cost next to nothing: a quick pass first
  // registers at most quick_max_pairs pairs of frames `stride` apart (the chain still spans the
  // stack, so motion anywhere accumulates into it) on frames shrunk to quick_max_side_px, one
  // pyramid level fewer. When its accumulated transforms move no corner by min_motion_px that
  // is the answer (still); otherwise (more motion, a pair failing or out of line) the full chain
  // runs as if it had not and decides with the still test. What the quick pass cannot see is
  // one frame out of line between two it samples.
  bool quick_still_check = true;
  int quick_max_side_px = 256;
  int quick_max_pairs = 12;
  // A moving stack's chain accumulates its pairs' small errors: on the lens renderer's stacks with
  // 5-20 % scale change and 50-300 px shift (chain-evaluate moving) they added up to 0.2-0.3 %
  // of scale at the ends of the chain. So, once the stack is called moving, every frame is
  // registered once more directly against the reference frame (ECC, one level, on the
  // registration image of both shrunk to refine_max_side_px), started from the chain's
  // composed transform; a frame whose refinement does not converge, correlates below
  // refine_min_correlation or moves a corner by more than refine_max_change_px from the chain's
  // keeps the chain's transform.
  bool refine_to_reference = true;
  int refine_max_side_px = 1024;
  double refine_min_correlation = 0.2;
  double refine_max_change_px = 8.0;  // full-resolution px
  // Frames prepared and pairs registered at once (0 = all hardware threads; 1 = in order, two
  // frames in memory, load called once per frame in order). With more, load must be
  // thread-safe: the chain is cut into contiguous runs, each started from the identity, and a
  // run's first frame is loaded by its run and by the run before.
  int threads = 1;
  Status Validate() const;
};

struct ChainRegistration {
  int reference_frame = 0;                        // (n - 1) / 2
  std::vector<cv::Matx23d> frame_from_reference;  // full-resolution px: reference grid -> frame i
  std::vector<cv::Matx23d> pair;                  // pair[i]: frame i-1 -> frame i (pair[0] identity)
  std::vector<double> pair_correlation;           // ECC correlation of pair i (pair 0: 1)
  // The still test could not tell the motion from 0, or it is below min_motion_px.
  bool still = false;
  double still_statistic = 0.0;                   // max |mean| / standard error over the corner coordinates
  double still_threshold = 0.0;                   // the statistic's critical value at the stated rate
  double max_corner_displacement_px = 0.0;        // of the accumulated transforms
  // The quick pass decided (still): frame_from_reference holds its transforms for the frames it
  // sampled, interpolated between them; pair and pair_correlation stay identity / 1.
  bool quick = false;
  int quick_stride = 0;  // frames apart in the quick pass (0: it did not run)
  // Frames whose transform the refinement against the reference replaced (refine_to_reference).
  int refined_frames = 0;
  // Per frame: the refinement's ECC correlation (0: it did not converge or did not run; the
  // reference 1).
  std::vector<double> refine_correlation;
};

// load(i), i in [0, n): frame i (CV_8UC1, CV_16UC1 or CV_32FC1), called in order (options.threads
// 1): the quick pass's frames, then, unless it called the stack still, every frame once more,
// and for a moving stack with refine_to_reference the reference and every other frame again.
// INVALID_ARGUMENT: fewer than 3 frames, frames smaller than 32x32 px or of different sizes (naming
// the frame); FAILED_PRECONDITION naming the frame pairs that could not be registered (featureless,
// unrelated) or disagree with the chain.
// registered_pairs (may be null) receives how many pairs registered, also when the chain fails:
// 0 on a failure means the stack gave no measurement of motion at all (e.g. featureless).
StatusOr<ChainRegistration> RegisterChain(const std::function<StatusOr<cv::Mat>(int)>& load, int n,
                                          const ChainRegistrationOptions& options, int* registered_pairs = nullptr);

// Upper (1 - alpha/2) quantile of Student's t with dof degrees of freedom (Cornish-Fisher; within
// 1 % for dof >= 3).
double StudentTQuantile(double one_sided_alpha, int dof);

}  // namespace inspection
