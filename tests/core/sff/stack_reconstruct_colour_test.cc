// ReconstructStackFolder on colour stacks (core/sff/stack_reconstruct.h): focus on luminance, the
// all-in-focus image in colour, its luminance exactly the engine's grey all-in-focus of the same
// stack stored as grey luminance frames, and mixed grey/colour frames refused naming the frame.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "core/io/colour.h"
#include "core/io/stack.h"
#include "core/sff/stack_reconstruct.h"
#include "tests/core/colour_stack_synthetic.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;
using testing::ColourStackSpec;

fs::path TempDir(const std::string& tag) {
  const fs::path dir = fs::temp_directory_path() / ("stack_colour_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  return dir;
}

// The same stack with each frame replaced by its luminance (core/io/colour.h).
StackManifest WriteLuminanceCopy(const fs::path& from, const StackManifest& m, const fs::path& to) {
  fs::create_directories(to);
  for (size_t i = 0; i < m.frames.size(); ++i) {
    auto grey = LoadStackFrame(from, m, i);
    EXPECT_TRUE(grey.ok());
    cv::imwrite((to / m.frames[i].file).string(), *grey);
  }
  EXPECT_TRUE(WriteStackManifest(to, m).ok());
  return m;
}

void ExpectColourMatchesGreyEngine(bool sixteen_bit) {
  ColourStackSpec spec;
  spec.sixteen_bit = sixteen_bit;
  const fs::path dir = TempDir(sixteen_bit ? "c16" : "c8"), grey_dir = TempDir(sixteen_bit ? "g16" : "g8");
  const StackManifest m = testing::WriteColourStack(dir, spec);
  WriteLuminanceCopy(dir, m, grey_dir);
  std::atomic<bool> cancel{false};
  SffOptions o;
  auto colour = ReconstructStackFolder(dir, m, o, {}, cancel);
  auto grey = ReconstructStackFolder(grey_dir, m, o, {}, cancel);
  ASSERT_TRUE(colour.ok()) << colour.status().ToString();
  ASSERT_TRUE(grey.ok()) << grey.status().ToString();
  EXPECT_EQ(colour->all_in_focus.type(), sixteen_bit ? CV_16UC3 : CV_8UC3);
  EXPECT_EQ(grey->all_in_focus.type(), sixteen_bit ? CV_16UC1 : CV_8UC1);
  // Depth and confidence are those of the luminance stack, bit for bit.
  cv::Mat depth_colour = colour->depth_um.clone(), depth_grey = grey->depth_um.clone();
  cv::patchNaNs(depth_colour, -1.0);
  cv::patchNaNs(depth_grey, -1.0);
  EXPECT_EQ(cv::norm(depth_colour, depth_grey, cv::NORM_INF), 0.0);
  EXPECT_GT(grey->valid_fraction, 0.9);
  EXPECT_EQ(cv::norm(colour->confidence, grey->confidence, cv::NORM_INF), 0.0);
  auto luma = LuminanceOf(colour->all_in_focus);
  ASSERT_TRUE(luma.ok());
  EXPECT_EQ(cv::norm(*luma, grey->all_in_focus, cv::NORM_INF), 0.0);
  // And it is the in-focus frame's colour: the sharp texture where each half is in focus.
  const cv::Mat tex = testing::ColourTexture(spec);
  const int border = o.window_px;  // away from the image border and the depth step
  int same = 0, total = 0;
  for (int y = border; y < tex.rows - border; ++y) {
    for (int x = border; x < tex.cols - border; ++x) {
      if (std::abs(x - tex.cols / 2) < border) continue;
      ++total;
      const bool equal = sixteen_bit ? colour->all_in_focus.at<cv::Vec3w>(y, x) == tex.at<cv::Vec3w>(y, x)
                                     : colour->all_in_focus.at<cv::Vec3b>(y, x) == tex.at<cv::Vec3b>(y, x);
      same += equal ? 1 : 0;
    }
  }
  std::printf("colour all-in-focus (%d-bit): %d of %d pixels exactly the in-focus frame's colour\n",
              sixteen_bit ? 16 : 8, same, total);
  EXPECT_GT(double(same) / total, 0.97);
  fs::remove_all(dir);
  fs::remove_all(grey_dir);
}

TEST(StackReconstructColourTest, EightBitColourKeepsColourWithTheGreyEnginesChoice) {
  ExpectColourMatchesGreyEngine(false);
}

TEST(StackReconstructColourTest, SixteenBitColourKeepsColourWithTheGreyEnginesChoice) {
  ExpectColourMatchesGreyEngine(true);
}

TEST(StackReconstructColourTest, GreyFrameInAColourStackNamesTheFrame) {
  ColourStackSpec spec;
  const fs::path dir = TempDir("mixed");
  const StackManifest m = testing::WriteColourStack(dir, spec, /*grey_frame=*/4);
  std::atomic<bool> cancel{false};
  auto r = ReconstructStackFolder(dir, m, SffOptions{}, {}, cancel);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("frame 4 (f4.png): grey differs from frame 0 (colour (3 channels))"),
            std::string::npos)
      << r.status().ToString();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace inspection
