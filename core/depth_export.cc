// Depth map writers/readers (thesis 3.1 output): float32 TIFF in µm, confidence TIFF, colour
// preview PNG with a µm scale bar, 16-bit PNG with scale/offset, PLY point cloud, ISO 25178-72 x3p.
// Every writer renders into memory or "<path>.tmp" first and renames, so failures leave nothing.
#include "core/depth_export.h"

#include <tiffio.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

namespace fs = std::filesystem;

fs::path TmpPath(const fs::path& path) { return fs::path(path.string() + ".tmp"); }

void RemoveQuietly(const fs::path& p) {
  std::error_code ec;
  fs::remove(p, ec);
}

// Moves a finished temporary file into place; removes it when that fails.
Status CommitTmp(const fs::path& tmp, const fs::path& path) {
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    RemoveQuietly(tmp);
    return Status::Internal(path.string() + ": rename from temporary file failed: " + ec.message());
  }
  return Status::Ok();
}

Status WriteBytesAtomic(const fs::path& path, const void* data, size_t size) {
  const fs::path tmp = TmpPath(path);
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return Status::InvalidArgument(path.string() + ": cannot create file");
    out.write(static_cast<const char*>(data), std::streamsize(size));
    out.flush();
    if (!out) {
      out.close();
      RemoveQuietly(tmp);
      return Status::Internal(path.string() + ": write failed");
    }
  }
  return CommitTmp(tmp, path);
}

Status CheckFloatMap(const cv::Mat& m, const char* field) {
  if (m.empty()) return Status::InvalidArgument(std::string(field) + " is empty");
  if (m.type() != CV_32FC1) return Status::InvalidArgument(std::string(field) + " must be CV_32FC1");
  return Status::Ok();
}

// Collects libtiff's messages for this handle instead of printing them (no global handlers).
struct TiffMessages {
  std::string text;
};

int TiffErrorHandler(TIFF*, void* user_data, const char* module, const char* fmt, va_list ap) {
  auto* msgs = static_cast<TiffMessages*>(user_data);
  char buf[512];
  std::vsnprintf(buf, sizeof(buf), fmt, ap);
  if (!msgs->text.empty()) msgs->text += "; ";
  if (module) msgs->text += std::string(module) + ": ";
  msgs->text += buf;
  return 1;  // handled: do not reach the global handler
}

int TiffWarningHandler(TIFF*, void*, const char*, const char*, va_list) { return 1; }

struct TiffHandle {
  TIFF* tif = nullptr;
  TiffMessages msgs;
  TiffHandle(const fs::path& path, const char* mode) {
    TIFFOpenOptions* opts = TIFFOpenOptionsAlloc();
    TIFFOpenOptionsSetErrorHandlerExtR(opts, TiffErrorHandler, &msgs);
    TIFFOpenOptionsSetWarningHandlerExtR(opts, TiffWarningHandler, nullptr);
    tif = TIFFOpenExt(path.c_str(), mode, opts);
    TIFFOpenOptionsFree(opts);
  }
  ~TiffHandle() {
    if (tif) TIFFClose(tif);
  }
  // Closes explicitly so the final flush error can be seen.
  bool Close() {
    if (!tif) return false;
    TIFF* t = tif;
    tif = nullptr;
    const bool flushed = TIFFFlush(t) == 1;
    TIFFClose(t);
    return flushed && msgs.text.empty();
  }
};

