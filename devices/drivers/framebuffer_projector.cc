// Linux framebuffer projector: mode query, grey -> pixel format conversion, region blit.
#include "devices/drivers/framebuffer_projector.h"

#include <fcntl.h>
#include <linux/fb.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

namespace inspection {
namespace {

std::string Errno(const std::string& what) { return what + ": " + std::strerror(errno); }

}  // namespace

Status FramebufferMode::Validate() const {
  if (width <= 0 || height <= 0) return Status::InvalidArgument("mode.width and mode.height must be > 0");
  if (bits_per_pixel != 8 && bits_per_pixel != 16 && bits_per_pixel != 24 && bits_per_pixel != 32) {
    return Status::InvalidArgument("mode.bits_per_pixel must be 8, 16, 24 or 32");
  }
  if (line_length_bytes != 0 && line_length_bytes < width * bytes_per_pixel()) {
    return Status::InvalidArgument("mode.line_length_bytes is smaller than width * bytes per pixel");
  }
  if (x_offset < 0 || y_offset < 0) return Status::InvalidArgument("mode.x_offset/y_offset must be >= 0");
  for (const FramebufferBitfield* f : {&red, &green, &blue, &transp}) {
    if (f->offset < 0 || f->length < 0 || f->length > 8 || f->offset + f->length > bits_per_pixel) {
      if (bits_per_pixel != 8) return Status::InvalidArgument("mode colour bitfields must lie within the pixel");
    }
  }
  return Status::Ok();
}

FramebufferProjector::FramebufferProjector(FramebufferProjectorOptions options) : options_(std::move(options)) {
  if (options_.mode) mode_ = *options_.mode;
  published_.Set(BuildInfo());
}

FramebufferProjector::~FramebufferProjector() { Close(); }

void FramebufferProjector::Close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

Status FramebufferProjector::Connect() {
  Republish publish{this};
  Close();
  const std::string& path = options_.device;
  int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) {
    last_error_ = Errno("opening " + path);
    return Status::Unavailable("projector (framebuffer): " + last_error_ +
                               (errno == EACCES ? " (add the service user to group 'video')" : ""));
  }
  struct stat st {};
  ::fstat(fd, &st);
  is_device_ = S_ISCHR(st.st_mode);
  if (is_device_) {
    fb_var_screeninfo var{};
    fb_fix_screeninfo fix{};
    if (::ioctl(fd, FBIOGET_VSCREENINFO, &var) != 0 || ::ioctl(fd, FBIOGET_FSCREENINFO, &fix) != 0) {
      last_error_ = Errno(path + " is not a framebuffer (FBIOGET_*SCREENINFO)");
      ::close(fd);
      return Status::Unavailable("projector (framebuffer): " + last_error_);
    }
    if (fix.type != FB_TYPE_PACKED_PIXELS) {
      ::close(fd);
      last_error_ = path + ": only packed-pixel framebuffers are supported";
      return Status::Unavailable("projector (framebuffer): " + last_error_);
    }
    mode_.width = static_cast<int>(var.xres);
    mode_.height = static_cast<int>(var.yres);
    mode_.bits_per_pixel = static_cast<int>(var.bits_per_pixel);
    mode_.line_length_bytes = static_cast<int>(fix.line_length);
    mode_.x_offset = static_cast<int>(var.xoffset);
    mode_.y_offset = static_cast<int>(var.yoffset);
    mode_.red = {static_cast<int>(var.red.offset), static_cast<int>(var.red.length)};
    mode_.green = {static_cast<int>(var.green.offset), static_cast<int>(var.green.length)};
    mode_.blue = {static_cast<int>(var.blue.offset), static_cast<int>(var.blue.length)};
    mode_.transp = {static_cast<int>(var.transp.offset), static_cast<int>(var.transp.length)};
    fb_id_ = std::string(fix.id, strnlen(fix.id, sizeof fix.id));
  } else {
    if (!options_.mode) {
      ::close(fd);
      last_error_ = path + " is not a framebuffer device; projector.mode must describe it";
      return Status::InvalidArgument("projector: " + last_error_);
    }
    mode_ = *options_.mode;
    fb_id_ = "file";
  }
  if (Status s = mode_.Validate(); !s.ok()) {
    ::close(fd);
    last_error_ = s.message();
    return Status::Unavailable("projector (framebuffer) " + path + ": unsupported mode: " + s.message());
  }
  const int rw = options_.region_width > 0 ? options_.region_width : mode_.width - options_.region_x;
  const int rh = options_.region_height > 0 ? options_.region_height : mode_.height - options_.region_y;
  region_ = cv::Rect(options_.region_x, options_.region_y, rw, rh);
  if (region_.x < 0 || region_.y < 0 || rw <= 0 || rh <= 0 || region_.x + rw > mode_.width ||
      region_.y + rh > mode_.height) {
    ::close(fd);
    last_error_ = "region " + std::to_string(region_.x) + "," + std::to_string(region_.y) + " " + std::to_string(rw) +
                  "x" + std::to_string(rh) + " does not fit the " + std::to_string(mode_.width) + "x" +
                  std::to_string(mode_.height) + " screen";
    return Status::InvalidArgument("projector: " + last_error_);
  }
  if (!is_device_) {
    // A stand-in file must hold the whole virtual screen the mode describes.
    const off_t needed = static_cast<off_t>(mode_.stride()) * (mode_.y_offset + mode_.height);
    if (st.st_size < needed && ::ftruncate(fd, needed) != 0) {
      last_error_ = Errno("sizing " + path);
      ::close(fd);
      return Status::Unavailable("projector (framebuffer): " + last_error_);
    }
  }
  fd_ = fd;
  last_error_.clear();
  return Status::Ok();
}

