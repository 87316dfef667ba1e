// DeviceRig: a Rig built from real drivers by CreateRig (devices/rig_config.h). Owns the
// devices; knows how to reconnect each one for Rig::Reset.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "devices/rig.h"

namespace inspection {

class DeviceRig : public Rig {
 public:
  struct Part {
    std::function<Status()> connect;  // (re)connects; empty for devices that cannot be lost
  };

  DeviceRig(std::unique_ptr<Camera> camera, Part camera_part, std::unique_ptr<Stage> stage, Part stage_part,
            std::unique_ptr<Projector> projector, Part projector_part, double pixel_size_um, ScanDefaults defaults)
      : camera_(std::move(camera)),
        stage_(std::move(stage)),
        projector_(std::move(projector)),
        parts_{std::move(camera_part), std::move(stage_part), std::move(projector_part)},
        pixel_size_um_(pixel_size_um),
        defaults_(defaults) {}

  Camera& camera() override { return *camera_; }
  Projector& projector() override { return *projector_; }
  Stage& stage() override { return *stage_; }
  double pixel_size_um() const override { return pixel_size_um_; }
  ScanDefaults scan_defaults() const override { return defaults_; }

  // Reconnects every device (a reset after an error must not trust a device that merely
  // still looks connected), then reports what is still missing, naming each device.
  Status Reset() override;

 private:
  std::unique_ptr<Camera> camera_;
  std::unique_ptr<Stage> stage_;
  std::unique_ptr<Projector> projector_;
  Part parts_[3];  // camera, stage, projector
  double pixel_size_um_;
  ScanDefaults defaults_;
};

}  // namespace inspection
