// Stage: moves the specimen along the optical axis (z) through the focus plane.
#pragma once

#include "core/util/status.h"
#include "devices/camera.h"

namespace inspection {

class Stage {
 public:
  virtual ~Stage() = default;

  virtual DeviceInfo info() const = 0;
  virtual double min_z_um() const = 0;  // travel limits
  virtual double max_z_um() const = 0;

  virtual Status Home() = 0;
  // Moves and waits until the move completed and the stage settled. OUT_OF_RANGE outside the
  // travel limits, DEADLINE_EXCEEDED on move timeout, UNAVAILABLE when the device is gone.
  virtual Status MoveTo(double z_um) = 0;
  // Position as last reported by the device (simulated: includes repeatability error).
  virtual StatusOr<double> position_um() = 0;
  // +- bound of the uniform error of one move (datasheet or measured), for measurement
  // uncertainty (core/metrology/depth_noise_model.h); 0 = not characterised.
  virtual double repeatability_um() const { return 0.0; }
};

}  // namespace inspection
