// ReconstructStackFolder (core/sff/stack_reconstruct.h), the one stack folder -> SFF engine loop:
// same depth as the in-memory engine, per-frame progress with the frame's statistics, cancel,
// and errors naming the unreadable frame.
#include "core/sff/stack_reconstruct.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "core/io/stack.h"
#include "tests/core/sff_synthetic.h"

namespace inspection {
namespace {

using testing::BitIdentical;
using testing::TiltedPlaneStack;
using testing::UniformZ;

TEST(StackReconstructTest, ReconstructsTheFolderReportsFramesAndNamesUnreadableFrame) {
  const auto dir = std::filesystem::temp_directory_path() / ("stack_reconstruct_test_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const auto s = TiltedPlaneStack(cv::Size(48, 32), UniformZ(6, 0.0, 1.0), 2.0, 0.02, 0.02);
  StackManifest m;
  m.pixel_size_um = 1.0;
  for (size_t k = 0; k < s.frames.size(); ++k) {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%04zu.png", k);
    ASSERT_TRUE(cv::imwrite((dir / name).string(), s.frames[k]));
    m.frames.push_back({name, s.z_um[k], 0.0, "uniform:128"});
  }
  ASSERT_TRUE(WriteStackManifest(dir, m).ok());
  auto manifest = ReadStackManifest(dir);
  ASSERT_TRUE(manifest.ok()) << manifest.status().ToString();

  std::atomic<bool> cancel{false};
  std::vector<int> indices;
  std::vector<double> z_seen;
  auto on_frame = [&](int i, int n, double z_um, const FrameStatistics& st) {
    indices.push_back(i);
    z_seen.push_back(z_um);
    EXPECT_EQ(n, 6);
    EXPECT_NEAR(st.mean_grey, cv::mean(s.frames[size_t(i)])[0], 1e-9) << "frame " << i;
  };
  auto ok = ReconstructStackFolder(dir, *manifest, SffOptions{}, on_frame, cancel);
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  auto in_memory = SffEngine::ReconstructInMemory(SffOptions{}, s.frames, s.z_um);
  ASSERT_TRUE(in_memory.ok());
  EXPECT_TRUE(BitIdentical(ok->depth_um, in_memory->depth_um));
  EXPECT_TRUE(BitIdentical(ok->all_in_focus, in_memory->all_in_focus));
  EXPECT_EQ(indices, (std::vector<int>{0, 1, 2, 3, 4, 5}));
  EXPECT_EQ(z_seen, s.z_um);

  cancel = true;
  auto cancelled = ReconstructStackFolder(dir, *manifest, SffOptions{}, nullptr, cancel);
  EXPECT_EQ(cancelled.status().code(), StatusCode::kCancelled);
  EXPECT_NE(cancelled.status().message().find("frame 0"), std::string::npos) << cancelled.status().ToString();
  cancel = false;

  std::ofstream(dir / "frame_0003.png", std::ios::trunc) << "garbage";
  auto bad = ReconstructStackFolder(dir, *manifest, SffOptions{}, nullptr, cancel);
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("frame_0003.png"), std::string::npos) << bad.status().ToString();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace inspection
