// The PNG fast path of frame decoding (core/io/png_frame_decode.h): the pixels cv::imread gives,
// bit for bit, for grey and colour at 8 and 16 bits under every zlib level (and so every mix of
// row filters libpng picks); everything it does not take, and every damaged file, comes back
// empty for the general decoder to handle and name.
#include "core/io/png_frame_decode.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdint>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

namespace inspection {
namespace {

std::string Encode(const cv::Mat& image, int level) {
  std::vector<uchar> buf;
  EXPECT_TRUE(cv::imencode(".png", image, buf, {cv::IMWRITE_PNG_COMPRESSION, level}));
  return std::string(buf.begin(), buf.end());
}

cv::Mat Reference(const std::string& file) {
  return cv::imdecode(std::vector<uchar>(file.begin(), file.end()), cv::IMREAD_UNCHANGED);
}

bool SameImage(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

// Noise (rows filtered "none" or "sub"), smooth ramps ("up", "average", "Paeth") and a flat
// block, so the adaptive filter choice exercises several filters within one image.
cv::Mat TestImage(cv::Size size, int type, uint64_t seed) {
  cv::Mat image(size, type);
  cv::RNG rng(seed);
  const double top = CV_MAT_DEPTH(type) == CV_16U ? 65536 : 256;
  rng.fill(image, cv::RNG::UNIFORM, 0, top);
  const int cn = image.channels();
  for (int y = size.height / 3; y < size.height; ++y) {
    for (int x = 0; x < size.width * cn; ++x) {
      const double v = std::fmod(7.0 * x + 13.0 * y + 0.01 * x * y, top);
      if (CV_MAT_DEPTH(type) == CV_16U) {
        image.ptr<uint16_t>(y)[x] = uint16_t(v);
      } else {
        image.ptr<uint8_t>(y)[x] = uint8_t(v);
      }
    }
  }
  image(cv::Rect(0, 0, size.width / 4, size.height / 4)).setTo(cv::Scalar::all(42));
  return image;
}

TEST(PngFrameDecodeTest, PixelsAreImreadsForGreyAndColourAt8And16Bits) {
  for (const int type : {CV_8UC1, CV_16UC1, CV_8UC3, CV_16UC3}) {
    for (const int level : {0, 1, 3, 9}) {
      for (const cv::Size size : {cv::Size(53, 37), cv::Size(1, 5), cv::Size(300, 2)}) {
        const cv::Mat image = TestImage(size, type, uint64_t(type * 100 + level));
        const std::string file = Encode(image, level);
        const cv::Mat fast = DecodePlainPng(file);
        ASSERT_FALSE(fast.empty()) << "type " << type << " level " << level << " size " << size;
        EXPECT_TRUE(SameImage(fast, Reference(file))) << "type " << type << " level " << level << " size " << size;
        EXPECT_TRUE(SameImage(fast, image));  // lossless: what was written
        EXPECT_TRUE(fast.isContinuous());
      }
    }
  }
}

// A chunk as PNG stores it: length, type, data, CRC-32 of type and data (bitwise, as the spec's
// sample code).
std::string Chunk(const std::string& type, const std::string& data) {
  const std::string body = type + data;
  uint32_t crc = 0xffffffffu;
  for (const char ch : body) {
    crc ^= uint8_t(ch);
    for (int k = 0; k < 8; ++k) crc = (crc & 1) ? 0xedb88320u ^ (crc >> 1) : crc >> 1;
  }
  crc ^= 0xffffffffu;
  auto be32 = [](uint32_t v) {
    return std::string{char(v >> 24), char(v >> 16), char(v >> 8), char(v)};
  };
  return be32(uint32_t(data.size())) + body + be32(crc);
}

TEST(PngFrameDecodeTest, WhatItDoesNotTakeOrCannotTrustComesBackEmpty) {
  const cv::Mat grey = TestImage(cv::Size(40, 30), CV_8UC1, 5);
  const std::string file = Encode(grey, 3);
  ASSERT_FALSE(DecodePlainPng(file).empty());
  // The hand-made chunks are well formed: re-inserting an IHDR's own bytes keeps the file good.
  const std::string ihdr_data = file.substr(16, 13);
  const std::string rest = file.substr(8 + 25);
  ASSERT_EQ(Chunk("IHDR", ihdr_data), file.substr(8, 25));
  // Not a PNG, empty, truncated anywhere.
  EXPECT_TRUE(DecodePlainPng("").empty());
  EXPECT_TRUE(DecodePlainPng("GIF89a..").empty());
  for (const size_t keep : {size_t(8), size_t(20), file.size() / 2, file.size() - 12, file.size() - 1}) {
    EXPECT_TRUE(DecodePlainPng(file.substr(0, keep)).empty()) << keep;
  }
  // A flipped bit in the image data: its chunk's CRC no longer matches.
  std::string damaged = file;
  const size_t idat = damaged.find("IDAT");
  ASSERT_NE(idat, std::string::npos);
  damaged[idat + 4 + 10] = char(damaged[idat + 4 + 10] ^ 0x10);
  EXPECT_TRUE(DecodePlainPng(damaged).empty());
  // The same flip with the CRC made to match: the zlib stream's own check (or inflate) fails.
  const uint32_t idat_length = uint32_t(uint8_t(file[idat - 4])) << 24 | uint32_t(uint8_t(file[idat - 3])) << 16 |
                               uint32_t(uint8_t(file[idat - 2])) << 8 | uint32_t(uint8_t(file[idat - 1]));
  std::string idat_data = file.substr(idat + 4, idat_length);
  idat_data[idat_length / 2] = char(idat_data[idat_length / 2] ^ 0x10);
  EXPECT_TRUE(DecodePlainPng(file.substr(0, idat - 4) + Chunk("IDAT", idat_data) +
                             file.substr(idat + 4 + idat_length + 4))
                  .empty());
  // Alpha (imread keeps 4 channels): left to imread.
  EXPECT_TRUE(DecodePlainPng(Encode(cv::Mat(10, 12, CV_8UC4, cv::Scalar(1, 2, 3, 4)), 1)).empty());
  // Interlaced (Adam7), a palette, a transparency chunk (imread would add alpha), an unknown
  // critical chunk: left to imread. An unknown ancillary chunk is skipped.
  std::string interlaced_ihdr = ihdr_data;
  interlaced_ihdr[12] = 1;
  const std::string signature = file.substr(0, 8);
  EXPECT_TRUE(DecodePlainPng(signature + Chunk("IHDR", interlaced_ihdr) + rest).empty());
  const std::string ihdr = file.substr(8, 25);
  EXPECT_TRUE(DecodePlainPng(signature + ihdr + Chunk("PLTE", std::string(6, '\x7f')) + rest).empty());
  EXPECT_TRUE(DecodePlainPng(signature + ihdr + Chunk("tRNS", std::string("\0\x2a", 2)) + rest).empty());
  EXPECT_TRUE(DecodePlainPng(signature + ihdr + Chunk("ABCD", "x") + rest).empty());
  const cv::Mat with_ancillary = DecodePlainPng(signature + ihdr + Chunk("tEXt", std::string("k\0v", 3)) + rest);
  EXPECT_TRUE(SameImage(with_ancillary, grey));
  // More image data than the image holds: refused here (libpng only warns; imread decides).
  cv::Mat taller(31, 40, CV_8UC1, cv::Scalar(9));
  const std::string tall = Encode(taller, 3);
  EXPECT_TRUE(DecodePlainPng(signature + ihdr + tall.substr(8 + 25)).empty());
  // An image whose rows inflate to more than max_raw_bytes goes to the general decoder before
  // any buffer is allocated from its header (40 x 30 grey: 30 x 41 = 1230 bytes).
  EXPECT_TRUE(DecodePlainPng(file, 1229).empty());
  EXPECT_TRUE(SameImage(DecodePlainPng(file, 1230), grey));
}

// A zlib stream of stored (uncompressed) deflate blocks, so a test controls every filtered byte.
std::string StoredZlib(const std::string& raw) {
  std::string z = "\x78\x01";
  size_t pos = 0;
  do {
    const size_t n = std::min<size_t>(65535, raw.size() - pos);
    const bool last = pos + n == raw.size();
    z += char(last ? 1 : 0);
    z += char(n & 0xff);
    z += char(n >> 8);
    z += char(~n & 0xff);
    z += char((~n >> 8) & 0xff);
    z += raw.substr(pos, n);
    pos += n;
  } while (pos < raw.size());
  uint32_t a = 1, b = 0;  // Adler-32
  for (const char ch : raw) {
    a = (a + uint8_t(ch)) % 65521;
    b = (b + a) % 65521;
  }
  for (const int shift : {24, 16, 8, 0}) z += char(((b << 16 | a) >> shift) & 0xff);
  return z;
}

// The PNG spec's filter predictor (9.2) for byte x of a row: a left, b up, c up-left.
int Predict(int filter, int a, int b, int c) {
  switch (filter) {
    case 1:
      return a;
    case 2:
      return b;
    case 3:
      return (a + b) / 2;
    case 4: {
      const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
      return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
    }
    default:
      return 0;
  }
}

// Every row filter at every sample layout and at widths around the 16-byte blocks of the
// vectorised Sub and Up (libpng's own choice, above, need not use each filter for each layout).
TEST(PngFrameDecodeTest, EveryRowFilterAtEveryLayoutAndWidth) {
  for (const int type : {CV_8UC1, CV_16UC1, CV_8UC3, CV_16UC3}) {
    for (const int width : {1, 2, 7, 8, 15, 16, 17, 31, 33, 100}) {
      const int height = 11;
      const cv::Mat image = TestImage(cv::Size(width, height), type, uint64_t(type * 1000 + width));
      const int cn = image.channels(), sample = int(image.elemSize1());
      const size_t bpp = size_t(cn * sample), stride = size_t(width) * bpp;
      // The rows as PNG stores them: big-endian samples in RGB order.
      std::vector<std::vector<uint8_t>> rows(size_t(height), std::vector<uint8_t>(stride, 0));
      for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
          for (int c = 0; c < cn; ++c) {
            const int src = (cn - 1 - c);  // BGR -> RGB
            const uint32_t v = sample == 2 ? image.ptr<uint16_t>(y)[x * cn + src] : image.ptr<uint8_t>(y)[x * cn + src];
            uint8_t* out = &rows[size_t(y)][size_t(x) * bpp + size_t(c * sample)];
            if (sample == 2) {
              out[0] = uint8_t(v >> 8);
              out[1] = uint8_t(v);
            } else {
              out[0] = uint8_t(v);
            }
          }
        }
      }
      for (int first_filter = 0; first_filter < 5; ++first_filter) {
        std::string raw;
        for (int y = 0; y < height; ++y) {
          const int filter = (first_filter + y) % 5;  // each filter on several rows, after each other one
          raw += char(filter);
          for (size_t x = 0; x < stride; ++x) {
            const int a = x >= bpp ? rows[size_t(y)][x - bpp] : 0;
            const int b = y > 0 ? rows[size_t(y - 1)][x] : 0;
            const int c = y > 0 && x >= bpp ? rows[size_t(y - 1)][x - bpp] : 0;
            raw += char(uint8_t(rows[size_t(y)][x] - Predict(filter, a, b, c)));
          }
        }
        std::string ihdr;
        for (const uint32_t v : {uint32_t(width), uint32_t(height)}) {
          for (const int shift : {24, 16, 8, 0}) ihdr += char((v >> shift) & 0xff);
        }
        ihdr += char(sample * 8);
        ihdr += char(cn == 3 ? 2 : 0);
        ihdr += std::string(3, '\0');
        const std::string file = std::string("\x89PNG\r\n\x1a\n", 8) + Chunk("IHDR", ihdr) +
                                 Chunk("IDAT", StoredZlib(raw)) + Chunk("IEND", "");
        const cv::Mat fast = DecodePlainPng(file);
        ASSERT_FALSE(fast.empty()) << "type " << type << " width " << width << " first filter " << first_filter;
        EXPECT_TRUE(SameImage(fast, image)) << "type " << type << " width " << width << " first filter " << first_filter;
        EXPECT_TRUE(SameImage(Reference(file), image)) << "the hand-made file is what libpng reads too";
      }
    }
  }
}

}  // namespace
}  // namespace inspection
