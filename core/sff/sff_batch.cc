// Batch SFF for a stack already in memory (thesis 3.1, SffEngine::ReconstructInMemory): cache-
// sized tiles run across all frames, so the per-pixel state never leaves the cache; the same
// kernels as the streaming engines, so the result is bit-identical to pushing the frames.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>

#include "core/util/cpu_features.h"
#include "core/util/parallel_for.h"
#include "core/sff/sff_engine.h"
#include "core/sff/internal/sff_engine_internal.h"
#include "core/io/stack.h"
#include "core/sff/internal/tenengrad_kernel.h"

namespace inspection {

namespace sff_internal {
namespace {

// 8-bit Tenengrad over inputs that passed ReconstructInMemory's checks. Tiles across all frames:
// each worker keeps one tile's state, runs every frame over it, then interpolates the tile; the
// same kernels as PushFrame, so the result is bit-identical.
DepthResult ReconstructFusedTiles(const SffOptions& options, const std::vector<cv::Mat>& frames,
                                  const std::vector<double>& z_um) {
  const cv::Size size = frames[0].size();
  const int type = frames[0].type();
  const int threads = ResolveThreads(options.threads);
  const bool compact = UseCompact(options, type);
  const int j = options.interpolation == DepthInterpolation::kLineFit ? options.linefit_half_width : 1;
  const int tiles_x = (size.width + kTileW - 1) / kTileW, tiles_y = (size.height + kBatchTileH - 1) / kBatchTileH;
  const int n_tiles = tiles_x * tiles_y;
  DepthOutputs out;
  out.depth.create(size, CV_32F);
  out.confidence.create(size, CV_32F);
  out.aif.create(size, type);
  const int workers = std::max(1, std::min(threads, n_tiles));
  std::vector<CompactState> compact_states(compact ? size_t(workers) : 0);
  std::vector<StatePlanes<int32_t, uint8_t>> states(compact ? 0 : size_t(workers));
  std::vector<TenengradScratch> scratch(static_cast<size_t>(workers));
  std::vector<std::vector<int32_t>> volumes(static_cast<size_t>(workers));
  for (int w = 0; w < workers; ++w) {
    if (compact)
      compact_states[size_t(w)].Allocate(kTileW, kBatchTileH, options.use_simd, options.use_avx512);
    else
      states[size_t(w)].Allocate(kTileW, kBatchTileH, j, options.use_simd);
    scratch[size_t(w)].Reserve(options.window_px);
    volumes[size_t(w)].resize(size_t(kTileW) * kBatchTileH * kFrameChunk);
  }
  const bool avx2 = options.use_simd && CpuHasAvx2();
  const int n = int(frames.size());
  const std::vector<float> zf(z_um.begin(), z_um.end());
  std::atomic<size_t> valid{0};
  ParallelFor(n_tiles, workers, [&](int t, int worker) {
    int32_t* vol = volumes[size_t(worker)].data();
    if (compact) compact_states[size_t(worker)].Reset();
    const int x0 = (t % tiles_x) * kTileW, y0 = (t / tiles_x) * kBatchTileH;
    const int tw = std::min(kTileW, size.width - x0), th = std::min(kBatchTileH, size.height - y0);
    for (int k0 = 0; k0 < n; k0 += kFrameChunk) {
      const int k1 = std::min(n, k0 + kFrameChunk);
      for (int k = k0; k < k1; ++k) {
        const cv::Mat* next = k + 1 < n ? &frames[size_t(k) + 1] : nullptr;
        FocusRowsToVolume(avx2, frames[size_t(k)], k - k0, x0, y0, tw, th, options.window_px, scratch[size_t(worker)],
                          vol, next);
      }
      // Each state row stays in L1 (compact state with AVX2 / AVX-512: in registers) while the
      // chunk's frames update it, in frame order.
      const size_t slot_stride = size_t(kBatchTileH) * kTileW;
      for (int y = 0; y < th; ++y) {
        const size_t off = size_t(y) * kTileW;
        const int32_t* vol_row = vol + size_t(y) * kTileW;
        const uint8_t* pix_rows[kFrameChunk];
        for (int k = k0; k < k1; ++k) pix_rows[k - k0] = frames[size_t(k)].ptr<uint8_t>(y0 + y) + x0;
        if (compact) {
          UpdateCompactRow(compact_states[size_t(worker)], off, tw, k0, k1, k0, vol_row, slot_stride, pix_rows);
        } else {
          UpdateExactRowFrames(states[size_t(worker)], off, tw, k0, k1, vol_row, slot_stride, pix_rows);
        }
      }
    }
    size_t v = 0;
    for (int y = 0; y < th; ++y) {
      const size_t off = size_t(y) * kTileW;
      if (compact) {
        v +=
            FinishCompactRow(compact_states[size_t(worker)], off, tw, zf, options, out.depth.ptr<uint32_t>(y0 + y) + x0,
                             out.confidence.ptr<uint32_t>(y0 + y) + x0, out.aif.ptr<uint8_t>(y0 + y) + x0);
      } else {
        v += FinishExactSpan(states[size_t(worker)], off, tw, z_um, options, out, x0, y0 + y);
      }
    }
    valid += v;
  });
  return MakeDepthResult(out.depth, out.confidence, out.aif, int(frames.size()), valid.load());
}

}  // namespace
}  // namespace sff_internal

StatusOr<DepthResult> SffEngine::ReconstructInMemory(const SffOptions& options, const std::vector<cv::Mat>& frames,
                                                     const std::vector<double>& z_um) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (frames.size() < 3) {
    return Status::InvalidArgument("stack has " + std::to_string(frames.size()) + " frames; at least 3 are needed");
  }
  if (z_um.size() != frames.size()) {
    return Status::InvalidArgument("z_um has " + std::to_string(z_um.size()) + " values for " +
                                   std::to_string(frames.size()) + " frames");
  }
  if (frames[0].empty()) return Status::InvalidArgument("frame 0: empty image");
  const cv::Size size = frames[0].size();
  const int type = frames[0].type();
  if (type != CV_8UC1 && type != CV_16UC1) {
    return Status::InvalidArgument("frame 0: frames must be 8- or 16-bit single-channel");
  }
  for (size_t k = 0; k < frames.size(); ++k) {
    INSPECT_RETURN_IF_ERROR(sff_internal::CheckFrame(frames[k], int(k), size, type));
  }
  for (size_t k = 0; k < z_um.size(); ++k) {
    if (!std::isfinite(z_um[k])) return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um is not finite");
  }
  INSPECT_RETURN_IF_ERROR(CheckMonotonicZ(z_um));
  INSPECT_RETURN_IF_ERROR(sff_internal::CheckCreate(options, size, type));
  if (frames.size() >= 65535) return Status::ResourceExhausted("more than 65535 frames");

  if (!sff_internal::UseFused(options, type)) {
    INSPECT_ASSIGN_OR_RETURN(auto engine, Create(options, size, type));
    for (size_t k = 0; k < frames.size(); ++k) INSPECT_RETURN_IF_ERROR(engine->PushFrame(frames[k], z_um[k]));
    return engine->Finish();
  }
  return sff_internal::ReconstructFusedTiles(options, frames, z_um);
}

}  // namespace inspection
