// Camera: one grey-scale image per software trigger. Implemented by the simulated rig and by
// the Aravis driver (GigE Vision / USB3 Vision). Not thread-safe: the rig's job worker owns it.
#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "core/util/status.h"

namespace inspection {

struct DeviceInfo {
  std::string role;    // "camera", "stage", "projector"
  std::string driver;  // "simulated", "aravis", "apt-usb", "framebuffer", ...
  std::string model;
  std::string serial;
  bool connected = false;
  std::string detail;  // human-readable state, e.g. the last error
};

class Camera {
 public:
  virtual ~Camera() = default;

  virtual DeviceInfo info() const = 0;
  virtual cv::Size frame_size() const = 0;
  virtual int bit_depth() const = 0;  // significant bits: 8, 10, 12 or 16

  virtual Status SetExposure(double exposure_us) = 0;
  virtual double exposure_us() const = 0;
  virtual Status SetGain(double gain_db) = 0;

  // Triggers one exposure and waits for it. Returns CV_8UC1 when bit_depth() == 8, else CV_16UC1
  // with values in [0, 2^bit_depth - 1]. UNAVAILABLE when the device is gone, DEADLINE_EXCEEDED
  // on frame timeout.
  virtual StatusOr<cv::Mat> Capture() = 0;
};

}  // namespace inspection