Status WriteFloatTiff(const fs::path& path, const cv::Mat& values, const DepthExportMeta& meta) {
  if (!(meta.pixel_size_um >= 0.0) || !std::isfinite(meta.pixel_size_um)) {
    return Status::InvalidArgument("pixel_size_um must be finite and >= 0");
  }
  const fs::path tmp = TmpPath(path);
  TiffHandle h(tmp, "w");
  if (!h.tif) return Status::InvalidArgument(path.string() + ": cannot create TIFF: " + h.msgs.text);
  TIFF* tif = h.tif;
  TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, uint32_t(values.cols));
  TIFFSetField(tif, TIFFTAG_IMAGELENGTH, uint32_t(values.rows));
  TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, uint16_t(1));
  TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, uint16_t(32));
  TIFFSetField(tif, TIFFTAG_SAMPLEFORMAT, uint16_t(SAMPLEFORMAT_IEEEFP));
  TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, uint16_t(PHOTOMETRIC_MINISBLACK));
  TIFFSetField(tif, TIFFTAG_PLANARCONFIG, uint16_t(PLANARCONFIG_CONTIG));
  TIFFSetField(tif, TIFFTAG_COMPRESSION, uint16_t(COMPRESSION_NONE));
  TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, TIFFDefaultStripSize(tif, 0));
  TIFFSetField(tif, TIFFTAG_SOFTWARE, "inspection sff");
  if (!meta.description.empty()) TIFFSetField(tif, TIFFTAG_IMAGEDESCRIPTION, meta.description.c_str());
  if (meta.pixel_size_um > 0.0) {
    // Resolution in pixels per centimetre: 1 cm = 1e4 µm.
    const float px_per_cm = float(1e4 / meta.pixel_size_um);
    TIFFSetField(tif, TIFFTAG_RESOLUTIONUNIT, uint16_t(RESUNIT_CENTIMETER));
    TIFFSetField(tif, TIFFTAG_XRESOLUTION, px_per_cm);
    TIFFSetField(tif, TIFFTAG_YRESOLUTION, px_per_cm);
  }
  std::vector<float> row(size_t(values.cols));
  for (int y = 0; y < values.rows; ++y) {
    std::memcpy(row.data(), values.ptr<float>(y), row.size() * sizeof(float));
    if (TIFFWriteScanline(tif, row.data(), uint32_t(y), 0) != 1) {
      const std::string msg = h.msgs.text;
      h.Close();
      RemoveQuietly(tmp);
      return Status::Internal(path.string() + ": TIFF write failed at row " + std::to_string(y) + ": " + msg);
    }
  }
  if (!h.Close()) {
    RemoveQuietly(tmp);
    return Status::Internal(path.string() + ": TIFF write failed: " + h.msgs.text);
  }
  return CommitTmp(tmp, path);
}

}  // namespace

Status WriteDepthTiff(const fs::path& path, const cv::Mat& depth_um, const DepthExportMeta& meta) {
  INSPECT_RETURN_IF_ERROR(CheckFloatMap(depth_um, "depth_um"));
  return WriteFloatTiff(path, depth_um, meta);
}

Status WriteConfidenceTiff(const fs::path& path, const cv::Mat& confidence, const DepthExportMeta& meta) {
  INSPECT_RETURN_IF_ERROR(CheckFloatMap(confidence, "confidence"));
  return WriteFloatTiff(path, confidence, meta);
}

StatusOr<cv::Mat> ReadDepthTiff(const fs::path& path) { return ReadDepthTiff(path, nullptr); }

