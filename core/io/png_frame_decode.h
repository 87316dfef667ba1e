// A fast path for the most common stack frame file, a plain PNG (grey or RGB, 8 or 16 bit, not
// interlaced), decoded in one pass with libdeflate into the frame's own buffer: the frames of an
// upload decode while it arrives (core/io/stack_frame_decoder.h), and PNG inflation was most of the
// end-to-end time of a reconstruction. The pixels are cv::imread's bit for bit (PNG is
// lossless): the same channel order (BGR) and byte order (native) as cv::IMREAD_UNCHANGED.
#pragma once

#include <opencv2/core.hpp>
#include <cstddef>
#include <string_view>

namespace inspection {

// The image in `file` (a whole PNG file's bytes): CV_8UC1, CV_16UC1, CV_8UC3 or CV_16UC3 (BGR).
// An empty Mat when the file is anything else or anything this path does not take (palette,
// alpha, transparency chunk, bit depth < 8, interlace, more than max_raw_bytes of raw rows, a
// bad checksum, truncated or corrupt data):
// the caller then decodes it the general way (cv::imread), which also names what is wrong.
// max_raw_bytes: the largest inflated size (rows with their filter bytes) this path allocates from
// the header; larger images take the general path, whose decoder applies OpenCV's size limits.
inline constexpr size_t kPngFastPathMaxRawBytes = size_t(1) << 28;  // 256 MiB
cv::Mat DecodePlainPng(std::string_view file, size_t max_raw_bytes = kPngFastPathMaxRawBytes);
// Decoding keeps its per-thread byte buffers from frame to frame up to this size; a larger
// frame's buffer is freed after use.
inline constexpr size_t kPngFastPathKeptBufferBytes = size_t(64) << 20;

}  // namespace inspection
