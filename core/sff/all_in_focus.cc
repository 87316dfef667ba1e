// Running per-pixel argmax of a score, keeping the winning frame's pixel (core/sff/all_in_focus.h).
#include "core/sff/all_in_focus.h"

#include <cmath>
#include <limits>

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
void AllInFocusComposer::Update(const cv::Mat& frame, const cv::Mat& score) {
  const int cn = frame.channels();
  const int32_t k = frames_pushed_;
  for (int y = 0; y < frame.rows; ++y) {
    const P* src = frame.ptr<P>(y);
    P* dst = image_.ptr<P>(y);
    int32_t* idx = index_.ptr<int32_t>(y);
    if (score_type_ == CV_32SC1) {
      const int32_t* s = score.ptr<int32_t>(y);
      int32_t* b = best_.ptr<int32_t>(y);
      for (int x = 0; x < frame.cols; ++x) {
        if (s[x] > b[x]) {
          b[x] = s[x];
          idx[x] = k;
          for (int c = 0; c < cn; ++c) dst[cn * x + c] = src[cn * x + c];
        }
      }
    } else {
      const float* s = score.ptr<float>(y);
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

Status AllInFocusComposer::PushFrame(const cv::Mat& frame, const cv::Mat& score) {
  const std::string at = "frame " + std::to_string(frames_pushed_) + ": ";
  if (frame.type() != image_.type()) {
    return Status::InvalidArgument(at + "type " + cv::typeToString(frame.type()) + " differs from the composer's " +
                                   cv::typeToString(image_.type()));
  }
  if (frame.size() != image_.size() || score.size() != image_.size()) {
    return Status::InvalidArgument(at + "frame and score must be " + std::to_string(image_.cols) + "x" +
                                   std::to_string(image_.rows));
  }
  if (score.type() != CV_32FC1 && score.type() != CV_32SC1) {
    return Status::InvalidArgument(at + "score must be CV_32FC1 or CV_32SC1");
  }
  if (frames_pushed_ == 0) {
    score_type_ = score.type();
    score.copyTo(best_);
    if (score_type_ == CV_32FC1) {
      // A NaN first score must not block every later frame.
      const cv::Mat nan_mask = ~(best_ == best_);  // CMP_NE is false for NaN
      best_.setTo(-std::numeric_limits<float>::infinity(), nan_mask);
    }
    frame.copyTo(image_);
    index_.setTo(0);
    ++frames_pushed_;
    return Status::Ok();
  }
  if (score.type() != score_type_) {
    return Status::InvalidArgument(at + "score type differs from the first frame's (all integer or all float)");
  }
  if (frame.depth() == CV_8U)
    Update<uint8_t>(frame, score);
  else
    Update<uint16_t>(frame, score);
  ++frames_pushed_;
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
