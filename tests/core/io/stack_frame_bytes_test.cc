// Decoding a frame from its file's bytes in memory (DecodeStackFrameInMemory, core/io/stack_frame_decoder.h;
// DecodeStackFrameBytes, core/io/stack.h), as a stored scan's frames are read from its archive: the
// pixels of DecodeStackFrame on the same file for every stack format (PNG grey/colour 8/16 bit,
// TIFF, JPEG), and the same errors naming the frame for what is not a frame.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "core/io/stack.h"
#include "core/io/stack_frame_decoder.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

class StackFrameBytesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("stack_frame_bytes_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A manifest whose frame 1 is `file` (frames 0 and 2 only complete the stack).
  StackManifest ManifestFor(const std::string& file) {
    StackManifest m;
    m.frames = {{"a.png", 0.0, 0.0, ""}, {file, 1.0, 0.0, ""}, {"c.png", 2.0, 0.0, ""}};
    return m;
  }
  std::string Bytes(const std::string& file) {
    std::ifstream in(dir_ / file, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }

  fs::path dir_;
};

cv::Mat Pattern(int type) {
  cv::Mat m(37, 53, type);
  cv::randu(m, 0, CV_MAT_DEPTH(type) == CV_16U ? 65535 : 255);
  return m;
}

TEST_F(StackFrameBytesTest, EveryFormatDecodesToTheFilesPixels) {
  const struct {
    const char* file;
    int type;
  } cases[] = {{"g8.png", CV_8UC1},    {"g16.png", CV_16UC1}, {"c8.png", CV_8UC3},
               {"c16.png", CV_16UC3},  {"g8.tiff", CV_8UC1},  {"g16.tif", CV_16UC1},
               {"c16.tiff", CV_16UC3}, {"g8.jpg", CV_8UC1},   {"c8.jpg", CV_8UC3}};
  for (const auto& c : cases) {
    ASSERT_TRUE(cv::imwrite((dir_ / c.file).string(), Pattern(c.type))) << c.file;
    const StackManifest m = ManifestFor(c.file);
    auto from_file = DecodeStackFrame(dir_, m, 1);
    auto in_memory = DecodeStackFrameInMemory(Bytes(c.file), m, 1);
    ASSERT_TRUE(from_file.ok()) << c.file;
    ASSERT_TRUE(in_memory.ok()) << c.file << ": " << in_memory.status().ToString();
    EXPECT_EQ(in_memory->type(), c.type) << c.file;
    ASSERT_EQ(in_memory->size(), from_file->size()) << c.file;
    ASSERT_EQ(in_memory->type(), from_file->type()) << c.file;
    EXPECT_EQ(0, std::memcmp(in_memory->data, from_file->data, from_file->total() * from_file->elemSize())) << c.file;
  }
}

TEST_F(StackFrameBytesTest, WhatIsNoFrameGivesTheFileDecodesError) {
  // Not an image, an empty file, a cut PNG, 4 channels, float pixels.
  std::ofstream(dir_ / "text.png") << "not an image";
  std::ofstream(dir_ / "empty.png");
  ASSERT_TRUE(cv::imwrite((dir_ / "whole.png").string(), Pattern(CV_8UC1)));
  const std::string whole = Bytes("whole.png");
  std::ofstream(dir_ / "cut.png", std::ios::binary) << whole.substr(0, whole.size() / 2);
  ASSERT_TRUE(cv::imwrite((dir_ / "bgra.png").string(), cv::Mat(8, 8, CV_8UC4, cv::Scalar(1, 2, 3, 4))));
  ASSERT_TRUE(cv::imwrite((dir_ / "float.tiff").string(), cv::Mat(8, 8, CV_32FC1, cv::Scalar(0.5))));
  for (const char* file : {"text.png", "empty.png", "cut.png", "bgra.png", "float.tiff"}) {
    const StackManifest m = ManifestFor(file);
    auto from_file = DecodeStackFrame(dir_, m, 1);
    auto in_memory = DecodeStackFrameInMemory(Bytes(file), m, 1);
    ASSERT_FALSE(from_file.ok()) << file;
    ASSERT_FALSE(in_memory.ok()) << file;
    EXPECT_EQ(in_memory.status().code(), StatusCode::kInvalidArgument) << file;
    EXPECT_EQ(in_memory.status().message(), from_file.status().message()) << file;
    EXPECT_EQ(in_memory.status().message().rfind(std::string("frame 1 (") + file + "): ", 0), 0u)
        << in_memory.status().message();
  }
}

}  // namespace
}  // namespace inspection