DeviceInfo FramebufferProjector::BuildInfo() const {
  DeviceInfo d;
  d.role = "projector";
  d.driver = "framebuffer";
  d.model = fb_id_.empty() ? options_.device : fb_id_ + " " + options_.device;
  d.connected = fd_ >= 0;
  d.detail = fd_ >= 0 ? std::to_string(mode_.width) + "x" + std::to_string(mode_.height) + " " +
                            std::to_string(mode_.bits_per_pixel) + " bpp, region " + std::to_string(region_.width) +
                            "x" + std::to_string(region_.height) + "+" + std::to_string(region_.x) + "+" +
                            std::to_string(region_.y)
                      : last_error_;
  return d;
}

cv::Size FramebufferProjector::resolution() const {
  if (fd_ < 0 && options_.region_width > 0) return {options_.region_width, options_.region_height};
  return region_.size();
}

void FramebufferProjector::EncodePixel(uint8_t grey, uint8_t* out) const {
  const int bpp = mode_.bytes_per_pixel();
  if (mode_.bits_per_pixel == 8) {
    out[0] = grey;
    return;
  }
  auto channel = [grey](const FramebufferBitfield& f) -> uint32_t {
    if (f.length <= 0) return 0;
    return (static_cast<uint32_t>(grey) >> (8 - f.length)) << f.offset;
  };
  uint32_t v = channel(mode_.red) | channel(mode_.green) | channel(mode_.blue);
  if (mode_.transp.length > 0) v |= ((1u << mode_.transp.length) - 1u) << mode_.transp.offset;  // opaque
  for (int i = 0; i < bpp; ++i) out[i] = static_cast<uint8_t>((v >> (8 * i)) & 0xFF);           // little-endian memory
}

Status FramebufferProjector::Show(const cv::Mat& pattern) {
  Republish publish{this};
  if (fd_ < 0)
    return Status::Unavailable("projector (framebuffer " + options_.device + ") is not connected: " + last_error_);
  if (pattern.type() != CV_8UC1 || pattern.size() != region_.size()) {
    return Status::InvalidArgument("pattern must be CV_8UC1 of " + std::to_string(region_.width) + "x" +
                                   std::to_string(region_.height) + " (projector resolution)");
  }
  const int bpp = mode_.bytes_per_pixel();
  // Grey -> pixel bytes once per grey level.
  std::vector<uint8_t> lut(256 * 4);
  for (int g = 0; g < 256; ++g) EncodePixel(static_cast<uint8_t>(g), &lut[static_cast<size_t>(g) * 4]);
  std::vector<uint8_t> row(static_cast<size_t>(region_.width) * bpp);
  for (int y = 0; y < region_.height; ++y) {
    const int src_y = options_.flip_vertical ? region_.height - 1 - y : y;
    const uint8_t* src = pattern.ptr<uint8_t>(src_y);
    for (int x = 0; x < region_.width; ++x) {
      const int src_x = options_.flip_horizontal ? region_.width - 1 - x : x;
      std::memcpy(&row[static_cast<size_t>(x) * bpp], &lut[static_cast<size_t>(src[src_x]) * 4], bpp);
    }
    const off_t offset = static_cast<off_t>(mode_.y_offset + region_.y + y) * mode_.stride() +
                         static_cast<off_t>(mode_.x_offset + region_.x) * bpp;
    size_t done = 0;
    while (done < row.size()) {
      const ssize_t n = ::pwrite(fd_, row.data() + done, row.size() - done, offset + static_cast<off_t>(done));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        last_error_ = Errno("writing " + options_.device);
        Close();  // e.g. ENODEV after the display was unplugged; Connect() reopens
        return Status::Unavailable("projector (framebuffer): " + last_error_);
      }
      done += static_cast<size_t>(n);
    }
  }
  if (is_device_) {
    // Return once the frame has been scanned out; drivers without vsync support say ENOTTY.
    uint32_t crtc = 0;
    ::ioctl(fd_, FBIO_WAITFORVSYNC, &crtc);
  }
  return Status::Ok();
}

}  // namespace inspection
