// Projector: the adaptive light source sharing the microscope objective with the camera
// (thesis 4.1). Shows 8-bit grey patterns at its native resolution.
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"
#include "devices/camera.h"

namespace inspection {

class Projector {
 public:
  virtual ~Projector() = default;

  virtual DeviceInfo info() const = 0;
  virtual cv::Size resolution() const = 0;  // e.g. 1280x720

  // pattern: CV_8UC1 of resolution(). Returns when the pattern is on the display.
  virtual Status Show(const cv::Mat& pattern) = 0;
  // Convenience: a uniform grey pattern (thesis STD illumination uses 128).
  virtual Status ShowUniform(int grey);
};

}  // namespace inspection
