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
#include <functional>
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

  // Rows [y0, y1) of a frame's score into *rows (y1 - y0 rows of the frame's width).
  using ScoreRowsFn = std::function<Status(int y0, int y1, cv::Mat* rows)>;
  // PushFrame(frame, score) with the score asked for band by band (band_rows >= 1 rows each, in
  // order), so that no whole-frame score exists: for a 24 MP frame a CV_32SC1 score is 96 MB
  // beside the composer's 11 bytes per pixel. The same result as PushFrame with the whole score.
  Status PushFrameInBands(const cv::Mat& frame, const ScoreRowsFn& score_rows, int band_rows);

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
  // Checks of a push: the frame's type and size; a score band's size (count rows), its type and,
  // once a frame was pushed, that it is the first frame's.
  Status CheckFrame(const cv::Mat& frame) const;
  Status CheckScoreRows(const cv::Mat& rows, int count) const;
  // Rows [y0, y0 + score.rows) of the frame; score's row 0 is frame row y0.
  template <typename P>
  void Update(const cv::Mat& frame, const cv::Mat& score, int y0);
  void FirstRows(const cv::Mat& frame, const cv::Mat& score, int y0);

  cv::Mat best_;  // CV_32FC1, or CV_32SC1 for integer scores (exact: no rounding of int32 sums)
  cv::Mat image_;
  cv::Mat index_;
  int score_type_ = -1;
  int frames_pushed_ = 0;
};

// Rows [y0, y1) of FocusScore(grey, ...) bit for bit, computed from those rows and a halo where
// the measure allows it (FocusMeasureIsRowLocal, core/sff/focus_measure.h; the integer Tenengrad
// of 8-bit frames is exact too), else from the whole frame's score.
Status FocusScoreRows(const cv::Mat& grey, FocusMeasure measure, int window_px, int y0, int y1, cv::Mat* rows);

// The focus map the SFF engine compares for this grey frame (CV_8UC1 / CV_16UC1, e.g. a colour
// frame's luminance from core/io/colour.h): the engine's integer Tenengrad kernel for 8-bit frames
// with Tenengrad (CV_32SC1, ComputeTenengradU8), ComputeFocusMeasure otherwise (CV_32FC1).
Status FocusScore(const cv::Mat& grey, FocusMeasure measure, int window_px, cv::Mat* score);

// Score for a depth map known before the pass: -|z_um - depth_um| (CV_32FC1), so each pixel takes
// the frame nearest its depth. Pixels without depth (NaN) score the same in every frame, so they
// keep the first frame pushed. depth_um: CV_32FC1.
Status DepthProximityScore(const cv::Mat& depth_um, double z_um, cv::Mat* score);

}  // namespace inspection
