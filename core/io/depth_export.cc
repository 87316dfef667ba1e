// Depth map writers/readers (thesis 3.1 output): float32 TIFF in µm, confidence TIFF, colour
// preview PNG with a µm scale bar, 16-bit PNG with scale/offset, PLY point cloud, ISO 25178-72 x3p.
// Every writer renders into memory or "<path>.tmp" first and renames, so failures leave nothing.
#include "core/io/depth_export.h"

#include <openssl/evp.h>
#include <tiffio.h>
#include <zip.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <system_error>
#include <vector>

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
    return Status::InvalidArgument(path.string() + ": not a floating-point TIFF (SampleFormat " + std::to_string(fmt) +
                                   ", BitsPerSample " + std::to_string(bps) + ")");
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
          std::memcpy(m.ptr<uint8_t>(int(ty + r)) + size_t(tx) * elem, tile.data() + size_t(r) * tw * elem, cw * elem);
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
      if (unit == RESUNIT_CENTIMETER)
        meta->pixel_size_um = 1e4 / double(xres);
      else if (unit == RESUNIT_INCH)
        meta->pixel_size_um = 25400.0 / double(xres);
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

StatusOr<cv::Mat> RenderDepthPreview(const cv::Mat& depth_um, const cv::Mat& inferred) {
  INSPECT_RETURN_IF_ERROR(CheckFloatMap(depth_um, "depth_um"));
  if (!inferred.empty() && (inferred.type() != CV_8UC1 || inferred.size() != depth_um.size())) {
    return Status::InvalidArgument("inferred mask must be CV_8UC1 of the depth map's size");
  }
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
    // Inferred depth must not pass for measured depth: dimmed and hatched.
    const bool any_inferred = !inferred.empty() && cv::countNonZero(inferred) > 0;
    if (any_inferred) {
      for (int y = 0; y < coloured.rows; ++y) {
        const uint8_t* m = inferred.ptr<uint8_t>(y);
        cv::Vec3b* c = coloured.ptr<cv::Vec3b>(y);
        for (int x = 0; x < coloured.cols; ++x) {
          if (!m[x]) continue;
          c[x] = (x + y) % 4 == 0 ? cv::Vec3b(128, 128, 128) : cv::Vec3b(c[x][0] * 0.55, c[x][1] * 0.55, c[x][2] * 0.55);
        }
      }
    }

    // Canvas: the map on the left, a panel with the colour bar and µm labels on the right.
    const int panel_w = kDepthPreviewPanelWidthPx, min_h = kDepthPreviewMinHeightPx;
    const int canvas_h = std::max(depth_um.rows, min_h);
    cv::Mat canvas(canvas_h, depth_um.cols + panel_w, CV_8UC3, cv::Scalar::all(0));
    coloured.copyTo(canvas(cv::Rect(0, 0, depth_um.cols, depth_um.rows)));
    const cv::Scalar white(255, 255, 255);
    const int bar_x = depth_um.cols + 12, bar_w = 18, bar_top = 28, bar_bottom = canvas_h - 12;
    const int bar_h = bar_bottom - bar_top;
    // The colour map's 256 entries, coloured once (applyColorMap per bar row built the map
    // again for each of ~1000 rows: most of the preview's time on a 1600 x 1200 map).
    cv::Mat ramp(1, 256, CV_8UC1), ramp_colours;
    for (int v = 0; v < 256; ++v) ramp.at<uint8_t>(0, v) = uint8_t(v);
    cv::applyColorMap(ramp, ramp_colours, cv::COLORMAP_VIRIDIS);
    for (int y = 0; y < bar_h; ++y) {
      const int v = int(std::lround(255.0 * (bar_h - 1 - y) / std::max(bar_h - 1, 1)));
      const cv::Vec3b col = ramp_colours.at<cv::Vec3b>(0, v);
      cv::line(canvas, {bar_x, bar_top + y}, {bar_x + bar_w - 1, bar_top + y}, cv::Scalar(col[0], col[1], col[2]));
    }
    cv::rectangle(canvas, cv::Rect(bar_x - 1, bar_top - 1, bar_w + 2, bar_h + 2), white, 1);
    const int font = cv::FONT_HERSHEY_SIMPLEX;
    const double font_scale = 0.4;
    cv::putText(canvas, "z [um]", {bar_x - 4, 16}, font, font_scale, white, 1, cv::LINE_AA);
    if (any_inferred) cv::putText(canvas, "hatched: inferred", {bar_x - 4, 25}, font, 0.3, white, 1, cv::LINE_AA);
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
    return canvas;
  } catch (const cv::Exception& e) {
    return Status::Internal(std::string("preview rendering failed: ") + e.what());
  }
}

