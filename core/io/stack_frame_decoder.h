// Decodes a stack's frames (core/io/stack.h) on a few threads as their files become complete (an
// upload's last chunk) or from bytes in memory (a stored scan's archive entries, through an
// injected decode function), in whatever order they finish,
// and hands them to the SFF engine loop (core/sff/stack_reconstruct.h) strictly in z order: the
// streaming engine of thesis 3.1 is fed frame by frame as before, only the decoding moved off
// its path. Decoded frames are kept up to a byte budget; a frame beyond it is checked and
// dropped, and decoded again by the consumer when its turn comes (memory stays bounded).
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "core/io/frame_statistics.h"
#include "core/io/stack.h"
#include "core/util/status.h"

namespace inspection {

// Decodes frame `index` as stored (by default DecodeStackFrame's pixels, plain PNGs through
// core/io/png_frame_decode.h; tests inject their own).
using StackFrameDecodeFn = std::function<StatusOr<cv::Mat>(int index)>;

// Frame `index` from its file's bytes in memory (a stored scan's archive entry): a plain PNG
// through the fast path, anything else DecodeStackFrameBytes; the pixels and errors of the
// default decode of that file on disk.
StatusOr<cv::Mat> DecodeStackFrameInMemory(std::string_view file, const StackManifest& manifest, int index);

struct StackFrameDecoderOptions {
  int threads = 0;  // decode threads; 0 = all hardware threads
  // Decoded frames kept for the consumer, bytes; frames beyond it are decoded again when
  // consumed. The default holds 60 colour frames of 1600 x 1200 at 8 bits. A stack that does
  // not fit whole keeps only a look-ahead of kLookaheadFramesPerThread frames per decode thread,
  // at most kMaxLookaheadFrames in all (the consumer's frame included), within it: most of its
  // frames are decoded twice anyway, and 1 GiB of frames beside the engine's state would be most
  // of the memory of a 24 MP stack. Two frames suffice whatever the thread count: a 24 MP frame
  // decodes in well under a second and the engine takes seconds per frame, while each frame
  // more costs 2 (16-bit grey) to 3 (8-bit colour) bytes per pixel of the stack's frames.
  int64_t max_kept_bytes = int64_t(1) << 30;
};

// Thread-safe: Submit*, Finish and Frame/Release may be called from any thread (one consumer).
class StackFrameDecoder {
 public:
  static constexpr int kLookaheadFramesPerThread = 2;
  static constexpr int kMaxLookaheadFrames = 2;

  // manifest: the stack's frames (Submit by index or by file name). decode empty = decode from
  // `dir` (DecodeStackFrame).
  StackFrameDecoder(std::filesystem::path dir, StackManifest manifest, const StackFrameDecoderOptions& options,
                    StackFrameDecodeFn decode = {});
  ~StackFrameDecoder();  // stops the threads; queued decodes are dropped
  StackFrameDecoder(const StackFrameDecoder&) = delete;
  StackFrameDecoder& operator=(const StackFrameDecoder&) = delete;

  const StackManifest& manifest() const { return manifest_; }

  // Queues the decode of frame `index` (its file is complete); a second call is ignored.
  void Submit(int index);
  // Queues every frame whose file is `relative` (as in stack.json); other files are ignored.
  void SubmitFile(const std::string& relative);

  // Queues what was not submitted, waits for every decode and checks the frames in index order as
  // ValidateStackFrames does: the first bad frame's error (INVALID_ARGUMENT naming it), the same
  // error as the sequential check whatever order the decodes finished in.
  Status Finish();

  // Frame `index` as stored (CV_8U/16U, 1 or 3 channels), waiting for its decode (queued now if
  // it was not); a dropped frame is decoded here. The cv::Mat shares the kept pixels. Frames
  // after it that were dropped or released are queued again on the pool (a look-ahead within the
  // budget), so a stack larger than the budget still decodes ahead of the consumer.
  StatusOr<cv::Mat> Frame(int index);
  // The progress-event statistics (core/io/frame_statistics.h) of grey frame `index` as stored,
  // computed by the thread that decoded it while its pixels were in cache; nullopt for colour
  // frames and frames not (yet) decoded by the pool. Kept after Release.
  std::optional<FrameStatistics> Statistics(int index) const;
  // The consumer is done with frame `index`: its pixels are freed (a later Frame decodes again).
  void Release(int index);
  // Frees every kept frame (the consumer reads the folder itself).
  void ReleaseAll();

  // Figures for benchmarks and logs.
  int64_t kept_bytes() const;
  int64_t peak_kept_bytes() const;
  int decoded_frames() const;  // decodes run so far, including the consumer's re-decodes
  int threads() const { return int(threads_.size()); }

 private:
  enum class State { kIdle, kQueued, kDecoding, kKept, kDropped, kReleased, kFailed };
  struct Slot {
    State state = State::kIdle;
    cv::Mat image;  // kKept
    std::optional<StackFrameShape> shape;
    std::optional<FrameStatistics> statistics;  // grey frames decoded by the pool
    Status error = Status::Ok();  // kFailed
    bool prefetch = false;        // queued again after a drop or release; its bytes are reserved
  };

  void Work();
  void QueueLocked(int index);
  // The budget frames of `frame_bytes` are kept within (max_kept_bytes, or the look-ahead).
  int64_t BudgetLocked(int64_t frame_bytes) const;
  // Frames a stack beyond the budget keeps decoded (StackFrameDecoderOptions::max_kept_bytes).
  int LookaheadFrames() const {
    return std::min(kMaxLookaheadFrames, kLookaheadFramesPerThread * std::max(1, int(threads_.size())));
  }
  void PrefetchLocked(int after);
  StatusOr<cv::Mat> DecodeOne(int index);

  const std::filesystem::path dir_;
  const StackManifest manifest_;
  const StackFrameDecoderOptions options_;
  StackFrameDecodeFn decode_;
  std::multimap<std::string, int> by_file_;

  mutable std::mutex mu_;       // guards everything below
  std::condition_variable cv_;  // a slot changed state, a task was queued, or stop
  std::vector<Slot> slots_;
  std::deque<int> queue_;
  bool stop_ = false;
  int64_t kept_bytes_ = 0;
  int64_t reserved_bytes_ = 0;  // prefetches queued or decoding
  int64_t peak_kept_bytes_ = 0;
  int decoded_ = 0;
  std::vector<std::thread> threads_;
};

}  // namespace inspection
