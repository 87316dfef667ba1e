// Luminance of 8- and 16-bit BGR frames in exact 16-bit fixed point (core/io/colour.h).
#include "core/io/colour.h"

#include <cstdint>

namespace inspection {
namespace {

// 65535 * 65536 + 32768 < 2^32: the 16-bit sum fits uint32 as well as the 8-bit one.
template <typename P>
void LumaRows(const cv::Mat& bgr, cv::Mat* grey) {
  for (int y = 0; y < bgr.rows; ++y) {
    const P* __restrict s = bgr.ptr<P>(y);
    P* __restrict d = grey->ptr<P>(y);
    for (int x = 0; x < bgr.cols; ++x) {
      const uint32_t v = kLumaFixedBlue * s[3 * x] + kLumaFixedGreen * s[3 * x + 1] + kLumaFixedRed * s[3 * x + 2];
      d[x] = P((v + 32768u) >> 16);
    }
  }
}

static_assert(kLumaFixedRed + kLumaFixedGreen + kLumaFixedBlue == 65536u, "grey must map to itself");

}  // namespace

StatusOr<cv::Mat> LuminanceOf(const cv::Mat& frame) {
  if (frame.empty()) return Status::InvalidArgument("frame is empty");
  switch (frame.type()) {
    case CV_8UC1:
    case CV_16UC1:
      return frame;
    case CV_8UC3: {
      cv::Mat grey(frame.size(), CV_8UC1);
      LumaRows<uint8_t>(frame, &grey);
      return grey;
    }
    case CV_16UC3: {
      cv::Mat grey(frame.size(), CV_16UC1);
      LumaRows<uint16_t>(frame, &grey);
      return grey;
    }
    default:
      return Status::InvalidArgument("frame is " + cv::typeToString(frame.type()) +
                                     "; expected 8- or 16-bit grey (1 channel) or colour (3 channels)");
  }
}

}  // namespace inspection