Status WriteDepthPreviewPng(const fs::path& path, const cv::Mat& depth_um, const cv::Mat& inferred) {
  StatusOr<cv::Mat> canvas = RenderDepthPreview(depth_um, inferred);
  if (!canvas.ok()) return canvas.status();
  std::vector<uchar> png;
  try {
    if (!cv::imencode(".png", *canvas, png)) return Status::Internal("PNG encoding failed");
  } catch (const cv::Exception& e) {
    return Status::Internal(std::string("PNG encoding failed: ") + e.what());
  }
  return WriteBytesAtomic(path, png.data(), png.size());
}

// ---------------------------------------------------------------------------------------------
// MD5 (RFC 1321) for the x3p checksums, by OpenSSL's EVP interface.

std::string Md5Hex(const void* data, size_t size) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  // EVP_Digest fails only when OpenSSL cannot allocate its context or offers no MD5 (a
  // FIPS-only provider): empty then, which the x3p writer reports instead of a wrong checksum.
  if (EVP_Digest(data, size, digest, &length, EVP_md5(), nullptr) != 1 || length != 16) return {};
  static constexpr char kHex[] = "0123456789abcdef";
  std::string hex(2 * length, '0');
  for (unsigned int i = 0; i < length; ++i) {
    hex[2 * i] = kHex[digest[i] >> 4];
    hex[2 * i + 1] = kHex[digest[i] & 0xf];
  }
  return hex;
}

std::string XmlEscape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

namespace {

// CRC-32 of a PNG chunk (ISO 3309, as PNG spec 5.5 defines it), by zlib.
uint32_t Crc32(const uint8_t* p, size_t n) { return uint32_t(crc32_z(0L, p, n)); }

void PutBigEndian32(std::string* out, uint32_t v) {
  for (int i = 3; i >= 0; --i) out->push_back(char(uint8_t(v >> (8 * i))));
}

std::string FormatDouble(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

std::string UtcNowIso8601() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%S+00:00", &tm);
  return buf;
}

// 0 = unknown scale: the lateral exports then use a pixel of 1 unit and say so.
Status CheckPixelSize(const DepthExportMeta& meta) {
  if (!(meta.pixel_size_um >= 0.0) || !std::isfinite(meta.pixel_size_um)) {
    return Status::InvalidArgument("pixel_size_um must be finite and >= 0 (0 = unknown scale)");
  }
  return Status::Ok();
}

double LateralStepOrOne(const DepthExportMeta& meta) { return meta.pixel_size_um > 0.0 ? meta.pixel_size_um : 1.0; }

constexpr const char* kUnknownScaleNote = "unknown scale: pixel_size_um missing, x and y count pixels";

}  // namespace

DepthPng16Scaling ChooseDepthPng16Scaling(const cv::Mat& depth_um) {
  DepthPng16Scaling s;
  if (depth_um.empty() || depth_um.type() != CV_32FC1) return s;
  const FiniteRange fr = FindFiniteRange(depth_um);
  if (fr.count == 0) return s;
  // 65534 steps between the smallest (value 1) and the largest (65535) finite depth; a flat map
  // gets 1 nm steps.
  s.scale_um = fr.hi > fr.lo ? (fr.hi - fr.lo) / 65534.0 : 1e-3;
  s.offset_um = fr.lo - s.scale_um;
  return s;
}

