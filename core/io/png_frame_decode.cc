// DecodePlainPng (core/io/png_frame_decode.h): PNG chunks (CRC-checked), the zlib stream inflated
// whole by libdeflate (Adler-32 checked) straight into the image's buffer, rows unfiltered in
// place (PNG spec 9.2), then put in OpenCV's channel and byte order.
#include "core/io/png_frame_decode.h"

#include <libdeflate.h>

#include <bit>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "core/io/internal/png_unfilter_kernel.h"

namespace inspection {

namespace {

uint32_t Be32(const unsigned char* p) {
  return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | uint32_t(p[3]);
}

// Reverses one row's filter: in (the filtered bytes) -> out (may lie before in within the same
// buffer: out[x] is written after in[x] is read, and never reaches an unread byte of in).
// up: the previous reconstructed row (zeros for the first). False for an unknown filter type.
bool Unfilter(int filter, const unsigned char* in, const unsigned char* up, unsigned char* out, size_t stride,
              size_t bpp) {
  switch (filter) {
    case 0:  // None
      std::memmove(out, in, stride);
      return true;
    case 1:  // Sub
      if (bpp == 1) {
        png_internal::PickPngUnfilter().sub1(in, out, stride);
        return true;
      }
      if (bpp == 2) {
        png_internal::PickPngUnfilter().sub2(in, out, stride);
        return true;
      }
      for (size_t x = 0; x < bpp; ++x) out[x] = in[x];
      for (size_t x = bpp; x < stride; ++x) out[x] = uint8_t(in[x] + out[x - bpp]);
      return true;
    case 2:  // Up
      png_internal::PickPngUnfilter().up(in, up, out, stride);
      return true;
    case 3:  // Average
      for (size_t x = 0; x < bpp; ++x) out[x] = uint8_t(in[x] + up[x] / 2);
      for (size_t x = bpp; x < stride; ++x) out[x] = uint8_t(in[x] + (int(out[x - bpp]) + int(up[x])) / 2);
      return true;
    case 4:  // Paeth; left and upper-left are 0 for the first pixel, which predicts "up"
      for (size_t x = 0; x < bpp; ++x) out[x] = uint8_t(in[x] + up[x]);
      for (size_t x = bpp; x < stride; ++x) {
        const int a = out[x - bpp], b = up[x], c = up[x - bpp];
        const int pa = std::abs(b - c), pb = std::abs(a - c), pc = std::abs(a + b - 2 * c);
        out[x] = uint8_t(in[x] + (pa <= pb && pa <= pc ? a : pb <= pc ? b : c));
      }
      return true;
    default:
      return false;
  }
}

struct Decompressor {
  libdeflate_decompressor* d = libdeflate_alloc_decompressor();
  ~Decompressor() {
    if (d) libdeflate_free_decompressor(d);
  }
};

}  // namespace

cv::Mat DecodePlainPng(std::string_view file, size_t max_raw_bytes) {
  static constexpr unsigned char kSignature[8] = {137, 80, 78, 71, 13, 10, 26, 10};
  if (file.size() < 8 || std::memcmp(file.data(), kSignature, 8) != 0) return {};
  const auto* bytes = reinterpret_cast<const unsigned char*>(file.data());
  uint32_t width = 0, height = 0;
  int bit_depth = 0, colour_type = 0;
  bool header = false, end = false;
  // The IDAT chunks' bytes, joined (libpng writes 8 KiB chunks; libdeflate inflates one buffer).
  // A buffer per thread, reused from frame to frame: a fresh one per frame cost ~200 page faults.
  thread_local std::string idat;
  idat.clear();
  struct TrimOnReturn {  // an unusually large frame's buffer is not kept
    std::string& s;
    ~TrimOnReturn() {
      if (s.capacity() > kPngFastPathKeptBufferBytes) s = std::string();
    }
  } trim{idat};
  for (size_t pos = 8; pos + 12 <= file.size();) {
    const uint32_t length = Be32(bytes + pos);
    if (length > file.size() - pos - 12) return {};
    const unsigned char* type = bytes + pos + 4;
    const unsigned char* data = type + 4;
    if (libdeflate_crc32(0, type, size_t(length) + 4) != Be32(data + length)) return {};
    const std::string_view name(reinterpret_cast<const char*>(type), 4);
    if (!header) {
      if (name != "IHDR" || length != 13) return {};
      width = Be32(data);
      height = Be32(data + 4);
      bit_depth = data[8];
      colour_type = data[9];
      // compression 0, filter method 0, no interlace; grey (0) or RGB (2) at 8 or 16 bits.
      if (data[10] != 0 || data[11] != 0 || data[12] != 0) return {};
      if ((colour_type != 0 && colour_type != 2) || (bit_depth != 8 && bit_depth != 16)) return {};
      header = true;
    } else if (name == "IDAT") {
      if (idat.capacity() < file.size()) idat.reserve(file.size());
      idat.append(reinterpret_cast<const char*>(data), length);
    } else if (name == "IEND") {
      end = true;
      break;
    } else if (name == "tRNS" || name == "PLTE" || !(type[0] & 0x20)) {
      return {};  // transparency (imread adds alpha), a palette, or an unknown critical chunk
    }
    pos += 12 + size_t(length);
  }
  if (!end || idat.empty() || width == 0 || height == 0) return {};
  const int channels = colour_type == 2 ? 3 : 1, sample_bytes = bit_depth / 8;
  const size_t bpp = size_t(channels) * sample_bytes, stride = size_t(width) * bpp;
  const size_t raw_bytes = size_t(height) * (stride + 1);
  // Larger frames take the general path, whose decoder applies OpenCV's own image-size limits:
  // the buffer below is allocated from the header before the data is seen.
  if (width > uint32_t(std::numeric_limits<int>::max()) / bpp ||
      raw_bytes / (stride + 1) != height || raw_bytes > max_raw_bytes ||
      raw_bytes > size_t(std::numeric_limits<int>::max())) {
    return {};
  }
  // One buffer: the inflated rows (a filter byte each, so `height` bytes more than the image),
  // unfiltered and moved down in place into the image rows it then holds.
  const int depth = sample_bytes == 2 ? CV_16U : CV_8U;
  cv::Mat buffer(1, int((raw_bytes + sample_bytes - 1) / sample_bytes), CV_MAKETYPE(depth, 1));
  unsigned char* base = buffer.data;
  Decompressor inflater;
  if (!inflater.d) return {};
  if (libdeflate_zlib_decompress(inflater.d, idat.data(), idat.size(), base, raw_bytes, nullptr) !=
      LIBDEFLATE_SUCCESS) {
    return {};  // corrupt, truncated or longer than the image
  }
  const std::vector<unsigned char> zeros(stride, 0);
  for (size_t y = 0; y < height; ++y) {
    const unsigned char* in = base + y * (stride + 1);
    const int filter = in[0];
    if (!Unfilter(filter, in + 1, y > 0 ? base + (y - 1) * stride : zeros.data(), base + y * stride, stride, bpp)) {
      return {};
    }
  }
  const size_t samples = size_t(height) * width * channels;
  if (sample_bytes == 2 && std::endian::native == std::endian::little) {  // PNG's 16-bit samples are big-endian
    uint16_t* s = reinterpret_cast<uint16_t*>(base);
    for (size_t i = 0; i < samples; ++i) s[i] = uint16_t(s[i] << 8 | s[i] >> 8);
  }
  if (channels == 3) {  // RGB -> BGR
    if (sample_bytes == 2) {
      uint16_t* s = reinterpret_cast<uint16_t*>(base);
      for (size_t i = 0; i < samples; i += 3) std::swap(s[i], s[i + 2]);
    } else {
      for (size_t i = 0; i < samples; i += 3) std::swap(base[i], base[i + 2]);
    }
  }
  return buffer.colRange(0, int(samples)).reshape(channels, int(height));
}

}  // namespace inspection
