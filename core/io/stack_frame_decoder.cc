// StackFrameDecoder (core/io/stack_frame_decoder.h): a small decode pool with a z-indexed slot per
// frame; the consumer waits on its frame's slot, so completion order never reaches the engine.
#include "core/io/stack_frame_decoder.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <string>
#include <system_error>
#include <utility>

#include "core/util/parallel_for.h"
#include "core/io/png_frame_decode.h"

namespace inspection {

namespace {

int64_t BytesOf(const cv::Mat& m) { return int64_t(m.total() * m.elemSize()); }

bool HasPngSignature(std::string_view bytes) {
  return bytes.size() >= 8 && std::memcmp(bytes.data(), "\x89PNG\r\n\x1a\n", 8) == 0;
}

// Frame `index` as DecodeStackFrame gives it; a plain PNG (most stacks) through the fast path
// (core/io/png_frame_decode.h), whose pixels are the same. Anything else, or a file the fast path
// does not take, the general way, which also words the errors.
StatusOr<cv::Mat> DecodeFrameFile(const std::filesystem::path& dir, const StackManifest& manifest, int index) {
  if (index >= 0 && index < int(manifest.frames.size())) {
    std::ifstream in(dir / manifest.frames[size_t(index)].file, std::ios::binary);
    char signature[8] = {};
    if (in.read(signature, sizeof signature) && HasPngSignature(std::string_view(signature, sizeof signature))) {
      in.seekg(0, std::ios::end);
      const std::streamoff size = in.tellg();
      // The file's bytes in a buffer of the decode thread, reused from frame to frame (a fresh,
      // zero-filled one per frame cost ~200 page faults and a pass over it).
      thread_local std::string buffer;
      if (size > 0 && buffer.size() < size_t(size)) buffer.resize(size_t(size));
      in.seekg(0);
      if (size > 0 && in.read(buffer.data(), size)) {
        cv::Mat image = DecodePlainPng(std::string_view(buffer.data(), size_t(size)));
        if (buffer.size() > kPngFastPathKeptBufferBytes) buffer = std::string();
        if (!image.empty()) return image;
      }
    }
  }
  return DecodeStackFrame(dir, manifest, size_t(index));
}

}  // namespace

StatusOr<cv::Mat> DecodeStackFrameInMemory(std::string_view file, const StackManifest& manifest, int index) {
  if (HasPngSignature(file)) {
    cv::Mat image = DecodePlainPng(file);
    if (!image.empty()) return image;
  }
  return DecodeStackFrameBytes(file, manifest, size_t(index));
}

StackFrameDecoder::StackFrameDecoder(std::filesystem::path dir, StackManifest manifest,
                                     const StackFrameDecoderOptions& options, StackFrameDecodeFn decode)
    : dir_(std::move(dir)), manifest_(std::move(manifest)), options_(options), decode_(std::move(decode)) {
  if (!decode_) decode_ = [this](int i) { return DecodeFrameFile(dir_, manifest_, i); };
  slots_.resize(manifest_.frames.size());
  for (size_t i = 0; i < manifest_.frames.size(); ++i) by_file_.emplace(manifest_.frames[i].file, int(i));
  const int n = std::min(ResolveThreads(options_.threads), std::max(1, int(slots_.size())));
  for (int t = 0; t < n; ++t) {
    try {
      threads_.emplace_back([this] { Work(); });
    } catch (const std::system_error&) {
      break;  // fewer threads; with none, Finish and Frame decode in the caller's thread
    }
  }
}

StackFrameDecoder::~StackFrameDecoder() {
  {
    std::lock_guard lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  for (auto& t : threads_) t.join();
}

void StackFrameDecoder::QueueLocked(int index) {
  if (index < 0 || index >= int(slots_.size()) || slots_[size_t(index)].state != State::kIdle) return;
  slots_[size_t(index)].state = State::kQueued;
  queue_.push_back(index);
}

int64_t StackFrameDecoder::BudgetLocked(int64_t frame_bytes) const {
  if (frame_bytes <= 0 || frame_bytes * int64_t(slots_.size()) <= options_.max_kept_bytes) return options_.max_kept_bytes;
  const int64_t lookahead = LookaheadFrames();
  return std::min(options_.max_kept_bytes, lookahead * frame_bytes);
}

void StackFrameDecoder::PrefetchLocked(int after) {
  if (threads_.empty() || !slots_[0].shape) return;
  const StackFrameShape& shape = *slots_[0].shape;
  const int64_t bytes = int64_t(shape.size.area()) * shape.channels * (shape.depth == CV_16U ? 2 : 1);
  const int64_t budget = BudgetLocked(bytes);
  const int lookahead = LookaheadFrames();
  for (int j = after + 1; j < int(slots_.size()) && j <= after + lookahead; ++j) {
    Slot& slot = slots_[size_t(j)];
    if (slot.state != State::kDropped && slot.state != State::kReleased) continue;
    if (kept_bytes_ + reserved_bytes_ + bytes > budget) break;
    slot.state = State::kQueued;
    slot.prefetch = true;
    reserved_bytes_ += bytes;
    queue_.push_back(j);
  }
}

void StackFrameDecoder::Submit(int index) {
  {
    std::lock_guard lock(mu_);
    QueueLocked(index);
  }
  cv_.notify_all();
}

void StackFrameDecoder::SubmitFile(const std::string& relative) {
  {
    std::lock_guard lock(mu_);
    auto [begin, end] = by_file_.equal_range(relative);
    for (auto it = begin; it != end; ++it) QueueLocked(it->second);
  }
  cv_.notify_all();
}

StatusOr<cv::Mat> StackFrameDecoder::DecodeOne(int index) {
  StatusOr<cv::Mat> image = decode_(index);
  std::lock_guard lock(mu_);
  ++decoded_;
  return image;
}

void StackFrameDecoder::Work() {
  std::unique_lock lock(mu_);
  for (;;) {
    cv_.wait(lock, [&] { return stop_ || !queue_.empty(); });
    if (stop_) return;
    const int index = queue_.front();
    queue_.pop_front();
    Slot& slot = slots_[size_t(index)];
    slot.state = State::kDecoding;
    lock.unlock();
    const bool again = slot.prefetch;  // statistics known from the first decode
    StatusOr<cv::Mat> image = decode_(index);
    std::optional<FrameStatistics> statistics;
    if (!again && image.ok() && image->channels() == 1) {
      statistics = ComputeFrameStatistics(*image, manifest_.bit_depth);
    }
    lock.lock();
    ++decoded_;
    int64_t reserved = 0;
    if (again) {
      slot.prefetch = false;
      if (slots_[0].shape) {
        const StackFrameShape& s0 = *slots_[0].shape;
        reserved = int64_t(s0.size.area()) * s0.channels * (s0.depth == CV_16U ? 2 : 1);
      }
      reserved_bytes_ -= reserved;
    }
    if (!image.ok()) {
      slot.state = State::kFailed;
      slot.error = image.status();
    } else {
      slot.shape = StackFrameShape::Of(*image);
      if (!again) slot.statistics = statistics;
      const int64_t bytes = BytesOf(*image);
      if (kept_bytes_ + bytes <= BudgetLocked(bytes)) {
        slot.image = std::move(image).value();
        slot.state = State::kKept;
        kept_bytes_ += bytes;
        peak_kept_bytes_ = std::max(peak_kept_bytes_, kept_bytes_);
      } else {
        slot.state = State::kDropped;  // checked; decoded again by the consumer
      }
    }
    cv_.notify_all();
  }
}

Status StackFrameDecoder::Finish() {
  std::unique_lock lock(mu_);
  for (int i = 0; i < int(slots_.size()); ++i) QueueLocked(i);
  cv_.notify_all();
  auto busy = [&] {
    return std::any_of(slots_.begin(), slots_.end(),
                       [](const Slot& s) { return s.state == State::kQueued || s.state == State::kDecoding; });
  };
  while (busy()) {
    if (threads_.empty() && !queue_.empty()) {
      const int index = queue_.front();
      queue_.pop_front();
      lock.unlock();
      StatusOr<cv::Mat> image = DecodeOne(index);
      lock.lock();
      Slot& slot = slots_[size_t(index)];
      if (image.ok()) {
        slot.shape = StackFrameShape::Of(*image);
        slot.state = State::kDropped;  // no pool: the consumer decodes again
      } else {
        slot.state = State::kFailed;
        slot.error = image.status();
      }
      continue;
    }
    cv_.wait(lock);
  }
  // In index order, as the sequential check: the first bad frame wins whatever finished first.
  for (size_t i = 0; i < slots_.size(); ++i) {
    const Slot& slot = slots_[i];
    if (slot.state == State::kFailed) return slot.error;
    INSPECT_RETURN_IF_ERROR(CheckStackFrameShape(manifest_, i, *slots_[0].shape, *slot.shape));
  }
  return Status::Ok();
}

StatusOr<cv::Mat> StackFrameDecoder::Frame(int index) {
  if (index < 0 || index >= int(slots_.size())) return Status::OutOfRange("frame index " + std::to_string(index));
  std::unique_lock lock(mu_);
  Slot& slot = slots_[size_t(index)];
  if (slot.state == State::kIdle) {
    // The consumer is waiting for it: ahead of the queue.
    slot.state = State::kQueued;
    queue_.push_front(index);
    cv_.notify_all();
  } else if (slot.state == State::kQueued && slot.prefetch) {  // a look-ahead the consumer caught up with
    queue_.erase(std::remove(queue_.begin(), queue_.end(), index), queue_.end());
    queue_.push_front(index);
  }
  PrefetchLocked(index);
  cv_.notify_all();
  while (slot.state == State::kQueued || slot.state == State::kDecoding) {
    if (threads_.empty()) {
      queue_.erase(std::remove(queue_.begin(), queue_.end(), index), queue_.end());
      slot.state = State::kDropped;
      break;
    }
    cv_.wait(lock);
  }
  switch (slot.state) {
    case State::kKept:
      return slot.image;
    case State::kFailed:
      return slot.error;
    default:
      break;  // dropped or released: decode again, outside the lock
  }
  lock.unlock();
  return DecodeOne(index);
}

std::optional<FrameStatistics> StackFrameDecoder::Statistics(int index) const {
  std::lock_guard lock(mu_);
  if (index < 0 || index >= int(slots_.size())) return std::nullopt;
  return slots_[size_t(index)].statistics;
}

void StackFrameDecoder::Release(int index) {
  std::lock_guard lock(mu_);
  if (index < 0 || index >= int(slots_.size())) return;
  Slot& slot = slots_[size_t(index)];
  if (slot.state != State::kKept) return;
  kept_bytes_ -= BytesOf(slot.image);
  slot.image.release();
  slot.state = State::kReleased;
}

void StackFrameDecoder::ReleaseAll() {
  for (int i = 0; i < int(slots_.size()); ++i) Release(i);
}

int64_t StackFrameDecoder::kept_bytes() const {
  std::lock_guard lock(mu_);
  return kept_bytes_;
}

int64_t StackFrameDecoder::peak_kept_bytes() const {
  std::lock_guard lock(mu_);
  return peak_kept_bytes_;
}

int StackFrameDecoder::decoded_frames() const {
  std::lock_guard lock(mu_);
  return decoded_;
}

}  // namespace inspection