Status WriteDepthPng16(const fs::path& path, const cv::Mat& depth_um, const DepthExportMeta& meta) {
  INSPECT_RETURN_IF_ERROR(CheckFloatMap(depth_um, "depth_um"));
  if (!(meta.pixel_size_um >= 0.0) || !std::isfinite(meta.pixel_size_um)) {
    return Status::InvalidArgument("pixel_size_um must be finite and >= 0");
  }
  const DepthPng16Scaling sc = ChooseDepthPng16Scaling(depth_um);
  cv::Mat q(depth_um.size(), CV_16UC1);
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    uint16_t* o = q.ptr<uint16_t>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      o[x] = std::isfinite(d[x])
                 ? uint16_t(std::clamp(std::lround((double(d[x]) - sc.offset_um) / sc.scale_um), 1L, 65535L))
                 : uint16_t(0);
    }
  }
  nlohmann::json j;
  j["format"] = "inspection-depth-png16";
  j["unit"] = "um";
  j["scale_um"] = sc.scale_um;
  j["offset_um"] = sc.offset_um;
  j["nan_value"] = 0;
  j["depth_um"] = "value * scale_um + offset_um";
  j["pixel_size_um"] = meta.pixel_size_um;
  if (!(meta.pixel_size_um > 0.0)) j["lateral_scale"] = kUnknownScaleNote;
  if (!meta.description.empty()) j["description"] = meta.description;
  const std::string text = j.dump();
  try {
    std::vector<uchar> png;
    if (!cv::imencode(".png", q, png)) return Status::Internal("PNG encoding failed");
    // tEXt chunk "inspection-depth" right after IHDR (8-byte signature + 25-byte IHDR).
    if (png.size() < 33 || std::memcmp(png.data() + 12, "IHDR", 4) != 0)
      return Status::Internal("unexpected PNG layout");
    std::string body = "inspection-depth";
    body.push_back('\0');
    body += text;
    std::string chunk;
    PutBigEndian32(&chunk, uint32_t(body.size()));
    const size_t type_at = chunk.size();
    chunk += "tEXt";
    chunk += body;
    PutBigEndian32(&chunk, Crc32(reinterpret_cast<const uint8_t*>(chunk.data()) + type_at, chunk.size() - type_at));
    std::string out(reinterpret_cast<const char*>(png.data()), 33);
    out += chunk;
    out.append(reinterpret_cast<const char*>(png.data()) + 33, png.size() - 33);
    const std::string sidecar = j.dump(2) + "\n";
    INSPECT_RETURN_IF_ERROR(WriteBytesAtomic(fs::path(path.string() + ".json"), sidecar.data(), sidecar.size()));
    return WriteBytesAtomic(path, out.data(), out.size());
  } catch (const cv::Exception& e) {
    return Status::Internal(std::string("PNG encoding failed: ") + e.what());
  }
}

Status WriteDepthPly(const fs::path& path, const cv::Mat& depth_um, const DepthExportMeta& meta) {
  INSPECT_RETURN_IF_ERROR(CheckFloatMap(depth_um, "depth_um"));
  INSPECT_RETURN_IF_ERROR(CheckPixelSize(meta));
  const double step = LateralStepOrOne(meta);
  std::vector<float> xyz;
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      if (!std::isfinite(d[x])) continue;
      xyz.push_back(float(x * step));
      xyz.push_back(float(y * step));
      xyz.push_back(d[x]);
    }
  }
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  if (meta.pixel_size_um > 0.0) {
    header += "comment inspection depth map; x, y, z in um\n";
    header += "comment pixel_size_um " + FormatDouble(meta.pixel_size_um) + "\n";
  } else {
    header += "comment inspection depth map; x, y in pixels, z in um\n";
    header += "comment " + std::string(kUnknownScaleNote) + "\n";
  }
  if (!meta.description.empty()) {
    std::string desc = meta.description;
    std::replace(desc.begin(), desc.end(), '\n', ' ');
    header += "comment " + desc + "\n";
  }
  header += "element vertex " + std::to_string(xyz.size() / 3) +
            "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  // x86-64 and every platform this runs on are little endian, as the header declares.
  static_assert(std::endian::native == std::endian::little, "PLY body is written in native byte order");
  std::string bytes = header;
  bytes.append(reinterpret_cast<const char*>(xyz.data()), xyz.size() * sizeof(float));
  return WriteBytesAtomic(path, bytes.data(), bytes.size());
}

