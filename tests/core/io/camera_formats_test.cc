// Frames from photographers' cameras (core/io/stack.h, core/io/raw_frame_decode.h): a camera RAW
// (a DNG written here, since LibRaw cannot write RAW) decodes to the expected linear 16-bit
// colour values in the file's orientation; a JPEG's EXIF orientation is applied on the file and
// the in-memory path alike; a stack mixing formats is refused naming the file; 16-bit frames of a
// stack that states no bit depth get 16-bit statistics.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "core/io/frame_statistics.h"
#include "core/io/raw_frame_decode.h"
#include "core/io/stack.h"
#include "tests/core/io/dng_writer.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

fs::path TempDir(const std::string& tag) {
  const fs::path dir = fs::temp_directory_path() / ("camera_formats_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string ReadBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// 64 x 48: left half one colour, right half another (12-bit values, BGR order).
const cv::Vec3w kLeft(1000, 2000, 3000);   // B, G, R
const cv::Vec3w kRight(2400, 1200, 600);

cv::Mat TwoColourScene() {
  cv::Mat bgr(48, 64, CV_16UC3, cv::Scalar(kLeft[0], kLeft[1], kLeft[2]));
  bgr.colRange(32, 64).setTo(cv::Scalar(kRight[0], kRight[1], kRight[2]));
  return bgr;
}

// The developed value of a 12-bit raw value: black 0, white 4095 -> 0..65535, linear.
double Developed(int raw) { return raw * 65535.0 / 4095.0; }

TEST(CameraRaw, DngDecodesToLinear16BitColourWithTheWrittenValues) {
  const fs::path dir = TempDir("dng");
  const fs::path dng = dir / "frame.dng";
  ASSERT_TRUE(testing::WriteCfaDng(dng.string(), testing::BayerRggbOf(TwoColourScene())));
  EXPECT_TRUE(IsRawFrameFile("frame.DNG"));
  EXPECT_TRUE(IsRawFrameFile("a/b.nef"));
  EXPECT_FALSE(IsRawFrameFile("frame.tiff"));

  auto from_file = DecodeRawFrameFile(dng.string(), "frame 0 (frame.dng)");
  ASSERT_TRUE(from_file.ok()) << from_file.status().message();
  const cv::Mat& img = *from_file;
  ASSERT_EQ(img.type(), CV_16UC3);
  ASSERT_EQ(img.size(), cv::Size(64, 48));
  // Away from the colour edge and the border (demosaicing mixes neighbours there), every channel
  // is the raw value scaled linearly: no gamma, no auto-brightness, no colour matrix.
  for (const auto& [x, expected] : {std::pair{12, kLeft}, std::pair{52, kRight}}) {
    for (int y = 8; y < 40; y += 7) {
      const cv::Vec3w p = img.at<cv::Vec3w>(y, x);
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(p[c], Developed(expected[c]), 0.005 * 65535) << "x " << x << " y " << y << " channel " << c;
      }
    }
  }
  // The same pixels from the bytes in memory (a stored scan's archive entry).
  auto from_bytes = DecodeRawFrame(ReadBytes(dng), "frame 0 (frame.dng)");
  ASSERT_TRUE(from_bytes.ok()) << from_bytes.status().message();
  EXPECT_EQ(cv::norm(*from_bytes, img, cv::NORM_INF), 0.0);

  // Through the stack folder: a DNG frame is an ordinary 16-bit colour frame.
  StackManifest m;
  m.frames = {{"frame.dng", 0.0, 0.0, ""}};
  auto image = LoadStackFrameImage(dir, m, 0);
  ASSERT_TRUE(image.ok()) << image.status().message();
  ASSERT_TRUE(image->is_colour());
  EXPECT_EQ(image->grey.type(), CV_16UC1);
  EXPECT_EQ(cv::norm(image->colour, img, cv::NORM_INF), 0.0);
  fs::remove_all(dir);
}

TEST(CameraRaw, OrientationFlagIsApplied) {
  const fs::path dir = TempDir("dng_orientation");
  const cv::Mat mosaic = testing::BayerRggbOf(TwoColourScene());
  ASSERT_TRUE(testing::WriteCfaDng((dir / "upright.dng").string(), mosaic, 4095, 1));
  ASSERT_TRUE(testing::WriteCfaDng((dir / "rotated.dng").string(), mosaic, 4095, 6));
  auto upright = DecodeRawFrameFile((dir / "upright.dng").string(), "upright");
  auto rotated = DecodeRawFrameFile((dir / "rotated.dng").string(), "rotated");
  ASSERT_TRUE(upright.ok() && rotated.ok());
  // Orientation 6: shown rotated 90 degrees clockwise, so the left half comes on top.
  ASSERT_EQ(rotated->size(), cv::Size(48, 64));
  cv::Mat expected;
  cv::rotate(*upright, expected, cv::ROTATE_90_CLOCKWISE);
  EXPECT_EQ(cv::norm(*rotated, expected, cv::NORM_INF), 0.0);
  EXPECT_NEAR(rotated->at<cv::Vec3w>(10, 24)[2], Developed(kLeft[2]), 0.005 * 65535);   // top: left's red
  EXPECT_NEAR(rotated->at<cv::Vec3w>(54, 24)[2], Developed(kRight[2]), 0.005 * 65535);  // bottom: right's
  fs::remove_all(dir);
}

TEST(CameraRaw, NotARawFileIsInvalidArgumentNamingTheFrame) {
  const fs::path dir = TempDir("bad_dng");
  std::ofstream(dir / "bad.dng") << "not a raw file at all";
  StackManifest m;
  m.frames = {{"bad.dng", 0.0, 0.0, ""}};
  auto image = DecodeStackFrame(dir, m, 0);
  ASSERT_FALSE(image.ok());
  EXPECT_EQ(image.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(image.status().message().rfind("frame 0 (bad.dng): cannot open camera RAW: ", 0), 0u)
      << image.status().message();
  fs::remove_all(dir);
}

// A JPEG with an EXIF APP1 segment (TIFF header, one IFD entry: Orientation) inserted after APP0.
std::string JpegWithOrientation(const cv::Mat& bgr, uint16_t orientation) {
  std::vector<uchar> jpeg;
  EXPECT_TRUE(cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 100}));
  std::string bytes(jpeg.begin(), jpeg.end());
  const std::string tiff = std::string("II\x2a\x00\x08\x00\x00\x00", 8) +  // little-endian, IFD at 8
                           std::string("\x01\x00", 2) +                     // one entry
                           std::string("\x12\x01\x03\x00\x01\x00\x00\x00", 8) +  // 0x0112 SHORT x1
                           std::string(1, char(orientation & 0xff)) + std::string(1, char(orientation >> 8)) +
                           std::string("\x00\x00", 2) + std::string("\x00\x00\x00\x00", 4);  // no next IFD
  const std::string payload = std::string("Exif\x00\x00", 6) + tiff;
  const size_t length = payload.size() + 2;
  const std::string app1 = std::string("\xff\xe1", 2) + char(length >> 8) + char(length & 0xff) + payload;
  size_t at = 2;  // after SOI; after APP0 (JFIF) when there is one
  if (uchar(bytes[2]) == 0xff && uchar(bytes[3]) == 0xe0) at = 4 + (size_t(uchar(bytes[4])) << 8 | uchar(bytes[5]));
  bytes.insert(at, app1);
  return bytes;
}

