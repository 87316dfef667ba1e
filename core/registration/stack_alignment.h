// Lateral alignment of a focus stack: the focus measure of thesis 3.1.3 compares a
// pixel across frames, which assumes frames registered pixel for pixel. Non-telecentric optics
// change the magnification through focus ("focus breathing") and stages drift laterally, so each
// frame is warped onto the grid of a reference frame before it is measured. The transform is a
// per-stack model of z (FocusBreathingModel): estimated from the stack itself (imported stacks)
// or calibrated once on the rig (scans), so frames can be warped as they arrive.
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/registration/frame_registration.h"
#include "core/util/status.h"

namespace inspection {

// What aligns a stack's frames. "none", "estimate", "calibrated".
enum class FrameAlignment {
  kNone,        // frames taken as registered pixel for pixel
  kEstimate,    // model estimated from the stack's frames (EstimateFocusBreathing)
  kCalibrated,  // model from the calibration bundle (calibration step focus_breathing)
};
const char* FrameAlignmentName(FrameAlignment a);
StatusOr<FrameAlignment> ParseFrameAlignment(const std::string& name);

// Below this largest corner displacement a stack is taken as registered and left as it is:
// warping would only resample (smooth) the frames, and an estimate on frames that do not move is
// itself off by about this much (neighbour registrations of one texture at different defocus err
// by ~5e-5 in scale per pair, and those errors are correlated).
inline constexpr double kNegligibleAlignmentPx = 0.5;

// An imported stack's default (no --alignment) leaves a stack whose measured motion moves no frame
// corner by this much as captured, and says so (AlignmentFigures::decision). Measured on the lens
// renderer's stacks (chain-evaluate moving, tuning seeds 8100-8105, 800x600 and 1600x1200):
// warping with the TRUE transforms changed the mean depth error by less than 1 % either way up
// to 1 px of corner motion (on the pixels both results measure), and improved every stack at
// 1.5 px of shift; a pure scale change was still neutral at 1.6 px (docs/alignment.md). Below this a warp
// gains nothing measurable, and a false one (a still stack's defocus read as motion) costs a
// misplaced depth map and several times the engine's time.
inline constexpr double kImportedWarpPaysPx = 1.5;

// The camera grid at stage z relative to the grid at reference_z_um (where it is the identity):
//   p_z = c + s(z) R(theta(z)) (p_ref - c) + d(z),
//   s(z) = 1 + scale_change_per_100um * (z - z_ref) / 100, theta(z) = rotation_rad_per_100um *
//   (z - z_ref) / 100, d(z) = shift_px_per_100um * (z - z_ref) / 100,
// c the image centre. Linear in z: the magnification of a non-telecentric objective changes
// with the working distance at first order, and a stage's lateral run-out over a few hundred um
// is a straight-line error at first order.
struct FocusBreathingModel {
  double reference_z_um = 0.0;
  cv::Size frame_size;                  // the camera grid the model was measured on
  double scale_change_per_100um = 0.0;  // relative magnification change, e.g. 0.02 = 2 %
  double rotation_rad_per_100um = 0.0;
  double shift_x_px_per_100um = 0.0;
  double shift_y_px_per_100um = 0.0;
  // How well the model explains the measurements: RMS over the agreeing neighbour pairs of the
  // (measured - model) pair transform at the frame corners, px; and the frames it came from.
  double fit_rms_px = 0.0;
  int frames = 0;
  // An estimate's test of its rates (EstimateFocusBreathing): the largest |median rate| over its
  // standard error from the pairs' scatter, and the Student t threshold each rate is held against
  // (1 % over the four rates). A rate under the threshold is 0 in the model; the stack is still
  // when the rest moves no corner by kNegligibleAlignmentPx. Both 0: not tested (a calibrated
  // model, or fewer than 4 pairs).
  double still_statistic = 0.0;
  double still_threshold = 0.0;
  // The largest frame-corner motion of the rates as measured, before the test (px; 0: not tested).
  double measured_corner_px = 0.0;

