// Streaming shape from focus (thesis 3.1): per-frame focus measure (3.1.3), running per-pixel
// maximum with its neighbours, depth interpolation and confidence at the end (3.1.4).
// Per-pixel state is O(pixels): best focus value, its frame index, j values before and after it,
// the last j values, the curve's sum and squared steps (for the confidence) and the all-in-focus
// grey value. 8-bit Tenengrad runs through a fused integer kernel (Sobel, squares, window sum and
// state update in one pass over a cache-sized tile, AVX2 / AVX-512 selected at run time); with
// maximum or Gaussian interpolation (the scan default) its state is the compact 23-byte layout
// described at CompactState (exact 32-bit state was 40 bytes), and PushFrame takes frames in
// chunks of 8 so that the state, which bounds its speed, is streamed through memory once per
// chunk rather than once per frame. The line fit and every other measure (through
// core/focus_measure.h) keep exact 32-bit state: 28 + 12 j bytes per pixel (StatePlanes).
#include "core/sff_engine.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <type_traits>

#include "core/cpu_features.h"
#include "core/focus_measure.h"
#include "core/parallel_for.h"
#include "core/sff_state.h"
#include "core/stack.h"
#include "core/tenengrad_kernel.h"

namespace inspection {

using namespace sff_internal;  // NOLINT: transitional, while the engines move out

namespace {

Status CheckFrame(const cv::Mat& frame, int k, cv::Size size, int type) {
  if (frame.empty()) return Status::InvalidArgument("frame " + std::to_string(k) + ": empty image");
  if (frame.size() != size) {
    return Status::InvalidArgument("frame " + std::to_string(k) + ": size " + std::to_string(frame.cols) + "x" +
                                   std::to_string(frame.rows) + " differs from the stack's " +
                                   std::to_string(size.width) + "x" + std::to_string(size.height));
  }
  if (frame.type() != type) {
    return Status::InvalidArgument("frame " + std::to_string(k) + ": pixel type " + std::to_string(frame.type()) +
                                   " differs from the stack's " + std::to_string(type) +
                                   " (bit depth or channels mismatch)");
  }
  return Status::Ok();
}

// Checks of PushFrame for frame k = z.size(): the engine is open, the frame matches, z_um is
// finite and continues the strictly monotonic z, at most 65535 frames (16-bit frame index).
Status CheckPush(const cv::Mat& frame, double z_um, const std::vector<double>& z, bool finished, cv::Size size,
                 int type) {
  const int k = int(z.size());
  if (finished) return Status::FailedPrecondition("engine already finished");
  INSPECT_RETURN_IF_ERROR(CheckFrame(frame, k, size, type));
  if (!std::isfinite(z_um)) return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um is not finite");
  if (k >= 1) {
    const double dz = z_um - z.back();
    if (dz == 0.0 || (k >= 2 && (dz > 0) != (z[1] > z[0]))) {
      return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um " + std::to_string(z_um) +
                                     (dz == 0.0 ? " duplicates the previous frame's" : " is not strictly monotonic"));
    }
  }
  if (k >= 65535) return Status::ResourceExhausted("frame " + std::to_string(k) + ": more than 65535 frames");
  return Status::Ok();
}

// Engine of every case but the compact one below: other measures and 16-bit frames (float
// focus values) and the line fit (j neighbours each side), with exact per-pixel state.
template <typename T, typename P>
class Engine final : public SffEngine {
 public:
  static constexpr bool kFused = std::is_same_v<T, int32_t>;

  Engine(const SffOptions& o, cv::Size size, int type) : options_(o), size_(size), type_(type) {
    const int j = o.interpolation == DepthInterpolation::kLineFit ? o.linefit_half_width : 1;
    state_.Allocate(size.width, size.height, j, o.use_simd);
    threads_ = ResolveThreads(o.threads);
    if constexpr (kFused) {
      scratch_.resize(size_t(threads_));
      for (auto& s : scratch_) s.Reserve(o.window_px);
    }
  }