Status WriteDepthX3p(const fs::path& path, const cv::Mat& depth_um, const DepthExportMeta& meta) {
  INSPECT_RETURN_IF_ERROR(CheckFloatMap(depth_um, "depth_um"));
  INSPECT_RETURN_IF_ERROR(CheckPixelSize(meta));
  // Point data: float64 metres, x fastest, NaN = not measured (no ValidPointsLink needed).
  std::vector<double> data(depth_um.total());
  size_t i = 0;
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      data[i++] = std::isfinite(d[x]) ? double(d[x]) * 1e-6 : std::numeric_limits<double>::quiet_NaN();
    }
  }
  const std::string data_md5 = Md5Hex(data.data(), data.size() * sizeof(double));
  if (data_md5.empty()) return Status::Internal("x3p " + path.string() + ": OpenSSL has no MD5 for the checksums");
  // Unknown scale: a 1 um increment (one unit per pixel), stated in Record2's comment.
  const std::string px_m = FormatDouble(LateralStepOrOne(meta) * 1e-6);
  const std::string comment = meta.pixel_size_um > 0.0
                                  ? meta.description
                                  : std::string(kUnknownScaleNote) + " (CX/CY increments of 1e-6 are 1 pixel)" +
                                        (meta.description.empty() ? "" : "; " + meta.description);
  const std::string now = UtcNowIso8601();
  std::string xml;
  xml += "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  xml +=
      "<p:ISO5436_2 xmlns:p=\"http://www.opengps.eu/2008/ISO5436_2\" "
      "xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" "
      "xsi:schemaLocation=\"http://www.opengps.eu/2008/ISO5436_2 "
      "http://www.opengps.eu/2008/ISO5436_2/ISO5436_2.xsd\">\n";
  xml += "  <Record1>\n    <Revision>ISO5436 - 2000</Revision>\n    <FeatureType>SUR</FeatureType>\n    <Axes>\n";
  xml += "      <CX>\n        <AxisType>I</AxisType>\n        <DataType>D</DataType>\n        <Increment>" + px_m +
         "</Increment>\n        <Offset>0</Offset>\n      </CX>\n";
  xml += "      <CY>\n        <AxisType>I</AxisType>\n        <DataType>D</DataType>\n        <Increment>" + px_m +
         "</Increment>\n        <Offset>0</Offset>\n      </CY>\n";
  xml +=
      "      <CZ>\n        <AxisType>A</AxisType>\n        <DataType>D</DataType>\n        <Increment>1</Increment>\n"
      "        <Offset>0</Offset>\n      </CZ>\n";
  xml += "    </Axes>\n  </Record1>\n";
  xml += "  <Record2>\n    <Date>" + now + "</Date>\n    <Creator>inspection</Creator>\n";
  xml +=
      "    <Instrument>\n      <Manufacturer>inspection</Manufacturer>\n      <Model>SFF microscope</Model>\n"
      "      <Serial>not available</Serial>\n      <Version>0.1</Version>\n    </Instrument>\n";
  xml += "    <CalibrationDate>" + now + "</CalibrationDate>\n";
  xml +=
      "    <ProbingSystem>\n      <Type>NonContacting</Type>\n      <Identification>shape from focus</Identification>\n"
      "    </ProbingSystem>\n";
  xml += "    <Comment>" + XmlEscape(comment) + "</Comment>\n  </Record2>\n";
  xml += "  <Record3>\n    <MatrixDimension>\n      <SizeX>" + std::to_string(depth_um.cols) +
         "</SizeX>\n      <SizeY>" + std::to_string(depth_um.rows) +
         "</SizeY>\n      <SizeZ>1</SizeZ>\n    </MatrixDimension>\n";
  xml += "    <DataLink>\n      <PointDataLink>bindata/data.bin</PointDataLink>\n      <MD5ChecksumPointData>" +
         data_md5 + "</MD5ChecksumPointData>\n    </DataLink>\n  </Record3>\n";
  xml += "  <Record4>\n    <ChecksumFile>md5checksum.hex</ChecksumFile>\n  </Record4>\n</p:ISO5436_2>\n";
  // As "md5sum main.xml" prints it (binary mode marker), so "md5sum -c" can check it.
  const std::string checksum = Md5Hex(xml.data(), xml.size()) + " *main.xml\n";

  const fs::path tmp = TmpPath(path);
  RemoveQuietly(tmp);
  int err = 0;
  zip_t* z = zip_open(tmp.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &err);
  if (!z)
    return Status::InvalidArgument(path.string() + ": cannot create zip (libzip error " + std::to_string(err) + ")");
  auto add = [&](const char* name, const void* bytes, size_t n) -> bool {
    zip_source_t* src = zip_source_buffer(z, bytes, n, 0);
    if (!src) return false;
    if (zip_file_add(z, name, src, ZIP_FL_ENC_UTF_8) < 0) {
      zip_source_free(src);
      return false;
    }
    return true;
  };
  const bool ok = zip_dir_add(z, "bindata", ZIP_FL_ENC_UTF_8) >= 0 && add("main.xml", xml.data(), xml.size()) &&
                  add("bindata/data.bin", data.data(), data.size() * sizeof(double)) &&
                  add("md5checksum.hex", checksum.data(), checksum.size());
  if (!ok) {
    const std::string msg = zip_strerror(z);
    zip_discard(z);
    RemoveQuietly(tmp);
    return Status::Internal(path.string() + ": zip assembly failed: " + msg);
  }
  if (zip_close(z) != 0) {
    const std::string msg = zip_strerror(z);
    zip_discard(z);
    RemoveQuietly(tmp);
    return Status::Internal(path.string() + ": zip write failed: " + msg);
  }
  return CommitTmp(tmp, path);
}

}  // namespace inspection
