// Rig configuration file: which driver and parameters for camera, stage and projector, and the
// factory that builds a Rig from it (inspectd --rig-config FILE). Format: JSON, documented in
// docs/devices.md; every error names the key, e.g. "rig config: camera.exposure_us must be > 0".
//
// A config selects either the simulated rig as a whole (every driver "simulated", options under
// "simulation") or real drivers for all three devices:
//   camera.driver     "aravis"        GigE Vision / USB3 Vision through Aravis
//   stage.driver      "apt-usb"       Thorlabs APT controller over its FTDI USB bridge (libusb)
//   projector.driver  "framebuffer"   Linux framebuffer /dev/fbN (HDMI micro-display)
//                     "none"          no projector: uniform illumination only
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "core/util/status.h"
#include "devices/drivers/apt_stage.h"
#include "devices/drivers/aravis_camera.h"
#include "devices/drivers/framebuffer_projector.h"
#include "devices/drivers/libusb_transport.h"
#include "devices/rig.h"
#include "devices/sim/simulated_rig.h"

namespace inspection {

struct RigConfig {
  bool simulated = true;  // true: everything below except `simulation` is unused
  SimulatedRigOptions simulation;

  std::string name;            // free text shown in GetRigStatus
  double pixel_size_um = 0.0;  // camera pixel on the specimen; required for a real rig
  ScanDefaults scan_defaults;

  std::string camera_driver = "simulated";
  AravisCameraOptions camera;

  std::string stage_driver = "simulated";
  AptStageOptions stage;
  UsbDeviceSelector stage_usb;

  std::string projector_driver = "simulated";
  FramebufferProjectorOptions projector;
  cv::Size projector_none_resolution{1280, 720};  // projector.driver "none"
};

// INVALID_ARGUMENT naming the key; NOT_FOUND when the file does not exist.
StatusOr<RigConfig> LoadRigConfig(const std::filesystem::path& path);
StatusOr<RigConfig> ParseRigConfig(const std::string& text);

struct RigStartOptions {
  // false: a configured device that is absent fails CreateRig with UNAVAILABLE naming it.
  // true: the rig starts anyway; the absent device reports info().connected == false with the
  // reason, its operations return UNAVAILABLE, Rig::CheckDevices() says why, Rig::Reset() retries.
  bool allow_degraded = false;
};

StatusOr<std::unique_ptr<Rig>> CreateRig(const RigConfig& config, const RigStartOptions& options);

}  // namespace inspection
