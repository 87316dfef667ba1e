// AravisCamera: a GigE Vision or USB3 Vision camera through Aravis 0.8. Opens by device id
// (e.g. "Basler-21234567", an IP address, or "Aravis-Fake-GV01") or by serial number, sets
// exposure, gain and pixel format (Mono8, Mono12, Mono16), and captures one frame per
// software trigger (one per z step of a scan, thesis 5.2).
#pragma once

#include <memory>
#include <string>
#include <thread>

#include "devices/camera.h"
#include "devices/drivers/published_info.h"

namespace inspection {

struct AravisCameraOptions {
  std::string device_id;               // Aravis device id; empty: match `serial`, or the first camera found
  std::string serial;                  // serial number as Aravis reports it (arv-tool-0.8 lists both)
  std::string pixel_format = "Mono8";  // Mono8 -> CV_8UC1; Mono12 / Mono16 -> CV_16UC1
  double exposure_us = 10000.0;
  double gain_db = 0.0;              // written with arv_camera_set_gain (cameras with GainRaw take raw units)
  double frame_timeout_ms = 2000.0;  // trigger -> complete frame; DEADLINE_EXCEEDED after it
  int n_buffers = 4;
  int packet_size = 0;  // GigE packet size in bytes; 0 = negotiate (arv_camera_gv_auto_packet_size)
  // Sensor region of interest; width/height 0 keep the camera's current region.
  int region_x = 0;
  int region_y = 0;
  int region_width = 0;
  int region_height = 0;

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

// Bits that a pixel format name carries; INVALID_ARGUMENT for unsupported formats.
StatusOr<int> AravisPixelFormatBits(const std::string& pixel_format);

// Not thread-safe (the rig's job worker owns it), except info(), which any thread may call.
//
// Failure semantics: when the camera disappears (cable, power, the process serving it), the
// next Capture returns UNAVAILABLE (the trigger or a control read fails, or the frame does not
// arrive and the camera no longer answers its control channel); a frame that does not arrive
// while the camera still answers is DEADLINE_EXCEEDED. After UNAVAILABLE, info().connected is
// false until Connect() succeeds again. Detecting a vanished GigE camera takes one GVCP
// command timeout (~2.5 s with Aravis's 5 x 500 ms retries); releasing the dead handles
// (~10 s more) happens in the background and Connect() waits for it.
class AravisCamera : public Camera {
 public:
  explicit AravisCamera(AravisCameraOptions options);
  ~AravisCamera() override;

  Status Connect();  // (re)opens the camera and starts triggered acquisition

  DeviceInfo info() const override { return published_.Get(); }
  cv::Size frame_size() const override;
  int bit_depth() const override;
  Status SetExposure(double exposure_us) override;
  double exposure_us() const override { return options_.exposure_us; }
  Status SetGain(double gain_db) override;
  StatusOr<cv::Mat> Capture() override;

 private:
  struct Handles;
  void Disconnect(const std::string& reason);
  void Publish();
  DeviceInfo BuildInfo() const;
  struct Republish {
    AravisCamera* c;
    ~Republish() { c->Publish(); }
  };
  Status Lost(const std::string& what);

  AravisCameraOptions options_;
  std::unique_ptr<Handles> h_;
  std::thread reaper_;  // releases the handles of a lost camera
  std::string model_, serial_, device_id_;
  cv::Size size_;
  int bits_ = 8;
  std::string last_error_ = "not connected yet";
  PublishedInfo published_;
};

}  // namespace inspection
