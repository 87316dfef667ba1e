// Tests of the depth map exports: exact round trips, format tags, atomic writes, preview colours.
#include "core/depth_export.h"

#include <tiffio.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>

#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

namespace fs = std::filesystem;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

class DepthExportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("depth_export_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // 13x7 ramp in µm with two NaN holes; values not representable in few bits.
  static cv::Mat SampleDepth() {
    cv::Mat d(7, 13, CV_32F);
    for (int y = 0; y < d.rows; ++y)
      for (int x = 0; x < d.cols; ++x) d.at<float>(y, x) = -3.25f + 0.37f * x + 1.1f * y + 1e-4f * x * y;
    d.at<float>(2, 5) = kNaN;
    d.at<float>(6, 12) = kNaN;
    return d;
  }

  static bool BitwiseEqual(const cv::Mat& a, const cv::Mat& b) {
    if (a.size() != b.size() || a.type() != b.type()) return false;
    for (int y = 0; y < a.rows; ++y)
      if (std::memcmp(a.ptr(y), b.ptr(y), a.cols * a.elemSize()) != 0) return false;
    return true;
  }

  fs::path dir_;
};

TEST_F(DepthExportTest, DepthTiffRoundTripIsBitExactWithMeta) {
  const cv::Mat d = SampleDepth();
  DepthExportMeta meta;
  meta.pixel_size_um = 0.74;
  meta.description = "skew5 tenengrad/gaussian";
  const fs::path p = dir_ / "depth.tiff";
  ASSERT_TRUE(WriteDepthTiff(p, d, meta).ok());
  EXPECT_FALSE(fs::exists(p.string() + ".tmp"));

  DepthExportMeta back;
  auto r = ReadDepthTiff(p, &back);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(BitwiseEqual(*r, d));
  EXPECT_NEAR(back.pixel_size_um, 0.74, 1e-6);
  EXPECT_EQ(back.description, "skew5 tenengrad/gaussian");

  // The tags a generic reader relies on.
  TIFF* tif = TIFFOpen(p.c_str(), "r");
  ASSERT_NE(tif, nullptr);
  uint16_t bps = 0, fmt = 0, spp = 0, unit = 0;
  float xres = 0, yres = 0;
  TIFFGetField(tif, TIFFTAG_BITSPERSAMPLE, &bps);
  TIFFGetField(tif, TIFFTAG_SAMPLEFORMAT, &fmt);
  TIFFGetField(tif, TIFFTAG_SAMPLESPERPIXEL, &spp);
  TIFFGetField(tif, TIFFTAG_RESOLUTIONUNIT, &unit);
  TIFFGetField(tif, TIFFTAG_XRESOLUTION, &xres);
  TIFFGetField(tif, TIFFTAG_YRESOLUTION, &yres);
  TIFFClose(tif);
  EXPECT_EQ(bps, 32);
  EXPECT_EQ(fmt, SAMPLEFORMAT_IEEEFP);
  EXPECT_EQ(spp, 1);
  EXPECT_EQ(unit, RESUNIT_CENTIMETER);
  EXPECT_NEAR(xres, 1e4 / 0.74, 0.01);
  EXPECT_NEAR(yres, 1e4 / 0.74, 0.01);
}

TEST_F(DepthExportTest, ReadsFloatTiffWrittenByOpenCv) {
  const cv::Mat d = SampleDepth();
  const fs::path p = dir_ / "cv.tiff";
  ASSERT_TRUE(cv::imwrite(p.string(), d));
  auto r = ReadDepthTiff(p);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(BitwiseEqual(*r, d));
}

TEST_F(DepthExportTest, ReadsTiledTiff) {
  // 40x37 float map in 16x16 tiles, written directly with libtiff.
  cv::Mat d(37, 40, CV_32F);
  for (int y = 0; y < d.rows; ++y)
    for (int x = 0; x < d.cols; ++x) d.at<float>(y, x) = float(y * 1000 + x) * 0.5f;
  const fs::path p = dir_ / "tiled.tiff";
  TIFF* tif = TIFFOpen(p.c_str(), "w");
  ASSERT_NE(tif, nullptr);
  TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, 40u);
  TIFFSetField(tif, TIFFTAG_IMAGELENGTH, 37u);
  TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, uint16_t(1));
  TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, uint16_t(32));
  TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, uint16_t(SAMPLEFORMAT_IEEEFP));
  TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, uint16_t(PHOTOMETRIC_MINISBLACK));
  TIFFSetField(tif, TIFFTAG_TILEWIDTH, 16u);
  TIFFSetField(tif, TIFFTAG_TILELENGTH, 16u);
  std::vector<float> tile(256);
  for (uint32_t ty = 0; ty < 37; ty += 16)
    for (uint32_t tx = 0; tx < 40; tx += 16) {
      std::fill(tile.begin(), tile.end(), -1.f);
      for (uint32_t r = 0; r < 16 && ty + r < 37; ++r)
        for (uint32_t c = 0; c < 16 && tx + c < 40; ++c) tile[r * 16 + c] = d.at<float>(ty + r, tx + c);
      ASSERT_GE(TIFFWriteTile(tif, tile.data(), tx, ty, 0, 0), 0);
    }
  TIFFClose(tif);
  auto r = ReadDepthTiff(p);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(BitwiseEqual(*r, d));
}

TEST_F(DepthExportTest, ReadRejectsMissingAndNonFloatFiles) {
  auto missing = ReadDepthTiff(dir_ / "nope.tiff");
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);

  const fs::path p8 = dir_ / "u8.tiff";
  ASSERT_TRUE(cv::imwrite(p8.string(), cv::Mat(4, 4, CV_8U, cv::Scalar(7))));
  auto r8 = ReadDepthTiff(p8);
  EXPECT_EQ(r8.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r8.status().message().find("not a floating-point TIFF"), std::string::npos);

  const fs::path junk = dir_ / "junk.tiff";
  std::ofstream(junk) << "this is not a tiff";
  EXPECT_EQ(ReadDepthTiff(junk).status().code(), StatusCode::kInvalidArgument);
}

