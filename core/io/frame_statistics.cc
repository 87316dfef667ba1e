#include "core/io/frame_statistics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/io/internal/frame_stats_kernel.h"

namespace inspection {

namespace {

// Rows are summed in runs of at most kRun pixels (core/io/internal/frame_stats_kernel.h).
using frame_stats_internal::kRun;
using frame_stats_internal::RunSums;

template <typename T>
FrameStatistics Compute(const cv::Mat& frame, int bit_depth) {
  const double full = double((1u << bit_depth) - 1u);
  const T sat = T(full);
  const T under = T(std::floor(0.02 * full));
  // Exact integer sums per run, accumulated in double (as the double sums of integers were).
  double sum = 0, sum2 = 0;
  uint64_t n_sat = 0, n_under = 0;
  static const frame_stats_internal::SumRun8Fn sum_run8 = frame_stats_internal::PickSumRun8();
  static const frame_stats_internal::SumRun16Fn sum_run16 = frame_stats_internal::PickSumRun16();
  for (int y = 0; y < frame.rows; ++y) {
    const T* row = frame.ptr<T>(y);
    for (int x0 = 0; x0 < frame.cols; x0 += kRun) {
      const int n = std::min(kRun, frame.cols - x0);
      RunSums r;
      if constexpr (sizeof(T) == 1) {
        r = sum_run8(row + x0, n, under);
      } else {
        r = sum_run16(row + x0, n, sat, under);
      }
      sum += double(r.sum);
      sum2 += double(r.sum2);
      n_sat += r.saturated;
      n_under += r.under;
    }
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
  // A 16-bit frame in a stack that states 8 significant bits (stack.json's default, e.g. an
  // imported folder of 16-bit TIFFs) uses its full range: full scale 255 would count nearly every
  // pixel as saturated.
  if (frame.depth() == CV_16U) return Compute<uint16_t>(frame, bit_depth <= 8 ? 16 : std::min(bit_depth, 16));
  return Compute<uint8_t>(frame, 8);
}

}  // namespace inspection
