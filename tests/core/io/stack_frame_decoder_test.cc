// StackFrameDecoder (core/io/stack_frame_decoder.h) feeding ReconstructStackFrames: parallel and
// out-of-order decoding reconstructs bit for bit what the sequential folder loop does, the
// engine still sees the frames in z order, the byte budget bounds what is kept, and a bad frame
// anywhere gives the sequential check's error naming that frame.
#include "core/io/stack_frame_decoder.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "core/io/stack.h"
#include "core/sff/stack_reconstruct.h"
#include "tests/core/colour_stack_synthetic.h"
#include "tests/core/sff_synthetic.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;
using testing::BitIdentical;

fs::path TempDir(const std::string& tag) {
  const fs::path dir = fs::temp_directory_path() / ("stack_decoder_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// A tilted textured plane, 8 frames of 64 x 48 grey PNG.
StackManifest WriteGreyStack(const fs::path& dir) {
  const auto s = testing::TiltedPlaneStack(cv::Size(64, 48), testing::UniformZ(8, 0.0, 1.0), 2.5, 0.03, 0.02);
  StackManifest m;
  m.pixel_size_um = 1.0;
  for (size_t k = 0; k < s.frames.size(); ++k) {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%04zu.png", k);
    EXPECT_TRUE(cv::imwrite((dir / name).string(), s.frames[k]));
    m.frames.push_back({name, s.z_um[k], 0.0, "uniform:128"});
  }
  EXPECT_TRUE(WriteStackManifest(dir, m).ok());
  return m;
}

StackFrameSource SourceOf(StackFrameDecoder& decoder) {
  return {[&decoder](int i) { return decoder.Frame(i); }, [&decoder](int i) { decoder.Release(i); },
          [&decoder](int i) { return decoder.Statistics(i); }};
}

void ExpectBitIdentical(const DepthResult& a, const DepthResult& b) {
  EXPECT_TRUE(BitIdentical(a.depth_um, b.depth_um));
  EXPECT_TRUE(BitIdentical(a.confidence, b.confidence));
  EXPECT_TRUE(BitIdentical(a.all_in_focus, b.all_in_focus));
  EXPECT_EQ(a.frame_count, b.frame_count);
  EXPECT_EQ(a.valid_fraction, b.valid_fraction);
}

// Parallel decode (3 threads, submitted in a scrambled order) against the sequential loop, grey
// and colour (8-bit PNG, 16-bit TIFF), unaligned and with the estimated alignment.
TEST(StackFrameDecoderTest, ParallelDecodeIsBitIdenticalToSequentialFolderLoop) {
  struct Case {
    std::string tag;
    bool colour, sixteen_bit;
    FrameAlignment alignment;
  };
  for (const Case& c : {Case{"grey", false, false, FrameAlignment::kNone},
                        Case{"grey_est", false, false, FrameAlignment::kEstimate},
                        Case{"colour8", true, false, FrameAlignment::kNone},
                        Case{"colour16", true, true, FrameAlignment::kNone}}) {
    SCOPED_TRACE(c.tag);
    const fs::path dir = TempDir(c.tag);
    StackManifest m;
    if (c.colour) {
      testing::ColourStackSpec spec;
      spec.sixteen_bit = c.sixteen_bit;
      m = testing::WriteColourStack(dir, spec);
    } else {
      m = WriteGreyStack(dir);
    }
    StackFolderAlignment a;
    a.alignment = c.alignment;
    a.fall_back_to_none = true;
    std::atomic<bool> cancel{false};
    // The progress events' statistics: computed in the loop (sequential) or by the decode threads.
    std::vector<FrameStatistics> sequential_stats, parallel_stats;
    auto collect = [](std::vector<FrameStatistics>* into) {
      return [into](int, int, double, const FrameStatistics& st) { into->push_back(st); };
    };
    auto sequential = ReconstructStackFolder(dir, m, SffOptions{}, collect(&sequential_stats), cancel, a);
    ASSERT_TRUE(sequential.ok()) << sequential.status().ToString();

    StackFrameDecoderOptions o;
    o.threads = 3;
    StackFrameDecoder decoder(dir, m, o);
    for (int i = int(m.frames.size()) - 1; i >= 0; i -= 2) decoder.Submit(i);
    for (int i = 0; i < int(m.frames.size()); i += 2) decoder.Submit(i);
    ASSERT_TRUE(decoder.Finish().ok());
    StackFolderAlignment concurrent = a;  // as the server runs it on decoded frames
    concurrent.options.threads = 0;
    for (int i = 0; i < int(m.frames.size()); ++i) {
      EXPECT_EQ(decoder.Statistics(i).has_value(), !c.colour) << "grey frames' statistics come from the pool";
    }
    auto parallel =
        ReconstructStackFrames(m, SourceOf(decoder), SffOptions{}, collect(&parallel_stats), cancel, concurrent);
    ASSERT_TRUE(parallel.ok()) << parallel.status().ToString();
    ExpectBitIdentical(*parallel, *sequential);
    ASSERT_EQ(parallel_stats.size(), m.frames.size());
    ASSERT_EQ(sequential_stats.size(), m.frames.size());
    for (size_t i = 0; i < m.frames.size(); ++i) {
      EXPECT_EQ(parallel_stats[i].mean_grey, sequential_stats[i].mean_grey) << i;
      EXPECT_EQ(parallel_stats[i].stddev_grey, sequential_stats[i].stddev_grey) << i;
      EXPECT_EQ(parallel_stats[i].saturated_percent, sequential_stats[i].saturated_percent) << i;
      EXPECT_EQ(parallel_stats[i].underexposed_percent, sequential_stats[i].underexposed_percent) << i;
      EXPECT_GT(parallel_stats[i].stddev_grey, 0.0) << i;
    }
    EXPECT_EQ(c.colour ? 3 : 1, parallel->all_in_focus.channels());
    // Every frame was decoded once (alignment's pass reads the kept frames) and released after
    // the engine took it.
    EXPECT_EQ(decoder.decoded_frames(), int(m.frames.size()));
    EXPECT_EQ(decoder.kept_bytes(), 0);
    fs::remove_all(dir);
  }
}

// One decode thread completes the frames in the order 5, 2, 7, 0, ... while the engine loop
// already waits for frame 0: the engine still receives 0, 1, 2, ... and the same result.
TEST(StackFrameDecoderTest, OutOfOrderCompletionFeedsTheEngineInZOrder) {
  const fs::path dir = TempDir("order");
  const StackManifest m = WriteGreyStack(dir);
  std::mutex mu;
  std::vector<int> completed;
  auto decode = [&](int i) -> StatusOr<cv::Mat> {
    auto image = DecodeStackFrame(dir, m, size_t(i));
    std::lock_guard lock(mu);
    completed.push_back(i);
    return image;
  };
  StackFrameDecoderOptions o;
  o.threads = 1;
  StackFrameDecoder decoder(dir, m, o, decode);
  const std::vector<int> submit_order = {5, 2, 7, 0, 3, 6, 1, 4};
  for (int i : submit_order) decoder.Submit(i);
  std::vector<int> pushed;
  std::atomic<bool> cancel{false};
  auto on_frame = [&](int i, int, double, const FrameStatistics&) { pushed.push_back(i); };
  auto parallel = ReconstructStackFrames(m, SourceOf(decoder), SffOptions{}, on_frame, cancel);
  ASSERT_TRUE(parallel.ok()) << parallel.status().ToString();
  {
    std::lock_guard lock(mu);
    EXPECT_EQ(completed, submit_order);  // the single worker took them in submission order
  }
  EXPECT_EQ(pushed, (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7}));
  auto sequential = ReconstructStackFolder(dir, m, SffOptions{}, {}, cancel);
  ASSERT_TRUE(sequential.ok());
  ExpectBitIdentical(*parallel, *sequential);
  fs::remove_all(dir);
}

// A budget of two frames: never more kept, the frames beyond it are decoded again when the
// engine reaches them, and the result does not change.
TEST(StackFrameDecoderTest, ByteBudgetBoundsKeptFramesWithoutChangingTheResult) {
  const fs::path dir = TempDir("budget");
  const StackManifest m = WriteGreyStack(dir);
  const int64_t frame_bytes = 64 * 48;
  StackFrameDecoderOptions o;
  o.threads = 2;
  o.max_kept_bytes = 2 * frame_bytes;
  StackFrameDecoder decoder(dir, m, o);
  for (int i = 0; i < int(m.frames.size()); ++i) decoder.Submit(i);
  ASSERT_TRUE(decoder.Finish().ok());
  EXPECT_LE(decoder.peak_kept_bytes(), 2 * frame_bytes);
  EXPECT_EQ(decoder.kept_bytes(), 2 * frame_bytes);
  std::atomic<bool> cancel{false};
  auto parallel = ReconstructStackFrames(m, SourceOf(decoder), SffOptions{}, {}, cancel);
  ASSERT_TRUE(parallel.ok()) << parallel.status().ToString();
  EXPECT_EQ(decoder.decoded_frames(), 8 + 6);  // 6 dropped frames decoded again
  auto sequential = ReconstructStackFolder(dir, m, SffOptions{}, {}, cancel);
  ASSERT_TRUE(sequential.ok());
  ExpectBitIdentical(*parallel, *sequential);
  fs::remove_all(dir);
}

// A stack that does not fit the budget whole (8 frames, room for 6) keeps only the look-ahead
// (2 frames per decode thread): holding 6 of 300 frames of 24 MP would cost 1 GiB beside the
// engine and save 2 % of the decodes. Dropped frames are decoded again once each, ahead of the
// engine by the pool, and the result does not change.
TEST(StackFrameDecoderTest, AStackLargerThanTheBudgetKeepsOnlyTheLookAhead) {
  const fs::path dir = TempDir("lookahead");
  const StackManifest m = WriteGreyStack(dir);
  const int64_t frame_bytes = 64 * 48;
  StackFrameDecoderOptions o;
  o.threads = 1;
  o.max_kept_bytes = 6 * frame_bytes;
  StackFrameDecoder decoder(dir, m, o);
  ASSERT_TRUE(decoder.Finish().ok());
  const int64_t lookahead = StackFrameDecoder::kLookaheadFramesPerThread * frame_bytes;
  EXPECT_EQ(decoder.peak_kept_bytes(), lookahead);
  EXPECT_EQ(decoder.kept_bytes(), lookahead);
  std::atomic<bool> cancel{false};
  int64_t peak_during = 0;
  auto on_frame = [&](int, int, double, const FrameStatistics&) {
    peak_during = std::max(peak_during, decoder.kept_bytes());
  };
  auto parallel = ReconstructStackFrames(m, SourceOf(decoder), SffOptions{}, on_frame, cancel);
  ASSERT_TRUE(parallel.ok()) << parallel.status().ToString();
  EXPECT_LE(peak_during, lookahead);
  EXPECT_EQ(decoder.peak_kept_bytes(), lookahead);
  EXPECT_EQ(decoder.decoded_frames(), 8 + 6);  // the 6 dropped frames once more each
  auto sequential = ReconstructStackFolder(dir, m, SffOptions{}, {}, cancel);
  ASSERT_TRUE(sequential.ok());
  ExpectBitIdentical(*parallel, *sequential);
  // A stack that fits whole keeps every frame, decoded once.
  o.max_kept_bytes = 8 * frame_bytes;
  StackFrameDecoder whole(dir, m, o);
  ASSERT_TRUE(whole.Finish().ok());
  EXPECT_EQ(whole.kept_bytes(), 8 * frame_bytes);
  fs::remove_all(dir);
}

// Frame 2 is not an image and frame 5 has another size; decoding 7..0 (frame 5 finishes before
// frame 2) still reports frame 2, with ValidateStackFrames' message; with frame 2 repaired,
// frame 5's size.
TEST(StackFrameDecoderTest, FirstBadFrameInZOrderIsReportedWhateverFinishedFirst) {
  const fs::path dir = TempDir("bad");
  const StackManifest m = WriteGreyStack(dir);
  const std::string good2 = (dir / "good2.png").string();
  fs::copy_file(dir / m.frames[2].file, good2);
  std::ofstream(dir / m.frames[2].file, std::ios::binary | std::ios::trunc) << "not an image";
  ASSERT_TRUE(cv::imwrite((dir / m.frames[5].file).string(), cv::Mat(20, 30, CV_8UC1, cv::Scalar(9))));
  const Status sequential = ValidateStackFrames(dir, m);
  ASSERT_EQ(sequential.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(sequential.message().find("frame 2 (frame_0002.png)"), std::string::npos) << sequential.message();
  for (int threads : {1, 2, 4}) {
    StackFrameDecoderOptions o;
    o.threads = threads;
    StackFrameDecoder decoder(dir, m, o);
    for (int i = int(m.frames.size()) - 1; i >= 0; --i) decoder.Submit(i);
    const Status s = decoder.Finish();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(s.message(), sequential.message()) << threads << " threads";
  }
  fs::remove(dir / m.frames[2].file);
  fs::copy_file(good2, dir / m.frames[2].file);
  StackFrameDecoder decoder(dir, m, {});
  const Status s = decoder.Finish();  // nothing submitted: Finish queues every frame itself
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "frame 5 (frame_0005.png): size 30x20 differs from frame 0 (64x48)");
  EXPECT_EQ(s.message(), ValidateStackFrames(dir, m).message());
  fs::remove_all(dir);
}

}  // namespace
}  // namespace inspection