  Status PushFrame(const cv::Mat& frame, double z_um) override {
    const int k = int(z_.size());
    INSPECT_RETURN_IF_ERROR(CheckPush(frame, z_um, z_, finished_, size_, type_));
    if constexpr (kFused) {
      const int tiles_x = (size_.width + kTileW - 1) / kTileW, tiles_y = (size_.height + kTileH - 1) / kTileH;
      ParallelFor(tiles_x * tiles_y, threads_, [&](int t, int worker) {
        const int x0 = (t % tiles_x) * kTileW, y0 = (t / tiles_x) * kTileH;
        const int tw = std::min(kTileW, size_.width - x0), th = std::min(kTileH, size_.height - y0);
        FusedTileFrame(frame, k, x0, y0, tw, th, options_.window_px, scratch_[size_t(worker)], state_, x0, y0);
      });
    } else {
      cv::Mat focus;
      INSPECT_RETURN_IF_ERROR(ComputeFocusMeasure(frame, options_.focus_measure, options_.window_px, &focus)
                                  .WithContext("frame " + std::to_string(k) + ": "));
      const int bands = std::min(size_.height, threads_ * 4);
      ParallelFor(bands, threads_, [&](int b, int) {
        const int y_begin = size_.height * b / bands, y_end = size_.height * (b + 1) / bands;
        UpdateExactRowsFromFocus(state_, k, focus, frame, y_begin, y_end);
      });
    }
    z_.push_back(z_um);
    return Status::Ok();
  }

  StatusOr<DepthResult> Finish() override {
    const int n = int(z_.size());
    if (finished_) return Status::FailedPrecondition("engine already finished");
    if (n < 3) return Status::InvalidArgument("stack has " + std::to_string(n) + " frames; at least 3 are needed");
    finished_ = true;
    DepthOutputs out;
    out.depth.create(size_, CV_32F);
    out.confidence.create(size_, CV_32F);
    out.aif.create(size_, type_);
    std::atomic<size_t> valid{0};
    ParallelFor(size_.height, threads_, [&](int y, int) {
      valid += FinishExactSpan(state_, size_t(y) * size_.width, size_.width, z_, options_, out, 0, y);
    });
    DepthResult r;
    r.depth_um = out.depth;
    r.confidence = out.confidence;
    r.all_in_focus = out.aif;
    r.frame_count = n;
    r.valid_fraction = double(valid.load()) / double(size_.area());
    state_ = {};  // release the O(pixels) state
    return r;
  }

  int frames_pushed() const override { return int(z_.size()); }
  size_t state_bytes() const override { return state_.Bytes(); }

 private:
  SffOptions options_;
  cv::Size size_;
  int type_;
  int threads_ = 1;
  bool finished_ = false;
  std::vector<double> z_;
  StatePlanes<T, P> state_;
  std::vector<TenengradScratch> scratch_;
};

// 8-bit frames, Tenengrad, maximum or Gaussian interpolation (the scan default): the fused
// kernel over the compact state (23 bytes per pixel); Finish writes depth, confidence and the
// all-in-focus image into the state's own buffers, so the result adds no memory, and frees the
// rest.
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
    if (finished_) return Status::FailedPrecondition("engine already finished");
    if (n < 3) return Status::InvalidArgument("stack has " + std::to_string(n) + " frames; at least 3 are needed");
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
    DepthResult r;
    r.depth_um = state_.best;      // CV_32F, now holding depth_um
    r.confidence = state_.sum_idx;  // CV_32F, now holding the confidence
    r.all_in_focus = state_.aif;
    r.frame_count = n;
    r.valid_fraction = double(valid.load()) / double(size_.area());
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
        FocusRowsToVolume(state_.avx2, pending_[size_t(slot)], slot, x0, y0, tw, th, options_.window_px, sc, vol,
                          next);
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
  std::vector<cv::Mat> pending_;              // frames of the open chunk
};

Status CheckCreate(const SffOptions& options, cv::Size frame_size, int frame_type) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (frame_size.width < 3 || frame_size.height < 3) return Status::InvalidArgument("frame size must be at least 3x3");
  if (frame_type != CV_8UC1 && frame_type != CV_16UC1) {
    return Status::InvalidArgument("frames must be 8- or 16-bit single-channel");
  }
  return Status::Ok();
}

