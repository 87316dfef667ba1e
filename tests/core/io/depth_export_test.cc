// Tests of the depth map exports: exact round trips, format tags, atomic writes, preview colours.
#include "core/io/depth_export.h"
#include "tests/lib/skip_or_fail.h"

#include <gtest/gtest.h>
#include <tiffio.h>
#include <unistd.h>
#include <zip.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>

namespace inspection {
namespace {

namespace fs = std::filesystem;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

class DepthExportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("depth_export_test_" + std::to_string(::getpid()) + "_" +
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

TEST(Md5Test, Rfc1321TestSuite) {
  auto md5 = [](const std::string& s) { return Md5Hex(s.data(), s.size()); };
  EXPECT_EQ(md5(""), "d41d8cd98f00b204e9800998ecf8427e");
  EXPECT_EQ(md5("a"), "0cc175b9c0f1b6a831c399e269772661");
  EXPECT_EQ(md5("abc"), "900150983cd24fb0d6963f7d28e17f72");
  EXPECT_EQ(md5("message digest"), "f96b697d7cb7938d525a2f31aaf161d0");
  EXPECT_EQ(md5("abcdefghijklmnopqrstuvwxyz"), "c3fcd3d76192e4007dfb496cca67e13b");
  EXPECT_EQ(md5("12345678901234567890123456789012345678901234567890123456789012345678901234567890"),
            "57edf4a22be3c955ac49da2e2107b67a");
}

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST_F(DepthExportTest, Png16RoundTripsWithinHalfAStepAndRecordsScale) {
  const cv::Mat d = SampleDepth();
  DepthExportMeta meta;
  meta.pixel_size_um = 0.5;
  const fs::path p = dir_ / "depth16.png";
  ASSERT_TRUE(WriteDepthPng16(p, d, meta).ok());
  const cv::Mat q = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(q.type(), CV_16UC1);
  const DepthPng16Scaling sc = ChooseDepthPng16Scaling(d);
  // Sidecar and tEXt chunk carry the same scale and offset.
  const auto side = nlohmann::json::parse(ReadAll(fs::path(p.string() + ".json")));
  EXPECT_DOUBLE_EQ(side["scale_um"].get<double>(), sc.scale_um);
  EXPECT_DOUBLE_EQ(side["offset_um"].get<double>(), sc.offset_um);
  EXPECT_EQ(side["nan_value"].get<int>(), 0);
  const std::string bytes = ReadAll(p);
  const size_t at = bytes.find("tEXtinspection-depth");
  ASSERT_NE(at, std::string::npos);
  const size_t len = (uint8_t(bytes[at - 4]) << 24) | (uint8_t(bytes[at - 3]) << 16) | (uint8_t(bytes[at - 2]) << 8) |
                     uint8_t(bytes[at - 1]);
  const auto text = nlohmann::json::parse(bytes.substr(at + 4 + 17, len - 17));
  EXPECT_DOUBLE_EQ(text["scale_um"].get<double>(), sc.scale_um);
  double lo, hi;
  cv::minMaxLoc(d, &lo, &hi, nullptr, nullptr, d == d);
  EXPECT_NEAR(sc.scale_um, (hi - lo) / 65534.0, 1e-12);
  for (int y = 0; y < d.rows; ++y)
    for (int x = 0; x < d.cols; ++x) {
      const float v = d.at<float>(y, x);
      const uint16_t u = q.at<uint16_t>(y, x);
      if (std::isnan(v)) {
        EXPECT_EQ(u, 0);
      } else {
        ASSERT_GE(u, 1);
        EXPECT_NEAR(u * sc.scale_um + sc.offset_um, v, 0.5 * sc.scale_um + 1e-9);
      }
    }
  EXPECT_EQ(q.at<uint16_t>(0, 0), 1);  // the minimum
}

TEST_F(DepthExportTest, PlySkipsNanAndScalesXY) {
  cv::Mat d(2, 3, CV_32F);
  d.at<float>(0, 0) = 1.5f;
  d.at<float>(0, 1) = kNaN;
  d.at<float>(0, 2) = 2.5f;
  d.at<float>(1, 0) = -3.f;
  d.at<float>(1, 1) = 4.f;
  d.at<float>(1, 2) = kNaN;
  DepthExportMeta meta;
  meta.pixel_size_um = 2.0;
  const fs::path p = dir_ / "cloud.ply";
  ASSERT_TRUE(WriteDepthPly(p, d, meta).ok());
  const std::string bytes = ReadAll(p);
  const std::string end = "end_header\n";
  const size_t body = bytes.find(end);
  ASSERT_NE(body, std::string::npos);
  const std::string header = bytes.substr(0, body);
  EXPECT_EQ(header.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
  EXPECT_NE(header.find("element vertex 4\n"), std::string::npos);
  ASSERT_EQ(bytes.size() - body - end.size(), 4 * 3 * sizeof(float));
  std::vector<float> v(12);
  std::memcpy(v.data(), bytes.data() + body + end.size(), 12 * sizeof(float));
  const std::vector<float> expected{0, 0, 1.5f, 4, 0, 2.5f, 0, 2, -3, 2, 2, 4};
  EXPECT_EQ(v, expected);
  EXPECT_EQ(WriteDepthPly(dir_ / "no.ply", d, {-1.0, ""}).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(fs::exists(dir_ / "no.ply"));
  EXPECT_NE(header.find("comment pixel_size_um 2\n"), std::string::npos) << header;
  EXPECT_EQ(header.find("unknown scale"), std::string::npos);

  // Unknown scale (pixel_size_um 0): x, y are the column and row, and the header says so.
  const fs::path u = dir_ / "unknown.ply";
  ASSERT_TRUE(WriteDepthPly(u, d, {}).ok());
  const std::string ubytes = ReadAll(u);
  const size_t ubody = ubytes.find(end);
  ASSERT_NE(ubody, std::string::npos);
  const std::string uheader = ubytes.substr(0, ubody);
  EXPECT_NE(uheader.find("comment unknown scale"), std::string::npos) << uheader;
  EXPECT_NE(uheader.find("x, y in pixels, z in um"), std::string::npos) << uheader;
  ASSERT_EQ(ubytes.size() - ubody - end.size(), 4 * 3 * sizeof(float));
  std::memcpy(v.data(), ubytes.data() + ubody + end.size(), 12 * sizeof(float));
  const std::vector<float> in_pixels{0, 0, 1.5f, 2, 0, 2.5f, 0, 1, -3, 1, 1, 4};
  EXPECT_EQ(v, in_pixels);
}

struct ZipEntries {
  std::vector<std::string> names;
  std::map<std::string, std::string> data;
};

ZipEntries ReadZip(const fs::path& p) {
  ZipEntries z;
  int err = 0;
  zip_t* za = zip_open(p.c_str(), ZIP_RDONLY, &err);
  EXPECT_NE(za, nullptr) << "libzip error " << err;
  if (!za) return z;
  const zip_int64_t n = zip_get_num_entries(za, 0);
  for (zip_int64_t i = 0; i < n; ++i) {
    zip_stat_t st;
    zip_stat_index(za, i, 0, &st);
    z.names.push_back(st.name);
    std::string buf(st.size, '\0');
    zip_file_t* f = zip_fopen_index(za, i, 0);
    if (f) {
      if (st.size) EXPECT_EQ(zip_fread(f, buf.data(), st.size), zip_int64_t(st.size));
      zip_fclose(f);
    }
    z.data[st.name] = buf;
  }
  zip_close(za);
  return z;
}

std::string Between(const std::string& s, const std::string& open, const std::string& close) {
  const size_t a = s.find(open);
  if (a == std::string::npos) return "";
  const size_t b = s.find(close, a + open.size());
  return s.substr(a + open.size(), b - a - open.size());
}

TEST_F(DepthExportTest, X3pHasIsoLayoutAndValidChecksums) {
  const cv::Mat d = SampleDepth();  // 13 x 7, two NaN
  DepthExportMeta meta;
  meta.pixel_size_um = 0.74;
  meta.description = "tilted <plane> & bump";
  const fs::path p = dir_ / "surface.x3p";
  ASSERT_TRUE(WriteDepthX3p(p, d, meta).ok());
  EXPECT_FALSE(fs::exists(p.string() + ".tmp"));
  const ZipEntries z = ReadZip(p);
  ASSERT_TRUE(z.data.count("main.xml"));
  ASSERT_TRUE(z.data.count("bindata/data.bin"));
  ASSERT_TRUE(z.data.count("md5checksum.hex"));
  EXPECT_EQ(z.names.front(), "bindata/");
  const std::string& xml = z.data.at("main.xml");
  const std::string& bin = z.data.at("bindata/data.bin");
  // md5checksum.hex holds the md5 of main.xml (md5sum format); the xml the md5 of the data.
  EXPECT_EQ(z.data.at("md5checksum.hex"), Md5Hex(xml.data(), xml.size()) + " *main.xml\n");
  EXPECT_EQ(Between(xml, "<MD5ChecksumPointData>", "</MD5ChecksumPointData>"), Md5Hex(bin.data(), bin.size()));
  EXPECT_EQ(Between(xml, "<PointDataLink>", "</PointDataLink>"), "bindata/data.bin");
  EXPECT_EQ(Between(xml, "<SizeX>", "</SizeX>"), "13");
  EXPECT_EQ(Between(xml, "<SizeY>", "</SizeY>"), "7");
  EXPECT_EQ(Between(xml, "<SizeZ>", "</SizeZ>"), "1");
  EXPECT_EQ(Between(xml, "<FeatureType>", "</FeatureType>"), "SUR");
  EXPECT_NEAR(std::stod(Between(Between(xml, "<CX>", "</CX>"), "<Increment>", "</Increment>")), 0.74e-6, 1e-18);
  EXPECT_EQ(Between(Between(xml, "<CZ>", "</CZ>"), "<AxisType>", "</AxisType>"), "A");
  EXPECT_EQ(Between(xml, "<Comment>", "</Comment>"), "tilted &lt;plane&gt; &amp; bump");
  EXPECT_NE(xml.find("xmlns:p=\"http://www.opengps.eu/2008/ISO5436_2\""), std::string::npos);
  // float64 metres, x fastest, NaN kept.
  ASSERT_EQ(bin.size(), size_t(13 * 7 * 8));
  std::vector<double> v(13 * 7);
  std::memcpy(v.data(), bin.data(), bin.size());
  for (int y = 0; y < 7; ++y)
    for (int x = 0; x < 13; ++x) {
      const float um = d.at<float>(y, x);
      const double m = v[size_t(y) * 13 + x];
      if (std::isnan(um))
        EXPECT_TRUE(std::isnan(m));
      else
        EXPECT_DOUBLE_EQ(m, double(um) * 1e-6);
    }
}

// The exports' bytes as the hand-written MD5 and CRC-32 produced them before OpenSSL and zlib
// took over (digests recorded from that build): the PNG's tEXt chunk CRC and the x3p's data
// checksum must not change, nor anything else in the files (main.xml without its two dates).
TEST_F(DepthExportTest, ExportBytesMatchGoldenDigests) {
  const cv::Mat d = SampleDepth();
  DepthExportMeta meta;
  meta.pixel_size_um = 0.5;
  meta.description = "golden";
  const fs::path png = dir_ / "golden16.png", x3p = dir_ / "golden.x3p";
  ASSERT_TRUE(WriteDepthPng16(png, d, meta).ok());
  ASSERT_TRUE(WriteDepthX3p(x3p, d, meta).ok());
  const std::string png_bytes = ReadAll(png);
  EXPECT_EQ(Md5Hex(png_bytes.data(), png_bytes.size()), "72b49511c5232693fe4fef827acef33d");
  const ZipEntries z = ReadZip(x3p);
  ASSERT_TRUE(z.data.count("main.xml"));
  std::string xml = z.data.at("main.xml");
  const std::string& bin = z.data.at("bindata/data.bin");
  EXPECT_EQ(Between(xml, "<MD5ChecksumPointData>", "</MD5ChecksumPointData>"), "85c8acb2b74d6d30604ad4f7fedc03d6");
  EXPECT_EQ(Md5Hex(bin.data(), bin.size()), "85c8acb2b74d6d30604ad4f7fedc03d6");
  for (const std::string tag : {"<Date>", "<CalibrationDate>"}) {
    const size_t at = xml.find(tag);
    ASSERT_NE(at, std::string::npos) << tag;
    xml.replace(at + tag.size(), 25, std::string(25, '-'));  // 2026-01-01T00:00:00+00:00
  }
  EXPECT_EQ(Md5Hex(xml.data(), xml.size()), "5e157f1b88e1c8f932302da6cc1ead00");
  EXPECT_EQ(z.data.at("md5checksum.hex"), Md5Hex(z.data.at("main.xml").data(), z.data.at("main.xml").size()) +
                                              " *main.xml\n");
}
TEST_F(DepthExportTest, X3pOpensInGwyddion) {
  // Gwyddion's thumbnailer loads the file with its x3p reader and renders the height field. A
  // ramp along x must come out as a brightness ramp along x.
  if (std::system("command -v gwyddion-thumbnailer > /dev/null 2>&1") != 0) {
    INSPECT_SKIP_OR_FAIL() << "gwyddion-thumbnailer not installed (Debian package gwyddion)";
  }
  cv::Mat d(64, 96, CV_32F);
  for (int y = 0; y < d.rows; ++y)
    for (int x = 0; x < d.cols; ++x) d.at<float>(y, x) = 10.f + 0.5f * x;
  DepthExportMeta meta;
  meta.pixel_size_um = 1.0;
  const fs::path p = dir_ / "ramp.x3p", png = dir_ / "ramp.png";
  ASSERT_TRUE(WriteDepthX3p(p, d, meta).ok());
  const std::string cmd = "gwyddion-thumbnailer gnome2 96 '" + p.string() + "' '" + png.string() + "' > /dev/null 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const cv::Mat thumb = cv::imread(png.string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(thumb.empty());
  EXPECT_EQ(thumb.cols, 96);
  EXPECT_EQ(thumb.rows, 64);
  const int r = thumb.rows / 2;
  EXPECT_LT(thumb.at<uint8_t>(r, 2) + 100, thumb.at<uint8_t>(r, thumb.cols - 3));  // dark left, bright right
  for (int x = 1; x < thumb.cols; ++x) EXPECT_GE(thumb.at<uint8_t>(r, x) + 2, thumb.at<uint8_t>(r, x - 1));
}

TEST_F(DepthExportTest, X3pOfUnknownScaleHasUnitIncrementsAndSaysSo) {
  const fs::path p = dir_ / "unknown.x3p";
  ASSERT_TRUE(WriteDepthX3p(p, SampleDepth(), {0.0, "from a folder"}).ok());
  const ZipEntries z = ReadZip(p);
  const std::string xml = z.data.count("main.xml") ? z.data.at("main.xml") : "";
  auto increment = [](const std::string& x, const char* open, const char* close) {
    return std::stod(Between(Between(x, open, close), "<Increment>", "</Increment>"));
  };
  EXPECT_DOUBLE_EQ(increment(xml, "<CX>", "</CX>"), 1e-6) << xml;
  EXPECT_DOUBLE_EQ(increment(xml, "<CY>", "</CY>"), 1e-6);
  const std::string comment = Between(xml, "<Comment>", "</Comment>");
  EXPECT_EQ(comment.rfind("unknown scale", 0), 0u) << comment;
  EXPECT_NE(comment.find("from a folder"), std::string::npos) << comment;
  // With a known scale, the comment is the description alone.
  ASSERT_TRUE(WriteDepthX3p(p, SampleDepth(), {0.5, "known"}).ok());
  const ZipEntries k = ReadZip(p);
  EXPECT_EQ(Between(k.data.at("main.xml"), "<Comment>", "</Comment>"), "known");
  EXPECT_DOUBLE_EQ(increment(k.data.at("main.xml"), "<CX>", "</CX>"), 0.5e-6);
}

TEST_F(DepthExportTest, X3pRejectsBadInputAndLeavesNothing) {
  const fs::path p = dir_ / "bad.x3p";
  EXPECT_EQ(WriteDepthX3p(p, SampleDepth(), {-1.0, ""}).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(WriteDepthX3p(p, cv::Mat(3, 3, CV_64F), {1.0, ""}).code(), StatusCode::kInvalidArgument);
  EXPECT_FALSE(WriteDepthX3p(dir_ / "nodir" / "a.x3p", SampleDepth(), {1.0, ""}).ok());
  EXPECT_FALSE(fs::exists(p));
  EXPECT_FALSE(fs::exists(p.string() + ".tmp"));
  EXPECT_FALSE(fs::exists(dir_ / "nodir"));
}

}  // namespace
}  // namespace inspection
