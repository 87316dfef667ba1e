// FramebufferProjector: an HDMI-attached LCoS/DLP micro-display driven through the Linux
// framebuffer (/dev/fbN). Queries the mode (FBIOGET_VSCREENINFO / FBIOGET_FSCREENINFO), converts
// the 8-bit grey pattern to the display's pixel format (8/16/24/32 bpp, from the RGB bitfields)
// and writes it into the calibrated region of the framebuffer (thesis 4.1: the projector image
// plane is conjugate to the camera through the shared objective; the region and flips place
// the pattern where the geometric calibration expects it).
#pragma once

#include <optional>
#include <string>

#include "devices/drivers/published_info.h"
#include "devices/projector.h"

namespace inspection {

// One colour channel: bit offset within the pixel and number of bits (fb_bitfield).
struct FramebufferBitfield {
  int offset = 0;
  int length = 0;
};

struct FramebufferMode {
  int width = 0;              // visible pixels (xres)
  int height = 0;             // visible lines (yres)
  int bits_per_pixel = 32;    // 8, 16, 24 or 32
  int line_length_bytes = 0;  // stride; 0 = width * bytes per pixel
  int x_offset = 0;           // visible area within the virtual framebuffer (xoffset, yoffset)
  int y_offset = 0;
  // 8 bpp is treated as grey (identity palette). Defaults: XRGB8888 / RGB565 / BGR888 layouts.
  FramebufferBitfield red{16, 8}, green{8, 8}, blue{0, 8}, transp{0, 0};

  int bytes_per_pixel() const { return (bits_per_pixel + 7) / 8; }
  int stride() const { return line_length_bytes > 0 ? line_length_bytes : width * bytes_per_pixel(); }
  Status Validate() const;
};

struct FramebufferProjectorOptions {
  std::string device = "/dev/fb0";
  // Required when `device` is not a framebuffer device (a regular file stand-in for tests or a
  // headless dry run); ignored for real /dev/fbN, whose mode is queried.
  std::optional<FramebufferMode> mode;
  // Calibrated geometry: the pattern occupies this region of the visible screen (width/height
  // 0 = the whole screen) and may be mirrored to match the optical path.
  int region_x = 0;
  int region_y = 0;
  int region_width = 0;
  int region_height = 0;
  bool flip_horizontal = false;
  bool flip_vertical = false;
};

// Not thread-safe, except info(), which any thread may call. Operations return UNAVAILABLE while the display is not
// connected.
class FramebufferProjector : public Projector {
 public:
  explicit FramebufferProjector(FramebufferProjectorOptions options);
  ~FramebufferProjector() override;

  // Opens the device (or file) and determines the mode; UNAVAILABLE when absent.
  Status Connect();

  DeviceInfo info() const override { return published_.Get(); }
  cv::Size resolution() const override;
  Status Show(const cv::Mat& pattern) override;

  const FramebufferMode& mode() const { return mode_; }
  // The bytes of one pixel of grey value g in the current mode (exposed for tests).
  void EncodePixel(uint8_t grey, uint8_t* out) const;

 private:
  void Close();
  DeviceInfo BuildInfo() const;
  struct Republish {
    FramebufferProjector* p;
    ~Republish() { p->published_.Set(p->BuildInfo()); }
  };

  FramebufferProjectorOptions options_;
  FramebufferMode mode_;
  int fd_ = -1;
  bool is_device_ = false;
  std::string fb_id_;
  std::string last_error_ = "not connected yet";
  cv::Rect region_;
  PublishedInfo published_;
};

}  // namespace inspection
