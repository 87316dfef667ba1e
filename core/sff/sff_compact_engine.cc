// Streaming SFF engine of the scan default (thesis 3.1): 8-bit frames, Tenengrad (eq. 3.14),
// maximum or Gaussian interpolation (eq. 3.23-3.24, 3.30-3.34), through the fused kernel
// (core/sff/internal/tenengrad_kernel.h) over the compact 23-byte state (core/sff/sff_state.h). Finish writes
// depth, confidence and the all-in-focus image into the state's own buffers, so the result
// adds no memory, and frees the rest.
#include <algorithm>
#include <atomic>
#include <string>

#include "core/util/parallel_for.h"
#include "core/sff/internal/sff_engine_internal.h"
#include "core/sff/internal/tenengrad_kernel.h"

namespace inspection::sff_internal {
namespace {

class CompactEngine final : public SffEngine {
 public:
  CompactEngine(const SffOptions& o, cv::Size size) : options_(o), size_(size) {
    state_.Allocate(size.width, size.height, o.use_simd, o.use_avx512);
    threads_ = ResolveThreads(o.threads);
    scratch_.resize(size_t(threads_));
    for (auto& s : scratch_) s.Reserve(o.window_px);
    volumes_.assign(size_t(threads_), std::vector<int32_t>(size_t(kTileW) * kBatchTileH * kFrameChunk));
  }

  // Frames are taken in chunks of kFrameChunk: each state tile is then read and written once
  // per chunk instead of once per frame (the state update is memory-bound), with the batch
  // path's kernels, so the result stays bit-identical. The frames of an open chunk are held
  // by reference (cv::Mat shares the pixels); a Mat over memory it does not own is copied.
  Status PushFrame(const cv::Mat& frame, double z_um) override {
    INSPECT_RETURN_IF_ERROR(CheckPush(frame, z_um, z_, finished_, size_, CV_8UC1));
    pending_.push_back(frame.u != nullptr ? frame : frame.clone());
    z_.push_back(z_um);
    if (int(pending_.size()) == kFrameChunk) ProcessPending();
    return Status::Ok();
  }

  StatusOr<DepthResult> Finish() override {
    const int n = int(z_.size());
    INSPECT_RETURN_IF_ERROR(CheckFinish(finished_, n));
    ProcessPending();
    finished_ = true;
    volumes_ = {};
    const std::vector<float> zf(z_.begin(), z_.end());
    std::atomic<size_t> valid{0};
    uint32_t* depth = reinterpret_cast<uint32_t*>(state_.best.data);
    uint32_t* conf = reinterpret_cast<uint32_t*>(state_.sum_idx.data);
    ParallelFor(size_.height, threads_, [&](int y, int) {
      const size_t off = size_t(y) * size_.width;
      valid += FinishCompactRow(state_, off, size_.width, zf, options_, depth + off, conf + off, state_.aif.data + off);
    });
    // best and sum_idx (CV_32F) now hold depth_um and the confidence.
    DepthResult r = MakeDepthResult(state_.best, state_.sum_idx, state_.aif, n, valid.load());
    state_ = {};  // the result owns its three buffers; the rest of the state is freed
    return r;
  }

  int frames_pushed() const override { return int(z_.size()); }
  size_t state_bytes() const override { return state_.Bytes(); }

 private:
  // Frames z_.size() - pending_.size() .. z_.size() - 1 over the state, tile by tile.
  void ProcessPending() {
    if (pending_.empty()) return;
    const int k1 = int(z_.size()), k0 = k1 - int(pending_.size());
    const int tiles_x = (size_.width + kTileW - 1) / kTileW, tiles_y = (size_.height + kBatchTileH - 1) / kBatchTileH;
    const size_t slot_stride = size_t(kBatchTileH) * kTileW;
    ParallelFor(tiles_x * tiles_y, threads_, [&](int t, int worker) {
      const int x0 = (t % tiles_x) * kTileW, y0 = (t / tiles_x) * kBatchTileH;
      const int tw = std::min(kTileW, size_.width - x0), th = std::min(kBatchTileH, size_.height - y0);
      TenengradScratch& sc = scratch_[size_t(worker)];
      int32_t* vol = volumes_[size_t(worker)].data();
      for (int k = k0; k < k1; ++k) {
        const int slot = k - k0;
        const cv::Mat* next = slot + 1 < int(pending_.size()) ? &pending_[size_t(slot) + 1] : nullptr;
        FocusRowsToVolume(state_.avx2, pending_[size_t(slot)], slot, x0, y0, tw, th, options_.window_px, sc, vol, next);
      }
      for (int y = 0; y < th; ++y) {
        const uint8_t* pix_rows[kFrameChunk];
        for (int k = k0; k < k1; ++k) pix_rows[k - k0] = pending_[size_t(k - k0)].ptr<uint8_t>(y0 + y) + x0;
        // The next row's state is a whole frame row of planes away: the hardware prefetcher
        // follows the planes within a row but not that jump.
        if (y + 1 < th) PrefetchCompactRow(state_.Row(size_t(y0 + y + 1) * size_.width + x0), tw);
        UpdateCompactRow(state_, size_t(y0 + y) * size_.width + x0, tw, k0, k1, k0, vol + size_t(y) * kTileW,
                         slot_stride, pix_rows);
      }
    });
    pending_.clear();
  }

  SffOptions options_;
  cv::Size size_;
  int threads_ = 1;
  bool finished_ = false;
  std::vector<double> z_;
  CompactState state_;
  std::vector<TenengradScratch> scratch_;
  std::vector<std::vector<int32_t>> volumes_;  // per worker: focus rows of one tile x kFrameChunk frames
  std::vector<cv::Mat> pending_;               // frames of the open chunk
};

}  // namespace

std::unique_ptr<SffEngine> NewCompactEngine(const SffOptions& options, cv::Size frame_size) {
  return std::make_unique<CompactEngine>(options, frame_size);
}

}  // namespace inspection::sff_internal
