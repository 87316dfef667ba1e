// Colour frames for shape from focus: the luminance focus is measured on (thesis 3.1.3 measures
// grey values; colour cameras deliver three channels), ITU-R BT.709 weights.
//
// Why BT.709 (0.2126 R + 0.7152 G + 0.0722 B) and not BT.601 (0.299, 0.587, 0.114): nearly
// every colour camera, PNG and JPEG encodes sRGB, whose primaries are BT.709's, and these
// weights are the luminance of exactly those primaries (BT.601's belong to the old NTSC
// primaries and survive in JPEG's YCbCr only as a coding transform). They also weight green
// most, the channel a Bayer sensor samples twice as densely and so the least noisy one, and
// blue least, the noisiest. The weights are applied to the stored (gamma-encoded) code
// values, i.e. luma Y', as for grey frames, which the engine also takes as stored.
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"

namespace inspection {

inline constexpr double kLumaWeightRed = 0.2126;
inline constexpr double kLumaWeightGreen = 0.7152;
inline constexpr double kLumaWeightBlue = 0.0722;

// The weights in 16-bit fixed point; they sum to exactly 65536, so a grey colour (R = G = B = v)
// maps to v exactly and the result never exceeds the input range.
inline constexpr uint32_t kLumaFixedRed = 13933;    // round(0.2126 * 65536)
inline constexpr uint32_t kLumaFixedGreen = 46871;  // round(0.7152 * 65536)
inline constexpr uint32_t kLumaFixedBlue = 4732;    // 65536 - the two above (round() gives 4732 too)

// Grey image for focus measurement: CV_8UC1 / CV_16UC1 frames are returned as they are (sharing
// the pixels); CV_8UC3 / CV_16UC3 frames, in OpenCV's BGR channel order, become
// Y = 0.2126 R + 0.7152 G + 0.0722 B rounded to the nearest code value of the same depth
// (CV_8UC1 / CV_16UC1). Other types: INVALID_ARGUMENT.
StatusOr<cv::Mat> LuminanceOf(const cv::Mat& frame);

}  // namespace inspection
