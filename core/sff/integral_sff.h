// Integral shape from focus (thesis 5.4, 6.4): the integral image of a stack (the mean of its
// frames, accumulated as they arrive), the frame noise estimated on the way, the all-in-focus
// texture restored from the integral image by the calibrated IPSF (eq. 5.23) with a Wiener
// shrinkage whose weight comes from that noise, and the reconstructions ISFF, ISFF-FAST and
// ISFF-GT with the correlation focus measure (core/sff/ncc_focus.h, eq. 5.24-5.26).
//
// How a streaming scan gets the template: the NCC of eq. 5.25 needs the restored image before
// the first frame is correlated, and the restored image needs the integral image of the whole
// stack. ReconstructIntegralSffStack therefore makes two passes over a stored stack (pass 1:
// IntegralImageAccumulator while the frames arrive; pass 2: NccFocusEngine over the frames read
// back), each O(pixels) in memory. A rig that can expose one frame while the stage sweeps the
// scan range (Nagahara's integral photograph, thesis 5.4) gives the integral image before the
// stack, and then one pass suffices: RestoreFocusedImage on that image, then NccFocusEngine
// while the frames arrive.
#pragma once

#include <filesystem>
#include <limits>
#include <opencv2/core.hpp>
#include <vector>

#include "core/calibration/calibration_bundle.h"
#include "core/calibration/integral_psf.h"
#include "core/sff/ncc_focus.h"
#include "core/sff/stack_reconstruct.h"
#include "core/util/status.h"

namespace inspection {

// Robust noise of one frame (grey units of the frame): Immerkaer's 3 x 3 mask (second
// differences in x and y, blind to locally planar grey values; response variance 36 sigma^2 for
// white noise) on every second pixel of every second row, sigma = median |response| / (0.6745 *
// 6), with the median interpolated inside its integer bin for 8/16-bit frames (otherwise
// quantisation makes it jump by 25 %). Pixels at 0 or at the frame's maximum (saturated) are
// left out. Texture in focus raises the estimate; defocused frames show almost only noise.
double EstimateFrameNoiseSigma(const cv::Mat& frame);

// The integral image I_int of thesis 5.4.1 (the mean of the stack's frames) accumulated frame
// by frame in double precision, with each frame's noise. O(pixels); not thread-safe.
class IntegralImageAccumulator {
 public:
  // Frames: CV_8UC1, CV_16UC1 or CV_32FC1, all of the first frame's size and type.
  Status Add(const cv::Mat& frame);
  int frame_count() const { return int(noise_.size()); }
  // CV_32FC1 mean of the frames; FAILED_PRECONDITION before the first frame.
  StatusOr<cv::Mat> IntegralImage() const;
  // Noise of one frame: the median over the frames of EstimateFrameNoiseSigma. Most frames of a
  // stack are out of focus at most pixels, so the median is the sensor noise even when a few
  // frames (a plane normal to the axis) are sharp everywhere. 0 before the first frame.
  double FrameNoiseSigma() const;

 private:
  cv::Mat sum_;  // CV_64FC1
  int type_ = -1;
  std::vector<double> noise_;
};

enum class IpsfRestoration {
  kPlain,          // eq. 5.23 alone: I_int * ipsf
  kNoiseAdaptive,  // eq. 5.23, then a Wiener shrinkage weighted by the stack's noise (default)
};

struct IpsfRestorationOptions {
  IpsfRestoration method = IpsfRestoration::kNoiseAdaptive;
  // Noise of one frame (grey units); NaN = estimated from the stack (IntegralImageAccumulator).
  double frame_noise_sigma = std::numeric_limits<double>::quiet_NaN();
  // Half-width (bins) of the box that smooths the restored image's power spectrum before the
  // noise power is subtracted from it (5 x 5 bins: the spectrum estimate has ~20 % scatter).
  int spectrum_smoothing_bins = 2;