  cv::Point2d centre_px() const { return {(frame_size.width - 1) * 0.5, (frame_size.height - 1) * 0.5}; }
  SimilarityTransform At(double z_um) const;  // grid at z relative to the reference grid
  // Pixels of the grid at reference_frame_z_um -> pixels of the frame at z_um.
  cv::Matx23d FrameFromReference(double z_um, double reference_frame_z_um) const;
  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

// Largest displacement (px) of a frame corner over the frames at z_um under the model, relative
// to the middle frame.
double MaxCornerDisplacementPx(const FocusBreathingModel& model, const std::vector<double>& z_um);

struct StackAlignmentOptions {
  FrameRegistrationOptions registration;
  // Pairs of neighbours that fail to register are left out of the fit; when more than this share
  // fails (or fewer than 2 pairs remain) the estimate fails.
  double max_failed_pair_share = 0.4;
  // A pair whose registration differs from the model's transform for that pair by more than this
  // (RMS at the frame corners, px) disagrees with the model. Failed and disagreeing pairs together
  // may be at most max_failed_pair_share of the pairs: else the stack does not follow one model,
  // aligning with it would smear the depth map, and the estimate fails instead.
  double max_pair_residual_px = 1.0;
  // Neighbour pairs registered at once. 1: one pair after another, two frames in memory (load is
  // called once per frame, in order). Otherwise (0 = all hardware threads) pairs register
  // concurrently: load must be thread-safe and is called for both frames of each pair (so use it
  // on frames held in memory, e.g. a StackFrameDecoder's); the model is the same bit for bit.
  int threads = 1;
  // At most this many pairs are registered (0 = every neighbour pair). A longer stack registers
  // frames `stride` = ceil((n - 1) / max_pairs) apart (and its last frame to the last one taken):
  // the chain still spans every step, so a jump anywhere shows in one pair, at a fraction of the
  // cost. What it no longer sees is one frame out of line between two in line. 30 pairs are
  // plenty for the medians; frames two or three steps apart share most of their defocus.
  int max_pairs = 30;
  // Most stacks do not move (a telecentric objective, a good stage): the same estimate at half
  // the working size (max_side_px / 2, one pyramid level fewer; about a quarter of the cost)
  // runs first, and when its model moves no frame corner by kNegligibleAlignmentPx that model is
  // the answer (the aligner then leaves the frames as they are). Its own noise is about twice
  // the full estimate's (a still 60 x 1600x1200 stack: 0.36 px against 0.20 px), so a stack
  // moving by ~0.5-0.8 px may be left unaligned where the full estimate would warp it; that is
  // the size of motion the aligner already treats as negligible. Otherwise, or when it fails,
  // the full estimate runs as if it had not.
  bool coarse_first = true;
  // A model that moves no frame corner by this much is still (frames left as captured); the
  // coarse pass's answer when its model moves them less. See StackAligner::Create.
  double min_motion_px = kNegligibleAlignmentPx;
  Status Validate() const;
};

// Estimates the model from a stack: each frame is registered to its neighbour (neighbours share
// most of their defocus, so their structure is alike; a frame far from the reference may share
// none with it) and the per-pair changes of scale, rotation and shift per um are combined by their
// median (robust to a pair that registered wrongly); each pair is then checked against the model.
// load(i) returns frame i (CV_8UC1 or CV_16UC1); only two frames are held at a time.
// reference_z_um of the result: z_um.front(). Errors: INVALID_ARGUMENT for fewer than 3 frames
// or frames smaller than 32x32 px ("alignment needs ..."), FAILED_PRECONDITION naming the frame
// pairs when registration fails or the model does not fit.
StatusOr<FocusBreathingModel> EstimateFocusBreathing(const std::function<StatusOr<cv::Mat>(int)>& load,
                                                     const std::vector<double>& z_um,
                                                     const StackAlignmentOptions& options);


// The alignment of one stack: every frame's transform to the reference frame, set up before the
// first frame arrives; Warp resamples each frame as it comes.
struct AlignmentFigures {
  FrameAlignment alignment = FrameAlignment::kNone;
  int reference_frame = 0;
  double max_scale_change_percent = 0.0;  // max |s - 1| over the frames, relative to the reference
  double max_shift_px = 0.0;              // max shift of the image centre
  double seen_by_every_frame_percent = 100.0;
  // How the transforms were found: "model" (the focus-breathing model through z), "chain" (each
  // frame registered to its neighbour, chain_registration.h), "" for none.
  std::string method;
  // Set when the default alignment fell back to none, and why (the CLI prints it).
  std::string fallback_reason;
  // Set when the default chose a method other than its first one, and why (e.g. an imported
  // stack the linear-in-z model did not fit, registered as a chain instead).
  std::string decision;
  bool still = false;  // the transforms were measured and found indistinguishable from none
  // The still test's statistic and critical value (chain: ChainRegistration's; model estimated
  // from the stack: FocusBreathingModel's rate test; 0 when not tested), and the largest corner
  // displacement of the transforms (px).
  double still_statistic = 0.0;
  double still_threshold = 0.0;
  double max_corner_displacement_px = 0.0;
  // Each frame's transform, reference grid -> frame pixels (empty for none), and the frame size
  // its similarity figures are taken about (SimilarityOf about the image centre).
  std::vector<cv::Matx23d> frame_from_reference;
  cv::Size frame_size;
};

class StackAligner {
 public:
  // The reference frame is the middle one (index (n - 1) / 2): the largest transform to any
  // frame is then about half of the stack's, which keeps the most pixels seen by every frame.
  // z_um: the stack's frame positions; the model must match frame_size. A model that moves no
  // frame corner by min_motion_px leaves the frames as they are (still): kNegligibleAlignmentPx
  // for a rig's scan; an imported stack's default passes kImportedWarpPaysPx, measured: below it
  // even a warp with the true transforms gains nothing measurable in depth accuracy
  // (docs/alignment.md).
  static StatusOr<StackAligner> Create(const FocusBreathingModel& model, FrameAlignment alignment,
                                       const std::vector<double>& z_um, cv::Size frame_size,
                                       double min_motion_px = kNegligibleAlignmentPx);
  // From measured per-frame transforms (e.g. RegisterChain's): warps unless `warps` is false (a
  // stack its still test could not tell from motionless), then frames stay as they are.
  static StatusOr<StackAligner> FromTransforms(const std::vector<cv::Matx23d>& frame_from_reference,
                                               int reference_frame, FrameAlignment alignment, cv::Size frame_size,
                                               bool warps);

  // Frame `index` resampled onto the reference grid (bilinear; outside the frame the border is
  // replicated so no false edge enters the focus measure; those pixels are masked at Finish). A
  // new Mat of the frame's type (the engine may keep it); the frame itself when !warps().
  StatusOr<cv::Mat> Warp(const cv::Mat& frame, int index) const;
  // False when the model moves no frame corner by kNegligibleAlignmentPx: frames stay as they
  // are, every pixel counts as seen (seen_by_every_frame_percent 100) and results are exactly
  // those without alignment.
  bool warps() const { return warps_; }

  const cv::Mat& seen_by_every_frame() const { return seen_; }  // CV_8UC1, 255 = seen
  const AlignmentFigures& figures() const { return figures_; }
  const cv::Matx23d& frame_from_reference(int index) const { return maps_[size_t(index)]; }

 private:
  cv::Size size_;
  std::vector<cv::Matx23d> maps_;
  cv::Mat seen_;
  AlignmentFigures figures_;
  bool warps_ = true;
};

}  // namespace inspection
