#include "core/frame_statistics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace inspection {

namespace {
template <typename T>
FrameStatistics Compute(const cv::Mat& frame, int bit_depth) {
  const double full = double((1u << bit_depth) - 1u);
  const T sat = T(full);
  const T under = T(std::floor(0.02 * full));
  double sum = 0, sum2 = 0;
  uint64_t n_sat = 0, n_under = 0;
  for (int y = 0; y < frame.rows; ++y) {
    const T* row = frame.ptr<T>(y);
    // Integer row sums (exact, as the double sums of integers were; the loop vectorises).
    uint64_t rs = 0, rs2 = 0, rsat = 0, runder = 0;
    for (int x = 0; x < frame.cols; ++x) {
      const uint64_t v = row[x];
      rs += v;
      rs2 += v * v;
      rsat += row[x] >= sat;
      runder += row[x] < under;
    }
    sum += double(rs);
    sum2 += double(rs2);
    n_sat += rsat;
    n_under += runder;
  }
  const double n = double(frame.total());
  FrameStatistics s;
  if (n == 0) return s;
  const double scale = 255.0 / full;
  const double mean = sum / n;
  s.mean_grey = mean * scale;
  s.stddev_grey = std::sqrt(std::max(0.0, sum2 / n - mean * mean)) * scale;
  s.saturated_percent = 100.0 * double(n_sat) / n;
  s.underexposed_percent = 100.0 * double(n_under) / n;
  return s;
}
}  // namespace

FrameStatistics ComputeFrameStatistics(const cv::Mat& frame, int bit_depth) {
  if (frame.depth() == CV_16U) return Compute<uint16_t>(frame, std::clamp(bit_depth, 8, 16));
  return Compute<uint8_t>(frame, 8);
}

}  // namespace inspection