bool UseFused(const SffOptions& o, int frame_type) {
  return frame_type == CV_8UC1 && o.focus_measure == FocusMeasure::kTenengrad;
}

bool UseCompact(const SffOptions& o, int frame_type) {
  return UseFused(o, frame_type) && o.interpolation != DepthInterpolation::kLineFit;
}

}  // namespace

StatusOr<std::unique_ptr<SffEngine>> SffEngine::Create(const SffOptions& options, cv::Size frame_size,
                                                       int frame_type) {
  INSPECT_RETURN_IF_ERROR(CheckCreate(options, frame_size, frame_type));
  if (UseCompact(options, frame_type)) return std::unique_ptr<SffEngine>(new CompactEngine(options, frame_size));
  if (UseFused(options, frame_type)) {
    return std::unique_ptr<SffEngine>(new Engine<int32_t, uint8_t>(options, frame_size, frame_type));
  }
  if (frame_type == CV_8UC1) return std::unique_ptr<SffEngine>(new Engine<float, uint8_t>(options, frame_size, frame_type));
  return std::unique_ptr<SffEngine>(new Engine<float, uint16_t>(options, frame_size, frame_type));
}

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
  for (size_t k = 0; k < frames.size(); ++k) INSPECT_RETURN_IF_ERROR(CheckFrame(frames[k], int(k), size, type));
  for (size_t k = 0; k < z_um.size(); ++k) {
    if (!std::isfinite(z_um[k])) return Status::InvalidArgument("frame " + std::to_string(k) + ": z_um is not finite");
  }
  INSPECT_RETURN_IF_ERROR(CheckMonotonicZ(z_um));
  INSPECT_RETURN_IF_ERROR(CheckCreate(options, size, type));
  if (frames.size() >= 65535) return Status::ResourceExhausted("more than 65535 frames");

  if (!UseFused(options, type)) {
    INSPECT_ASSIGN_OR_RETURN(auto engine, Create(options, size, type));
    for (size_t k = 0; k < frames.size(); ++k) INSPECT_RETURN_IF_ERROR(engine->PushFrame(frames[k], z_um[k]));
    return engine->Finish();
  }

  // Tiles across all frames: each worker keeps one tile's state, runs every frame over it, then
  // interpolates the tile; the same kernels as PushFrame, so the result is bit-identical.
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
    if (compact) compact_states[size_t(w)].Allocate(kTileW, kBatchTileH, options.use_simd, options.use_avx512);
    else states[size_t(w)].Allocate(kTileW, kBatchTileH, j, options.use_simd);
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
        v += FinishCompactRow(compact_states[size_t(worker)], off, tw, zf, options,
                              out.depth.ptr<uint32_t>(y0 + y) + x0, out.confidence.ptr<uint32_t>(y0 + y) + x0,
                              out.aif.ptr<uint8_t>(y0 + y) + x0);
      } else {
        v += FinishExactSpan(states[size_t(worker)], off, tw, z_um, options, out, x0, y0 + y);
      }
    }
    valid += v;
  });
  DepthResult r;
  r.depth_um = out.depth;
  r.confidence = out.confidence;
  r.all_in_focus = out.aif;
  r.frame_count = int(frames.size());
  r.valid_fraction = double(valid.load()) / double(size.area());
  return r;
}

StatusOr<DepthResult> ReconstructStack(const std::filesystem::path& dir, const SffOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  INSPECT_ASSIGN_OR_RETURN(StackManifest manifest, ReadStackManifest(dir));
  std::unique_ptr<SffEngine> engine;
  for (size_t k = 0; k < manifest.frames.size(); ++k) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, LoadStackFrame(dir, manifest, k));
    if (!engine) {
      INSPECT_ASSIGN_OR_RETURN(engine, SffEngine::Create(options, frame.size(), frame.type()));
    }
    Status st = engine->PushFrame(frame, manifest.frames[k].z_um);
    if (!st.ok()) return st.WithContext(manifest.frames[k].file + ": ");
  }
  if (!engine) return Status::InvalidArgument("stack.json: frames is empty");
  return engine->Finish();
}

}  // namespace inspection
