// Stack folder format: manifest parsing and frame validation name the field or frame at fault.
#include "core/stack.h"

#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

namespace inspection {
namespace {
namespace fs = std::filesystem;

class StackTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("stack_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  StackManifest WriteFrames(int n, cv::Size size = {32, 24}) {
    StackManifest m;
    m.pixel_size_um = 0.74;
    for (int i = 0; i < n; ++i) {
      const std::string name = "frame_" + std::to_string(i) + ".png";
      cv::imwrite((dir_ / name).string(), cv::Mat(size, CV_8UC1, cv::Scalar(10 * i)));
      m.frames.push_back({name, 5.0 * i, 1000.0, "uniform:128"});
    }
    EXPECT_TRUE(WriteStackManifest(dir_, m).ok());
    return m;
  }

  fs::path dir_;
};

TEST_F(StackTest, RoundTripsManifest) {
  WriteFrames(4);
  auto m = ReadStackManifest(dir_);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_DOUBLE_EQ(m->pixel_size_um, 0.74);
  ASSERT_EQ(m->frames.size(), 4u);
  EXPECT_DOUBLE_EQ(m->frames[3].z_um, 15.0);
  EXPECT_EQ(m->frames[2].pattern, "uniform:128");
  EXPECT_TRUE(ValidateStackFrames(dir_, *m).ok());
  auto f = LoadStackFrame(dir_, *m, 2);
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f->at<uint8_t>(0, 0), 20);
}

TEST_F(StackTest, MissingManifestIsInvalidArgument) {
  auto m = ReadStackManifest(dir_);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(m.status().message().find("stack.json is missing"), std::string::npos);
}

TEST_F(StackTest, NonMonotonicZNamesTheFrame) {
  auto m = ParseStackManifest(R"({"pixel_size_um":1,"frames":[
      {"file":"a.png","z_um":0},{"file":"b.png","z_um":5},{"file":"c.png","z_um":3}]})");
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(m.status().message().find("frames[2].z_um"), std::string::npos) << m.status().message();
}

TEST_F(StackTest, DuplicateZNamesTheFrame) {
  auto m = ParseStackManifest(R"({"pixel_size_um":1,"frames":[
      {"file":"a.png","z_um":0},{"file":"b.png","z_um":0},{"file":"c.png","z_um":3}]})");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("frames[1].z_um"), std::string::npos) << m.status().message();
}

TEST_F(StackTest, RejectsPathEscapingTheFolder) {
  auto m = ParseStackManifest(R"({"pixel_size_um":1,"frames":[
      {"file":"../a.png","z_um":0},{"file":"b.png","z_um":1},{"file":"c.png","z_um":3}]})");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("frames[0].file"), std::string::npos);
}

TEST_F(StackTest, MissingPixelSizeNamesTheField) {
  auto m = ParseStackManifest(R"({"frames":[]})");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("pixel_size_um"), std::string::npos);
}

TEST_F(StackTest, FewerThanThreeFramesIsRejected) {
  auto m = ParseStackManifest(R"({"pixel_size_um":1,"frames":[{"file":"a.png","z_um":0},{"file":"b.png","z_um":1}]})");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("at least 3"), std::string::npos);
}

TEST_F(StackTest, FramesOfDifferentSizesNameTheFrame) {
  StackManifest m = WriteFrames(4);
  cv::imwrite((dir_ / m.frames[2].file).string(), cv::Mat(cv::Size(16, 16), CV_8UC1, cv::Scalar(1)));
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("frame 2 (frame_2.png): size 16x16 differs from frame 0 (32x24)"), std::string::npos)
      << s.message();
}

TEST_F(StackTest, MixedBitDepthNamesTheFrame) {
  StackManifest m = WriteFrames(3);
  cv::imwrite((dir_ / m.frames[1].file).string(), cv::Mat(cv::Size(32, 24), CV_16UC1, cv::Scalar(1000)));
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame 1 (frame_1.png): bit depth 16"), std::string::npos) << s.message();
}

TEST_F(StackTest, UnreadableFrameNamesTheFrame) {
  StackManifest m = WriteFrames(3);
  std::ofstream(dir_ / m.frames[1].file) << "not an image";
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame 1 (frame_1.png): cannot decode"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace inspection