StatusOr<cv::Mat> ReadDepthTiff(const fs::path& path, DepthExportMeta* meta) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return Status::NotFound(path.string() + ": no such file");
  TiffHandle h(path, "r");
  if (!h.tif) return Status::InvalidArgument(path.string() + ": not a readable TIFF: " + h.msgs.text);
  TIFF* tif = h.tif;
  uint32_t width = 0, height = 0;
  uint16_t spp = 1, bps = 0, fmt = SAMPLEFORMAT_UINT, planar = PLANARCONFIG_CONTIG;
  TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &width);
  TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &height);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLESPERPIXEL, &spp);
  TIFFGetFieldDefaulted(tif, TIFFTAG_BITSPERSAMPLE, &bps);
  TIFFGetFieldDefaulted(tif, TIFFTAG_SAMPLEFORMAT, &fmt);
  TIFFGetFieldDefaulted(tif, TIFFTAG_PLANARCONFIG, &planar);
  if (width == 0 || height == 0 || width > (1u << 16) || height > (1u << 16)) {
    return Status::InvalidArgument(path.string() + ": image size " + std::to_string(width) + "x" +
                                   std::to_string(height) + " is not supported");
  }
  if (spp != 1) {
    return Status::InvalidArgument(path.string() + ": " + std::to_string(spp) +
                                   " samples per pixel; a depth map has one");
  }
  if (fmt != SAMPLEFORMAT_IEEEFP || (bps != 32 && bps != 64)) {
    return Status::InvalidArgument(path.string() + ": not a floating-point TIFF (SampleFormat " +
                                   std::to_string(fmt) + ", BitsPerSample " + std::to_string(bps) + ")");
  }
  const int cv_type = bps == 32 ? CV_32FC1 : CV_64FC1;
  cv::Mat m(int(height), int(width), cv_type);
  const size_t elem = bps / 8;
  if (TIFFIsTiled(tif)) {
    uint32_t tw = 0, th = 0;
    TIFFGetField(tif, TIFFTAG_TILEWIDTH, &tw);
    TIFFGetField(tif, TIFFTAG_TILELENGTH, &th);
    if (tw == 0 || th == 0) return Status::InvalidArgument(path.string() + ": bad tile size");
    std::vector<uint8_t> tile(size_t(TIFFTileSize(tif)));
    if (tile.size() < size_t(tw) * th * elem) return Status::InvalidArgument(path.string() + ": bad tile size");
    for (uint32_t ty = 0; ty < height; ty += th) {
      for (uint32_t tx = 0; tx < width; tx += tw) {
        if (TIFFReadTile(tif, tile.data(), tx, ty, 0, 0) < 0) {
          return Status::InvalidArgument(path.string() + ": unreadable tile at (" + std::to_string(tx) + ", " +
                                         std::to_string(ty) + "): " + h.msgs.text);
        }
        const uint32_t cw = std::min(tw, width - tx), ch = std::min(th, height - ty);
        for (uint32_t r = 0; r < ch; ++r) {
          std::memcpy(m.ptr<uint8_t>(int(ty + r)) + size_t(tx) * elem, tile.data() + size_t(r) * tw * elem,
                      cw * elem);
        }
      }
    }
  } else {
    if (size_t(TIFFScanlineSize(tif)) != size_t(width) * elem) {
      return Status::InvalidArgument(path.string() + ": unexpected scanline size");
    }
    for (uint32_t y = 0; y < height; ++y) {
      if (TIFFReadScanline(tif, m.ptr(int(y)), y, 0) != 1) {
        return Status::InvalidArgument(path.string() + ": unreadable row " + std::to_string(y) + ": " + h.msgs.text);
      }
    }
  }
  if (meta) {
    *meta = DepthExportMeta{};
    char* desc = nullptr;
    if (TIFFGetField(tif, TIFFTAG_IMAGEDESCRIPTION, &desc) == 1 && desc) meta->description = desc;
    float xres = 0.f;
    uint16_t unit = RESUNIT_INCH;
    if (TIFFGetField(tif, TIFFTAG_XRESOLUTION, &xres) == 1 && xres > 0.f) {
      TIFFGetFieldDefaulted(tif, TIFFTAG_RESOLUTIONUNIT, &unit);
      if (unit == RESUNIT_CENTIMETER) meta->pixel_size_um = 1e4 / double(xres);
      else if (unit == RESUNIT_INCH) meta->pixel_size_um = 25400.0 / double(xres);
    }
  }
  if (cv_type != CV_32FC1) m.convertTo(m, CV_32FC1);
  return m;
}

namespace {

// 1-2-5 tick spacing giving roughly `target` intervals over `range`.
double NiceStep(double range, int target) {
  const double raw = range / std::max(target, 1);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double f : {1.0, 2.0, 5.0, 10.0}) {
    if (raw <= f * mag) return f * mag;
  }
  return 10.0 * mag;
}

std::string FormatUm(double v, double step) {
  const int decimals = std::clamp(int(std::ceil(-std::log10(step))), 0, 4);
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", decimals, v);
  return buf;
}

struct FiniteRange {
  double lo = 0.0, hi = 0.0;
  size_t count = 0;
};

FiniteRange FindFiniteRange(const cv::Mat& m) {
  FiniteRange r;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (int y = 0; y < m.rows; ++y) {
    const float* p = m.ptr<float>(y);
    for (int x = 0; x < m.cols; ++x) {
      if (std::isfinite(p[x])) {
        lo = std::min(lo, p[x]);
        hi = std::max(hi, p[x]);
        ++r.count;
      }
    }
  }
  if (r.count) {
    r.lo = lo;
    r.hi = hi;
  }
  return r;
}

}  // namespace