TEST(ExifOrientation, JpegFramesAreTurnedAsTheCameraHeldThem) {
  const fs::path dir = TempDir("exif");
  // 64 x 32: a bright left half, a dark right half, a grey stripe on the top rows.
  cv::Mat bgr(32, 64, CV_8UC3, cv::Scalar(40, 40, 40));
  bgr.colRange(0, 32).setTo(cv::Scalar(220, 200, 180));
  bgr.rowRange(0, 4).setTo(cv::Scalar(128, 128, 128));
  {
    std::ofstream(dir / "upright.jpg", std::ios::binary) << JpegWithOrientation(bgr, 1);
    std::ofstream(dir / "rotated.jpg", std::ios::binary) << JpegWithOrientation(bgr, 6);
  }
  StackManifest m;
  m.frames = {{"upright.jpg", 0.0, 0.0, ""}, {"rotated.jpg", 1.0, 0.0, ""}};
  auto upright = DecodeStackFrame(dir, m, 0);
  auto rotated = DecodeStackFrame(dir, m, 1);
  ASSERT_TRUE(upright.ok() && rotated.ok());
  ASSERT_EQ(upright->size(), cv::Size(64, 32));
  ASSERT_EQ(upright->type(), CV_8UC3);
  ASSERT_EQ(rotated->size(), cv::Size(32, 64));  // orientation 6: 90 degrees clockwise
  cv::Mat expected;
  cv::rotate(*upright, expected, cv::ROTATE_90_CLOCKWISE);
  EXPECT_EQ(cv::norm(*rotated, expected, cv::NORM_INF), 0.0);
  EXPECT_GT(rotated->at<cv::Vec3b>(10, 16)[0], 200);  // the bright (left) half is on top now
  EXPECT_LT(rotated->at<cv::Vec3b>(54, 16)[0], 60);
  // The in-memory decode (stored scans) turns it the same way.
  auto in_memory = DecodeStackFrameBytes(ReadBytes(dir / "rotated.jpg"), m, 1);
  ASSERT_TRUE(in_memory.ok());
  EXPECT_EQ(cv::norm(*in_memory, *rotated, cv::NORM_INF), 0.0);
  // A grey JPEG stays one channel.
  cv::Mat grey;
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  ASSERT_TRUE(cv::imwrite((dir / "grey.jpg").string(), grey));
  m.frames[0].file = "grey.jpg";
  auto grey_frame = DecodeStackFrame(dir, m, 0);
  ASSERT_TRUE(grey_frame.ok());
  EXPECT_EQ(grey_frame->type(), CV_8UC1);
  fs::remove_all(dir);
}