  Status Validate() const;
};

// Restores the all-in-focus texture (CV_32FC1, size of integral_image) from the integral image
// of a stack of frame_count frames whose per-frame noise is frame_noise_sigma:
//   R = I_int * ipsf (eq. 5.23), then, kNoiseAdaptive, in the DCT domain (even extension, so no
//   wrap-around edges) R'(f) = R(f) g(f) with the Wiener gain of the integral image
//     W(f) = max(0, 1 - N / P(f)),  N = frame_noise_sigma^2 / frame_count
//   (the frames' noise averaged by the integral; P(f) the integral image's smoothed power
//   spectrum, estimated as R's divided by |IPSF(f)|^2), and g = min(1, W / W_cal), W_cal the
//   same gain for the calibration's noise ipsf.integral_noise_sigma^2, which the least-squares
//   kernel has damped already. The regularisation weight at every frequency is thus the
//   stack's estimated noise-to-signal ratio, nothing tuned per specimen; a scan as quiet as the
//   calibration (or quieter) gets eq. 5.23 unchanged.
StatusOr<cv::Mat> RestoreFocusedImage(const cv::Mat& integral_image, int frame_count, double frame_noise_sigma,
                                      const IntegralPsf& ipsf, const IpsfRestorationOptions& options);

struct IsffOptions {
  // Windows (thesis 6.4: 7 x 7), interpolation, confidence, ISFF-FAST (stop_at_first_maximum,
  // stop_threshold = "fast_threshold", default 0.9), threads.
  NccFocusOptions ncc;
  IpsfRestorationOptions restoration;

  Status Validate() const;
};

struct IsffResult {
  DepthResult depth;
  cv::Mat focused_template;        // CV_32FC1: the restored (ISFF) or given (ISFF-GT) template
  double frame_noise_sigma = 0.0;  // grey units: estimated from the stack, or as given
  NccWorkCounters work;            // ISFF-FAST's saving: work.tile_frames / work.tile_frames_full
  cv::Mat max_index;               // CV_16SC1: discrete maximum per pixel (Table 6.9's wrong maxima)
  cv::Mat frames_searched;         // CV_16SC1: frames each pixel's search took (ISFF-FAST stops early)
  double integral_seconds = 0.0;   // pass 1: integral image and noise
  double restore_seconds = 0.0;    // eq. 5.23 + shrinkage
  double focus_seconds = 0.0;      // pass 2 in all: NCC, maximum search, interpolation (+ decoding)
  // Parts of pass 2: engine set-up (template statistics, state memory), the search over the
  // frames (NCC and maximum: what ISFF-FAST shortens), interpolation and confidence.
  double search_setup_seconds = 0.0;
  double search_seconds = 0.0;
  double search_finish_seconds = 0.0;
  // Process CPU time of the search (all threads; std::clock): on a shared machine the wall
  // time also counts other jobs.
  double search_cpu_seconds = 0.0;
};

// FAILED_PRECONDITION naming the calibration step when the bundle (may be null) has no IPSF.
Status CheckIntegralPsfFor(const CalibrationBundle* bundle);

// ISFF (ISFF-FAST with options.ncc.stop_at_first_maximum) on a stack in memory: frames >= 3,
// all CV_8UC1 or all CV_16UC1 of one size, z_um strictly monotonic, one per frame. ipsf null ->
// FAILED_PRECONDITION (the integral_psf calibration step is missing).
StatusOr<IsffResult> ReconstructIntegralSff(const std::vector<cv::Mat>& frames, const std::vector<double>& z_um,
                                            const IntegralPsf* ipsf, const IsffOptions& options);

// ISFF-GT (thesis 6.4.3): the same focus measure with a given template, e.g. the ground-truth
// texture of the simulated rig; single pass. focused_template: frame size, single channel.
StatusOr<IsffResult> ReconstructIntegralSffWithTemplate(const std::vector<cv::Mat>& frames,
                                                        const std::vector<double>& z_um,
                                                        const cv::Mat& focused_template, const IsffOptions& options);

// ISFF on a stack folder (core/io/stack.h) in two streaming passes (see the top of this file):
// O(pixels) memory whatever the frame count. Errors name the frame or manifest field.
StatusOr<IsffResult> ReconstructIntegralSffStack(const std::filesystem::path& dir, const IntegralPsf* ipsf,
                                                 const IsffOptions& options);

// The same two passes on frames from `source` (as stored, by index; a colour frame is reduced to
// its luminance as LoadStackFrame does), e.g. a StackFrameDecoder (core/io/stack_frame_decoder.h)
// fed from memory: the same result bit for bit. Each frame is asked for twice, in z order, and
// released after its pass-2 read. manifest: the stack's (frames, z).
StatusOr<IsffResult> ReconstructIntegralSffFrames(const StackManifest& manifest, const StackFrameSource& source,
                                                  const IntegralPsf* ipsf, const IsffOptions& options);

}  // namespace inspection