Status WriteDepthPreviewPng(const fs::path& path, const cv::Mat& depth_um) {
  INSPECT_RETURN_IF_ERROR(CheckFloatMap(depth_um, "depth_um"));
  try {
    const FiniteRange fr = FindFiniteRange(depth_um);
    const double lo = fr.lo;
    const double span = fr.hi > fr.lo ? fr.hi - fr.lo : 1.0;
    // Depth -> 0..255 index; NaN keeps index 0 here and is painted black after colouring.
    cv::Mat index(depth_um.size(), CV_8UC1), nan_mask(depth_um.size(), CV_8UC1);
    for (int y = 0; y < depth_um.rows; ++y) {
      const float* d = depth_um.ptr<float>(y);
      uint8_t* idx = index.ptr<uint8_t>(y);
      uint8_t* nm = nan_mask.ptr<uint8_t>(y);
      for (int x = 0; x < depth_um.cols; ++x) {
        const bool finite = std::isfinite(d[x]);
        nm[x] = finite ? 0 : 255;
        idx[x] = finite ? uint8_t(std::lround(std::clamp((d[x] - lo) / span, 0.0, 1.0) * 255.0)) : 0;
      }
    }
    cv::Mat coloured;
    cv::applyColorMap(index, coloured, cv::COLORMAP_VIRIDIS);
    coloured.setTo(cv::Scalar::all(0), nan_mask);

    // Canvas: the map on the left, a panel with the colour bar and µm labels on the right.
    const int panel_w = 110, min_h = 200;
    const int canvas_h = std::max(depth_um.rows, min_h);
    cv::Mat canvas(canvas_h, depth_um.cols + panel_w, CV_8UC3, cv::Scalar::all(0));
    coloured.copyTo(canvas(cv::Rect(0, 0, depth_um.cols, depth_um.rows)));
    const cv::Scalar white(255, 255, 255);
    const int bar_x = depth_um.cols + 12, bar_w = 18, bar_top = 28, bar_bottom = canvas_h - 12;
    const int bar_h = bar_bottom - bar_top;
    for (int y = 0; y < bar_h; ++y) {
      const int v = int(std::lround(255.0 * (bar_h - 1 - y) / std::max(bar_h - 1, 1)));
      cv::Mat one(1, 1, CV_8UC1, cv::Scalar(v)), c;
      cv::applyColorMap(one, c, cv::COLORMAP_VIRIDIS);
      const cv::Vec3b col = c.at<cv::Vec3b>(0, 0);
      cv::line(canvas, {bar_x, bar_top + y}, {bar_x + bar_w - 1, bar_top + y}, cv::Scalar(col[0], col[1], col[2]));
    }
    cv::rectangle(canvas, cv::Rect(bar_x - 1, bar_top - 1, bar_w + 2, bar_h + 2), white, 1);
    const int font = cv::FONT_HERSHEY_SIMPLEX;
    const double font_scale = 0.4;
    cv::putText(canvas, "z [um]", {bar_x - 4, 16}, font, font_scale, white, 1, cv::LINE_AA);
    if (fr.count == 0) {
      cv::putText(canvas, "no depth", {bar_x + bar_w + 4, bar_top + bar_h / 2}, font, font_scale, white, 1,
                  cv::LINE_AA);
    } else {
      const double step = NiceStep(span, 5);
      auto y_of = [&](double z) { return bar_bottom - 1 - int(std::lround((z - lo) / span * (bar_h - 1))); };
      for (double t = std::ceil(lo / step) * step; t <= lo + span + 1e-9 * step; t += step) {
        const int y = y_of(t);
        cv::line(canvas, {bar_x + bar_w, y}, {bar_x + bar_w + 4, y}, white, 1);
        cv::putText(canvas, FormatUm(std::abs(t) < 1e-12 * step ? 0.0 : t, step), {bar_x + bar_w + 7, y + 4}, font,
                    font_scale, white, 1, cv::LINE_AA);
      }
    }
    std::vector<uchar> png;
    if (!cv::imencode(".png", canvas, png)) return Status::Internal("PNG encoding failed");
    return WriteBytesAtomic(path, png.data(), png.size());
  } catch (const cv::Exception& e) {
    return Status::Internal(std::string("preview rendering failed: ") + e.what());
  }
}

}  // namespace inspection
