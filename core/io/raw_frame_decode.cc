// Camera RAW decoding through LibRaw (core/io/raw_frame_decode.h). libraw_r (the thread-safe
// build): the stack frame decoder runs several decodes at once.
#include "core/io/raw_frame_decode.h"

#include <libraw/libraw.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <cstring>
#include <memory>

namespace inspection {
namespace {

struct ProcessedImage {
  libraw_processed_image_t* image = nullptr;
  ~ProcessedImage() {
    if (image) LibRaw::dcraw_clear_mem(image);
  }
};

// open_* done: unpack, demosaic, convert, copy out.
StatusOr<cv::Mat> Develop(LibRaw& raw, int open_rc, const std::string& name) {
  auto fail = [&](const char* step, int rc) {
    return Status::InvalidArgument(name + ": cannot " + step + " camera RAW: " + libraw_strerror(rc));
  };
  if (open_rc != LIBRAW_SUCCESS) return fail("open", open_rc);
  libraw_output_params_t& p = raw.imgdata.params;
  p.output_bps = 16;
  p.gamm[0] = 1.0;  // linear: gamma 1, toe slope 1
  p.gamm[1] = 1.0;
  p.no_auto_bright = 1;
  p.use_camera_wb = 1;
  p.output_color = 1;  // sRGB primaries
  p.user_flip = -1;    // the file's orientation
  // Never rescale by the frame's own brightest pixel: frames of one stack must stay comparable.
  p.adjust_maximum_thr = 0.0f;
  if (int rc = raw.unpack(); rc != LIBRAW_SUCCESS) return fail("unpack", rc);
  if (int rc = raw.dcraw_process(); rc != LIBRAW_SUCCESS) return fail("process", rc);
  int rc = LIBRAW_SUCCESS;
  ProcessedImage out{raw.dcraw_make_mem_image(&rc)};
  if (!out.image || rc != LIBRAW_SUCCESS) return fail("develop", rc);
  const libraw_processed_image_t& img = *out.image;
  if (img.type != LIBRAW_IMAGE_BITMAP || img.bits != 16 || (img.colors != 1 && img.colors != 3)) {
    return Status::InvalidArgument(name + ": camera RAW developed to an unexpected image (" +
                                   std::to_string(img.colors) + " colours, " + std::to_string(img.bits) + " bits)");
  }
  const size_t bytes = size_t(img.width) * img.height * img.colors * 2;
  if (img.data_size < bytes) return Status::InvalidArgument(name + ": camera RAW developed to a truncated image");
  // LibRaw's memory image: interleaved RGB (or grey), 16-bit in host byte order.
  cv::Mat rgb(img.height, img.width, CV_16UC(img.colors));
  std::memcpy(rgb.data, img.data, bytes);
  if (img.colors == 1) return rgb;
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

}  // namespace

bool IsRawFrameFile(std::string_view file_name) {
  const size_t dot = file_name.rfind('.');
  if (dot == std::string_view::npos) return false;
  std::string ext(file_name.substr(dot + 1));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  static constexpr std::array<const char*, 14> kRaw = {"dng", "cr2", "cr3", "crw", "nef", "nrw", "arw",
                                                       "srw", "raf", "orf", "rw2", "pef", "3fr", "iiq"};
  return std::any_of(kRaw.begin(), kRaw.end(), [&](const char* e) { return ext == e; });
}

StatusOr<cv::Mat> DecodeRawFrame(std::string_view bytes, const std::string& name) {
  auto raw = std::make_unique<LibRaw>();  // large: not on the decode thread's stack
  // LibRaw reads the buffer only, despite the non-const pointer.
  const int rc = raw->open_buffer(const_cast<char*>(bytes.data()), bytes.size());
  return Develop(*raw, rc, name);
}

StatusOr<cv::Mat> DecodeRawFrameFile(const std::string& path, const std::string& name) {
  auto raw = std::make_unique<LibRaw>();
  const int rc = raw->open_file(path.c_str());
  return Develop(*raw, rc, name);
}

}  // namespace inspection
