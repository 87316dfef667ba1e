// Running per-pixel argmax of a score, keeping the winning frame's pixel (core/sff/all_in_focus.h).
#include "core/sff/all_in_focus.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/sff/focus_measure.h"

namespace inspection {

StatusOr<AllInFocusComposer> AllInFocusComposer::Create(cv::Size frame_size, int frame_type) {
  if (frame_size.width <= 0 || frame_size.height <= 0) return Status::InvalidArgument("frame size must be positive");
  if (frame_type != CV_8UC1 && frame_type != CV_16UC1 && frame_type != CV_8UC3 && frame_type != CV_16UC3) {
    return Status::InvalidArgument("frame type " + cv::typeToString(frame_type) +
                                   " is not 8- or 16-bit grey or colour (3 channels)");
  }
  AllInFocusComposer c;
  c.image_ = cv::Mat::zeros(frame_size, frame_type);
  c.index_ = cv::Mat::zeros(frame_size, CV_32SC1);
  return c;
}

size_t AllInFocusComposer::state_bytes() const { return image_.total() * (4 + 4 + image_.elemSize()); }

template <typename P>
void AllInFocusComposer::Update(const cv::Mat& frame, const cv::Mat& score, int y0) {
  const int cn = frame.channels();
  const int32_t k = frames_pushed_;
  for (int r = 0; r < score.rows; ++r) {
    const int y = y0 + r;
    const P* src = frame.ptr<P>(y);
    P* dst = image_.ptr<P>(y);
    int32_t* idx = index_.ptr<int32_t>(y);
    if (score_type_ == CV_32SC1) {
      const int32_t* s = score.ptr<int32_t>(r);
      int32_t* b = best_.ptr<int32_t>(y);
      for (int x = 0; x < frame.cols; ++x) {
        if (s[x] > b[x]) {
          b[x] = s[x];
          idx[x] = k;
          for (int c = 0; c < cn; ++c) dst[cn * x + c] = src[cn * x + c];
        }
      }
    } else {
      const float* s = score.ptr<float>(r);
      float* b = best_.ptr<float>(y);
      for (int x = 0; x < frame.cols; ++x) {
        if (s[x] > b[x]) {  // NaN scores never win
          b[x] = s[x];
          idx[x] = k;
          for (int c = 0; c < cn; ++c) dst[cn * x + c] = src[cn * x + c];
        }
      }
    }
  }
}

void AllInFocusComposer::FirstRows(const cv::Mat& frame, const cv::Mat& score, int y0) {
  const cv::Range rows(y0, y0 + score.rows);
  if (best_.empty()) best_.create(image_.size(), score.type());
  cv::Mat best = best_.rowRange(rows);
  score.copyTo(best);
  if (score.type() == CV_32FC1) {
    // A NaN first score must not block every later frame.
    const cv::Mat nan_mask = ~(best == best);  // CMP_NE is false for NaN
    best.setTo(-std::numeric_limits<float>::infinity(), nan_mask);
  }
  cv::Mat image = image_.rowRange(rows);
  frame.rowRange(rows).copyTo(image);
  index_.rowRange(rows).setTo(0);
}

Status AllInFocusComposer::CheckFrame(const cv::Mat& frame) const {
  const std::string at = "frame " + std::to_string(frames_pushed_) + ": ";
  if (frame.type() != image_.type()) {
    return Status::InvalidArgument(at + "type " + cv::typeToString(frame.type()) + " differs from the composer's " +
                                   cv::typeToString(image_.type()));
  }
  if (frame.size() != image_.size()) {
    return Status::InvalidArgument(at + "frame and score must be " + std::to_string(image_.cols) + "x" +
                                   std::to_string(image_.rows));
  }
  return Status::Ok();
}

Status AllInFocusComposer::CheckScoreRows(const cv::Mat& rows, int count) const {
  const std::string at = "frame " + std::to_string(frames_pushed_) + ": ";
  if (rows.cols != image_.cols || rows.rows != count) {
    return Status::InvalidArgument(at + "frame and score must be " + std::to_string(image_.cols) + "x" +
                                   std::to_string(image_.rows));
  }
  if (rows.type() != CV_32FC1 && rows.type() != CV_32SC1) {
    return Status::InvalidArgument(at + "score must be CV_32FC1 or CV_32SC1");
  }
  if (score_type_ >= 0 && rows.type() != score_type_) {
    return Status::InvalidArgument(at + "score type differs from the first frame's (all integer or all float)");
  }
  return Status::Ok();
}

Status AllInFocusComposer::PushFrame(const cv::Mat& frame, const cv::Mat& score) {
  INSPECT_RETURN_IF_ERROR(CheckFrame(frame));
  if (score.size() != image_.size()) return CheckScoreRows(score, image_.rows);  // names the sizes
  return PushFrameInBands(
      frame,
      [&](int y0, int y1, cv::Mat* rows) {
        *rows = score.rowRange(y0, y1);
        return Status::Ok();
      },
      image_.rows);
}

Status AllInFocusComposer::PushFrameInBands(const cv::Mat& frame, const ScoreRowsFn& score_rows, int band_rows) {
  if (band_rows < 1) return Status::InvalidArgument("band_rows must be >= 1");
  INSPECT_RETURN_IF_ERROR(CheckFrame(frame));
  for (int y0 = 0; y0 < image_.rows; y0 += band_rows) {
    const int y1 = std::min(image_.rows, y0 + band_rows);
    cv::Mat rows;
    INSPECT_RETURN_IF_ERROR(score_rows(y0, y1, &rows));
    // A bad band after the first leaves the frame half composed: a bug of the caller's own score
    // function (the whole-score PushFrame checks before its one band), so reported, not undone.
    INSPECT_RETURN_IF_ERROR(CheckScoreRows(rows, y1 - y0));
    if (frames_pushed_ == 0) {
      score_type_ = rows.type();
      FirstRows(frame, rows, y0);
    } else if (frame.depth() == CV_8U) {
      Update<uint8_t>(frame, rows, y0);
    } else {
      Update<uint16_t>(frame, rows, y0);
    }
  }
  ++frames_pushed_;
  return Status::Ok();
}

Status FocusScoreRows(const cv::Mat& grey, FocusMeasure measure, int window_px, int y0, int y1, cv::Mat* rows) {
  if (y0 < 0 || y1 > grey.rows || y0 >= y1) return Status::InvalidArgument("rows out of the frame");
  const bool row_local = FocusMeasureIsRowLocal(measure);
  const int halo = row_local ? FocusMeasureHaloRows(window_px) : 0;
  const int h0 = row_local ? std::max(0, y0 - halo) : 0, h1 = row_local ? std::min(grey.rows, y1 + halo) : grey.rows;
  cv::Mat score;
  INSPECT_RETURN_IF_ERROR(FocusScore(grey.rowRange(h0, h1), measure, window_px, &score));
  *rows = score.rowRange(y0 - h0, y1 - h0);
  return Status::Ok();
}

Status FocusScore(const cv::Mat& grey, FocusMeasure measure, int window_px, cv::Mat* score) {
  if (grey.type() != CV_8UC1 && grey.type() != CV_16UC1) {
    return Status::InvalidArgument("focus score needs an 8- or 16-bit grey frame (a colour frame's luminance)");
  }
  if (measure == FocusMeasure::kTenengrad && grey.type() == CV_8UC1) {
    return ComputeTenengradU8(grey, window_px, score);
  }
  return ComputeFocusMeasure(grey, measure, window_px, score);
}

Status DepthProximityScore(const cv::Mat& depth_um, double z_um, cv::Mat* score) {
  if (depth_um.empty() || depth_um.type() != CV_32FC1) return Status::InvalidArgument("depth_um must be CV_32FC1");
  if (!std::isfinite(z_um)) return Status::InvalidArgument("z_um must be finite");
  cv::Mat out(depth_um.size(), CV_32FC1);
  const float lowest = std::numeric_limits<float>::lowest();
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    float* s = out.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      s[x] = std::isfinite(d[x]) ? -float(std::abs(double(d[x]) - z_um)) : lowest;
    }
  }
  *score = out;
  return Status::Ok();
}

}  // namespace inspection