TEST(StackFormats, MixedFormatsAreRefusedNamingTheFile) {
  const std::string manifest = R"({"frames": [{"file": "a1.png", "z_um": 0}, {"file": "a2.PNG", "z_um": 1},
      {"file": "noext", "z_um": 2}, {"file": "a3.jpg", "z_um": 3}]})";
  auto m = ParseStackManifest(manifest);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(m.status().message(),
            "stack.json: frames[3].file 'a3.jpg' is JPEG but frames[0].file 'a1.png' is PNG; the frames of a stack "
            "share one format");
  auto raws = ParseStackManifest(R"({"frames": [{"file": "a.nef", "z_um": 0}, {"file": "b.NEF", "z_um": 1},
      {"file": "c.dng", "z_um": 2}]})");
  ASSERT_FALSE(raws.ok());
  EXPECT_EQ(raws.status().message(),
            "stack.json: frames[2].file 'c.dng' is camera RAW (DNG) but frames[0].file 'a.nef' is camera RAW (NEF); "
            "the frames of a stack share one format");
  EXPECT_TRUE(ParseStackManifest(R"({"frames": [{"file": "a.tif", "z_um": 0}, {"file": "b.TIFF", "z_um": 1},
      {"file": "c", "z_um": 2}]})").ok());
  EXPECT_EQ(FrameFileFormat("x.arw"), "camera RAW (ARW)");
  EXPECT_EQ(FrameFileFormat("dir.d/frame"), "");
}

TEST(StackFormats, SixteenBitFramesOfAStackWithoutABitDepthUseTheirFullRange) {
  cv::Mat frame(10, 10, CV_16UC1, cv::Scalar(30000));
  frame.row(0).setTo(65535);
  const FrameStatistics s = ComputeFrameStatistics(frame, 8);  // stack.json's default bit depth
  EXPECT_NEAR(s.saturated_percent, 10.0, 1e-9);
  EXPECT_NEAR(s.mean_grey, (90 * 30000.0 + 10 * 65535.0) / 100.0 * 255.0 / 65535.0, 1e-6);
  EXPECT_EQ(ComputeFrameStatistics(frame, 12).saturated_percent, 100.0);  // 12 bits stated: 4095 is full
}

}  // namespace
}  // namespace inspection