TEST_F(DepthExportTest, WriteRejectsBadInputAndLeavesNothing) {
  const fs::path p = dir_ / "bad.tiff";
  EXPECT_EQ(WriteDepthTiff(p, cv::Mat(), {}).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(WriteDepthTiff(p, cv::Mat(3, 3, CV_8U), {}).code(), StatusCode::kInvalidArgument);
  DepthExportMeta neg;
  neg.pixel_size_um = -1.0;
  EXPECT_EQ(WriteDepthTiff(p, SampleDepth(), neg).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(p));
  EXPECT_FALSE(fs::exists(p.string() + ".tmp"));
  // Unwritable destination: no file, no temporary.
  const fs::path nodir = dir_ / "missing_dir" / "depth.tiff";
  EXPECT_FALSE(WriteDepthTiff(nodir, SampleDepth(), {}).ok());
  EXPECT_FALSE(WriteDepthPreviewPng(nodir, SampleDepth()).ok());
  EXPECT_FALSE(fs::exists(dir_ / "missing_dir"));
}

TEST_F(DepthExportTest, OverwriteReplacesPreviousFileAtomically) {
  const fs::path p = dir_ / "depth.tiff";
  ASSERT_TRUE(WriteDepthTiff(p, SampleDepth(), {}).ok());
  cv::Mat other(2, 3, CV_32F, cv::Scalar(42.5f));
  ASSERT_TRUE(WriteDepthTiff(p, other, {}).ok());
  auto r = ReadDepthTiff(p);
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(BitwiseEqual(*r, other));
}

TEST_F(DepthExportTest, ConfidenceTiffRoundTrip) {
  cv::Mat c(5, 6, CV_32F);
  cv::randu(c, 0.0, 1.0);
  DepthExportMeta meta;
  meta.pixel_size_um = 2.5;
  const fs::path p = dir_ / "confidence.tiff";
  ASSERT_TRUE(WriteConfidenceTiff(p, c, meta).ok());
  DepthExportMeta back;
  auto r = ReadDepthTiff(p, &back);
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(BitwiseEqual(*r, c));
  EXPECT_NEAR(back.pixel_size_um, 2.5, 1e-6);
  EXPECT_EQ(WriteConfidenceTiff(p, cv::Mat(2, 2, CV_64F), meta).code(), StatusCode::kInvalidArgument);
}

cv::Vec3b Viridis(int index) {
  cv::Mat one(1, 1, CV_8UC1, cv::Scalar(index)), c;
  cv::applyColorMap(one, c, cv::COLORMAP_VIRIDIS);
  return c.at<cv::Vec3b>(0, 0);
}

TEST_F(DepthExportTest, PreviewMapsRangeThroughViridisWithNanBlack) {
  // 300x250 map: left half at z = 10 µm, right half at 30 µm, a NaN block in the middle.
  cv::Mat d(250, 300, CV_32F, cv::Scalar(10.f));
  d(cv::Rect(150, 0, 150, 250)).setTo(30.f);
  d(cv::Rect(100, 100, 20, 20)).setTo(kNaN);
  d.at<float>(0, 0) = 20.f;  // mid value
  const fs::path p = dir_ / "preview.png";
  ASSERT_TRUE(WriteDepthPreviewPng(p, d).ok());
  EXPECT_FALSE(fs::exists(p.string() + ".tmp"));
  const cv::Mat img = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.type(), CV_8UC3);
  EXPECT_EQ(img.rows, 250);
  EXPECT_GT(img.cols, 300);  // scale bar panel on the right
  EXPECT_EQ(img.at<cv::Vec3b>(50, 50), Viridis(0));
  EXPECT_EQ(img.at<cv::Vec3b>(50, 250), Viridis(255));
  EXPECT_EQ(img.at<cv::Vec3b>(0, 0), Viridis(128));
  EXPECT_EQ(img.at<cv::Vec3b>(110, 110), cv::Vec3b(0, 0, 0));
  // The panel holds the bar (colour at its top = maximum) and white label text.
  const cv::Mat panel = img(cv::Rect(300, 0, img.cols - 300, img.rows));
  cv::Mat grey;
  cv::cvtColor(panel, grey, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(grey > 200), 100);
  EXPECT_EQ(img.at<cv::Vec3b>(28, 300 + 12 + 9), Viridis(255));
  EXPECT_EQ(img.at<cv::Vec3b>(250 - 13, 300 + 12 + 9), Viridis(0));
}

TEST_F(DepthExportTest, PreviewOfAllNanOrSmallMapsStillRenders) {
  const fs::path p = dir_ / "nan.png";
  cv::Mat d(8, 8, CV_32F, cv::Scalar(kNaN));
  ASSERT_TRUE(WriteDepthPreviewPng(p, d).ok());
  const cv::Mat img = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(img.empty());
  EXPECT_GE(img.rows, 200);  // small maps get a canvas tall enough for the labels
  EXPECT_EQ(img.at<cv::Vec3b>(3, 3), cv::Vec3b(0, 0, 0));
  cv::Mat flat(8, 8, CV_32F, cv::Scalar(5.f));
  ASSERT_TRUE(WriteDepthPreviewPng(p, flat).ok());
  EXPECT_EQ(cv::imread(p.string(), cv::IMREAD_UNCHANGED).at<cv::Vec3b>(3, 3), Viridis(0));
}

}  // namespace
}  // namespace inspection
