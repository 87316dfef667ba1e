// All-in-focus image in colour (thesis 3.1: each pixel taken from the frame where it is
// sharpest), composed while the frames stream in: per pixel, the colour of the best-scoring frame
// so far. State is O(pixels) (the best score, the kept pixel and its frame index), never the
// stack, so a scan or an upload can compose it beside the SFF engine.
//
// Scores: FocusScore reproduces the SFF engine's own choice (the same focus values of the same
// luminance, the same "first maximum wins" rule), so the colour image's luminance equals the
// engine's grey all-in-focus image; DepthProximityScore takes, per pixel, the frame nearest in z
// to a depth map known beforehand (a second pass over a stored stack, e.g. after refinement).
#pragma once

#include <cstddef>
#include <opencv2/core.hpp>

#include "core/sff/sff_engine.h"
#include "core/util/status.h"

namespace inspection {

// Not thread-safe; one producer pushes frames in any order (the result does not depend on z,
// only on the scores and, for equal scores, on which frame came first).
class AllInFocusComposer {
 public:
  // frame_type: CV_8UC1, CV_16UC1, CV_8UC3 or CV_16UC3 (colour in OpenCV's BGR order).
  static StatusOr<AllInFocusComposer> Create(cv::Size frame_size, int frame_type);

  // score: CV_32FC1 or CV_32SC1 of the frame size, higher = sharper. The first frame initialises
  // every pixel; later a pixel takes this frame's value where score > its best so far (strictly,
  // so the first of equal maxima wins, as in the engine). Errors name what does not match.
  Status PushFrame(const cv::Mat& frame, const cv::Mat& score);

  int frames_pushed() const { return frames_pushed_; }
  // Of frame_type; all zero before the first frame. Shares the composer's pixels: clone to keep
  // it while pushing on.
  const cv::Mat& all_in_focus() const { return image_; }
  // CV_32SC1: per pixel, the push index (0 = first frame pushed) the value was taken from.
  const cv::Mat& frame_index() const { return index_; }
  // Bytes of per-pixel state: 4 (score) + 4 (index) + the pixel (1 to 6 bytes).
  size_t state_bytes() const;

 private:
  AllInFocusComposer() = default;
  template <typename P>
  void Update(const cv::Mat& frame, const cv::Mat& score);

  cv::Mat best_;  // CV_32FC1, or CV_32SC1 for integer scores (exact: no rounding of int32 sums)
  cv::Mat image_;
  cv::Mat index_;
  int score_type_ = -1;
  int frames_pushed_ = 0;
};

// The focus map the SFF engine compares for this grey frame (CV_8UC1 / CV_16UC1, e.g. a colour
// frame's luminance from core/io/colour.h): the engine's integer Tenengrad kernel for 8-bit frames
// with Tenengrad (CV_32SC1, ComputeTenengradU8), ComputeFocusMeasure otherwise (CV_32FC1).
Status FocusScore(const cv::Mat& grey, FocusMeasure measure, int window_px, cv::Mat* score);

// Score for a depth map known before the pass: -|z_um - depth_um| (CV_32FC1), so each pixel takes
// the frame nearest its depth. Pixels without depth (NaN) score the same in every frame, so they
// keep the first frame pushed. depth_um: CV_32FC1.
Status DepthProximityScore(const cv::Mat& depth_um, double z_um, cv::Mat* score);

}  // namespace inspection
