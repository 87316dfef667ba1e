// Framebuffer projector against a file-backed stand-in: the exact bytes blitted for 8/16/24/32
// bpp, stride and panning offsets, the calibrated region and flips, and failure statuses.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "devices/drivers/framebuffer_projector.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

class FramebufferProjectorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = fs::temp_directory_path() / ("fb_test_" + std::to_string(::getpid()) + "_" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove(path_);
    std::ofstream(path_).close();
  }
  void TearDown() override { fs::remove(path_); }

  std::vector<uint8_t> FileBytes() const {
    std::ifstream f(path_, std::ios::binary);
    return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
  }
  FramebufferProjectorOptions Options(FramebufferMode mode) const {
    FramebufferProjectorOptions o;
    o.device = path_.string();
    o.mode = mode;
    return o;
  }
  fs::path path_;
};

// 3x2 pattern with distinct values.
cv::Mat Pattern3x2() { return (cv::Mat_<uint8_t>(2, 3) << 0, 128, 255, 16, 32, 64); }

TEST_F(FramebufferProjectorTest, Xrgb8888RegionBlitWritesExactBytes) {
  FramebufferMode m;
  m.width = 5;
  m.height = 4;
  m.bits_per_pixel = 32;  // XRGB8888: blue 0, green 8, red 16, no alpha
  FramebufferProjectorOptions o = Options(m);
  o.region_x = 1;
  o.region_y = 2;
  o.region_width = 3;
  o.region_height = 2;
  FramebufferProjector p(o);
  ASSERT_TRUE(p.Connect().ok());
  EXPECT_EQ(p.resolution(), cv::Size(3, 2));
  ASSERT_TRUE(p.Show(Pattern3x2()).ok());
  std::vector<uint8_t> bytes = FileBytes();
  ASSERT_EQ(bytes.size(), 5u * 4u * 4u);
  std::vector<uint8_t> expected(bytes.size(), 0);
  const uint8_t g[2][3] = {{0, 128, 255}, {16, 32, 64}};
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x) {
      const size_t at = static_cast<size_t>(((2 + y) * 5 + (1 + x)) * 4);
      expected[at] = expected[at + 1] = expected[at + 2] = g[y][x];
    }
  EXPECT_EQ(bytes, expected);
}

TEST_F(FramebufferProjectorTest, Rgb565PacksTopBitsOfEachChannel) {
  FramebufferMode m;
  m.width = 3;
  m.height = 2;
  m.bits_per_pixel = 16;
  m.red = {11, 5};
  m.green = {5, 6};
  m.blue = {0, 5};
  FramebufferProjector p(Options(m));
  ASSERT_TRUE(p.Connect().ok());
  ASSERT_TRUE(p.Show(Pattern3x2()).ok());
  // 128 -> r 16, g 32, b 16 -> 0x8410; 255 -> 0xFFFF; 16 -> r2 g4 b2 -> 0x1082; 32 -> 0x2104; 64 -> 0x4208.
  EXPECT_EQ(FileBytes(),
            (std::vector<uint8_t>{0x00, 0x00, 0x10, 0x84, 0xFF, 0xFF, 0x82, 0x10, 0x04, 0x21, 0x08, 0x42}));
}

TEST_F(FramebufferProjectorTest, Bgr888WithStrideAndPanOffset) {
  FramebufferMode m;
  m.width = 3;
  m.height = 2;
  m.bits_per_pixel = 24;
  m.line_length_bytes = 12;  // 3 padding bytes per line
  m.y_offset = 1;            // visible area starts at line 1 of the virtual screen
  FramebufferProjector p(Options(m));
  ASSERT_TRUE(p.Connect().ok());
  ASSERT_TRUE(p.Show(Pattern3x2()).ok());
  std::vector<uint8_t> expected(12 * 3, 0);
  const uint8_t g[2][3] = {{0, 128, 255}, {16, 32, 64}};
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 3; ++c) expected[static_cast<size_t>((1 + y) * 12 + x * 3 + c)] = g[y][x];
  EXPECT_EQ(FileBytes(), expected);
}

TEST_F(FramebufferProjectorTest, EightBitGreyWithFlipsAndOpaqueAlpha) {
  FramebufferMode m;
  m.width = 3;
  m.height = 2;
  m.bits_per_pixel = 8;
  FramebufferProjectorOptions o = Options(m);
  o.flip_horizontal = true;
  o.flip_vertical = true;
  FramebufferProjector p(o);
  ASSERT_TRUE(p.Connect().ok());
  ASSERT_TRUE(p.Show(Pattern3x2()).ok());
  EXPECT_EQ(FileBytes(), (std::vector<uint8_t>{64, 32, 16, 255, 128, 0}));

  FramebufferMode argb;
  argb.width = 1;
  argb.height = 1;
  argb.bits_per_pixel = 32;
  argb.transp = {24, 8};
  FramebufferProjector q(Options(argb));
  ASSERT_TRUE(q.Connect().ok());
  uint8_t px[4];
  q.EncodePixel(200, px);
  EXPECT_EQ(std::vector<uint8_t>(px, px + 4), (std::vector<uint8_t>{200, 200, 200, 255}));
}

TEST_F(FramebufferProjectorTest, ShowUniformFillsTheRegion) {
  FramebufferMode m;
  m.width = 4;
  m.height = 2;
  m.bits_per_pixel = 8;
  FramebufferProjector p(Options(m));
  ASSERT_TRUE(p.Connect().ok());
  ASSERT_TRUE(p.ShowUniform(128).ok());
  EXPECT_EQ(FileBytes(), std::vector<uint8_t>(8, 128));
  EXPECT_EQ(p.Show(cv::Mat(1, 4, CV_8UC1)).code(), StatusCode::kInvalidArgument);
}

TEST_F(FramebufferProjectorTest, FailuresNameTheCause) {
  FramebufferProjectorOptions no_mode;
  no_mode.device = path_.string();
  FramebufferProjector a(no_mode);
  Status s = a.Connect();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), ::testing::HasSubstr("projector.mode"));

  FramebufferProjectorOptions absent;
  absent.device = "/dev/fb-does-not-exist";
  FramebufferProjector b(absent);
  EXPECT_EQ(b.Connect().code(), StatusCode::kUnavailable);
  EXPECT_FALSE(b.info().connected);
  EXPECT_THAT(b.info().detail, ::testing::HasSubstr("/dev/fb-does-not-exist"));
  EXPECT_EQ(b.ShowUniform(0).code(), StatusCode::kUnavailable);

  FramebufferProjectorOptions not_fb;
  not_fb.device = "/dev/null";  // a character device without FBIOGET_VSCREENINFO
  FramebufferProjector c(not_fb);
  s = c.Connect();
  EXPECT_EQ(s.code(), StatusCode::kUnavailable);
  EXPECT_THAT(s.message(), ::testing::HasSubstr("not a framebuffer"));

  FramebufferMode m;
  m.width = 4;
  m.height = 2;
  FramebufferProjectorOptions too_big = Options(m);
  too_big.region_x = 2;
  too_big.region_width = 3;
  FramebufferProjector d(too_big);
  EXPECT_EQ(d.Connect().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace inspection
