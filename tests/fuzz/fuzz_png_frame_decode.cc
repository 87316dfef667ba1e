// libFuzzer target: a stack frame's file bytes as a client uploads them, through the plain-PNG
// fast path (core/io/png_frame_decode.h), which parses chunks and unfilters rows itself. Whatever it
// accepts must be OpenCV's (libpng's) decoding of the same bytes, pixel for pixel, whenever
// OpenCV decodes them too.
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string_view>

#include "core/io/png_frame_decode.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const cv::Mat fast = inspection::DecodePlainPng(std::string_view(reinterpret_cast<const char*>(data), size));
  if (fast.empty() || size > size_t(1) << 24) return 0;
  const cv::Mat bytes(1, int(size), CV_8UC1, const_cast<uint8_t*>(data));
  const cv::Mat ref = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
  if (!ref.empty() && (ref.type() != fast.type() || ref.size() != fast.size() || cv::norm(ref, fast, cv::NORM_INF) != 0)) {
    __builtin_trap();
  }
  return 0;
}
