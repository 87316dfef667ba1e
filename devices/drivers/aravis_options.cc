// Aravis camera options: validation without linking Aravis (rig configs are checked even in
// builds without the real drivers).
#include "devices/drivers/aravis_camera.h"

namespace inspection {

StatusOr<int> AravisPixelFormatBits(const std::string& f) {
  if (f == "Mono8") return 8;
  if (f == "Mono10") return 10;
  if (f == "Mono12") return 12;
  if (f == "Mono16") return 16;
  return Status::InvalidArgument("pixel_format '" + f + "' is not supported (Mono8, Mono10, Mono12, Mono16)");
}

Status AravisCameraOptions::Validate() const {
  if (!AravisPixelFormatBits(pixel_format).ok()) return AravisPixelFormatBits(pixel_format).status();
  if (!(exposure_us > 0.0)) return Status::InvalidArgument("exposure_us must be > 0");
  if (!(frame_timeout_ms > 0.0)) return Status::InvalidArgument("frame_timeout_ms must be > 0");
  if (n_buffers < 1) return Status::InvalidArgument("n_buffers must be >= 1");
  if (packet_size < 0) return Status::InvalidArgument("packet_size must be >= 0");
  if (region_x < 0 || region_y < 0 || region_width < 0 || region_height < 0) {
    return Status::InvalidArgument("region_x/region_y/region_width/region_height must be >= 0");
  }
  return Status::Ok();
}

}  // namespace inspection
