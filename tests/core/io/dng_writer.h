// A minimal camera RAW file for the tests: a CFA DNG (TIFF/EP based, DNG 1.4) written with
// libtiff, since LibRaw reads RAW but cannot write it. One uncompressed 16-bit Bayer mosaic
// (RGGB) in IFD 0 with the tags a DNG reader needs: DNGVersion, UniqueCameraModel, the CFA
// pattern, BlackLevel, WhiteLevel, AsShotNeutral and Orientation. No ColorMatrix: the reader
// keeps the camera's own primaries (no colour conversion), so the developed values are the
// mosaic's, scaled by 65535 / (white - black).
#pragma once

#include <tiffio.h>

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

namespace inspection::testing {

// The RGGB mosaic of a colour image (CV_16UC3, BGR, values up to white_level).
inline cv::Mat BayerRggbOf(const cv::Mat& bgr) {
  cv::Mat mosaic(bgr.size(), CV_16UC1);
  for (int y = 0; y < bgr.rows; ++y) {
    for (int x = 0; x < bgr.cols; ++x) {
      const cv::Vec3w p = bgr.at<cv::Vec3w>(y, x);
      const int channel = (y % 2 == 0) ? (x % 2 == 0 ? 2 : 1) : (x % 2 == 0 ? 1 : 0);  // R G / G B (BGR index)
      mosaic.at<uint16_t>(y, x) = p[channel];
    }
  }
  return mosaic;
}

// Writes `mosaic` (CV_16UC1, RGGB, even width and height) as a DNG. orientation: TIFF/EXIF
// Orientation (1 = as stored, 6 = shown rotated 90 degrees clockwise, ...). False on failure.
inline bool WriteCfaDng(const std::string& path, const cv::Mat& mosaic, uint32_t white_level = 4095,
                        int orientation = 1) {
  if (mosaic.type() != CV_16UC1) return false;
  TIFF* tif = TIFFOpen(path.c_str(), "w");
  if (!tif) return false;
  // libtiff 4.5 knows the CFA tags only in its EXIF table; register them for IFD 0.
  if (!TIFFFindField(tif, TIFFTAG_CFAREPEATPATTERNDIM, TIFF_ANY)) {
    static const TIFFFieldInfo cfa_fields[] = {
        {TIFFTAG_CFAREPEATPATTERNDIM, 2, 2, TIFF_SHORT, FIELD_CUSTOM, 1, 0, const_cast<char*>("CFARepeatPatternDim")},
        {TIFFTAG_CFAPATTERN, -1, -1, TIFF_BYTE, FIELD_CUSTOM, 1, 1, const_cast<char*>("CFAPattern")}};
    TIFFMergeFieldInfo(tif, cfa_fields, 2);
  }
  bool ok = true;
  ok &= TIFFSetField(tif, TIFFTAG_SUBFILETYPE, 0) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, uint32_t(mosaic.cols)) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_IMAGELENGTH, uint32_t(mosaic.rows)) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, 16) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_COMPRESSION, COMPRESSION_NONE) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_CFA) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_ORIENTATION, uint16_t(orientation)) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, uint32_t(mosaic.rows)) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_MAKE, "Inspection") == 1;
  ok &= TIFFSetField(tif, TIFFTAG_MODEL, "Test DNG") == 1;
  static const uint8_t kDngVersion[4] = {1, 4, 0, 0};
  ok &= TIFFSetField(tif, TIFFTAG_DNGVERSION, kDngVersion) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_UNIQUECAMERAMODEL, "Inspection Test DNG") == 1;
  static const uint16_t kCfaDim[2] = {2, 2};
  static const uint8_t kRggb[4] = {0, 1, 1, 2};
  ok &= TIFFSetField(tif, TIFFTAG_CFAREPEATPATTERNDIM, kCfaDim) == 1;
  ok &= TIFFSetField(tif, TIFFTAG_CFAPATTERN, 4, kRggb) == 1;
  const float black[1] = {0.0f};
  ok &= TIFFSetField(tif, TIFFTAG_BLACKLEVEL, 1, black) == 1;
  const uint32_t white[1] = {white_level};
  ok &= TIFFSetField(tif, TIFFTAG_WHITELEVEL, 1, white) == 1;
  const float neutral[3] = {1.0f, 1.0f, 1.0f};
  ok &= TIFFSetField(tif, TIFFTAG_ASSHOTNEUTRAL, 3, neutral) == 1;
  for (int y = 0; ok && y < mosaic.rows; ++y) {
    ok &= TIFFWriteScanline(tif, const_cast<uint16_t*>(mosaic.ptr<uint16_t>(y)), uint32_t(y), 0) == 1;
  }
  TIFFClose(tif);
  return ok;
}

}  // namespace inspection::testing
