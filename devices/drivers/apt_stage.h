// AptStage: a Thorlabs single-channel motor controller (KDC101, TDC001, KST101) driving a
// Z8-series actuator or an MTS translation stage along the optical axis, via the APT protocol
// over the controller's FTDI USB bridge. Converts encoder counts <-> µm from the stage type.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "devices/drivers/apt_protocol.h"
#include "devices/drivers/ftdi_serial.h"
#include "devices/drivers/published_info.h"
#include "devices/drivers/usb_transport.h"
#include "devices/stage.h"

namespace inspection {

// Encoder resolution and travel of the supported stage types.
struct AptStageType {
  std::string name;
  double counts_per_mm = 0.0;
  double travel_mm = 0.0;
};
// "Z806", "Z812", "Z825" (Z8 series DC servo actuators, 34554.96 counts/mm),
// "MTS25-Z8", "MTS50-Z8" (34304 counts/mm). NOT_FOUND lists the known names.
StatusOr<AptStageType> LookupAptStageType(const std::string& name);

struct AptStageOptions {
  std::string stage_type = "Z825";
  double counts_per_mm = 0.0;  // > 0 overrides the stage type's scale
  double min_z_um = 0.0;       // travel limits enforced before any move; within the stage travel
  double max_z_um = 25000.0;
  double move_timeout_ms = 10000.0;  // MOVE_COMPLETED must arrive within this
  double home_timeout_ms = 60000.0;  // MOVE_HOMED must arrive within this
  double settle_ms = 50.0;           // wait after MOVE_COMPLETED before the exposure may start
  bool home_on_connect = false;
  bool identify_on_connect = false;  // flash the controller's LED (MOD_IDENTIFY)
  FtdiLineSettings line;

  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

// Not thread-safe, except info(), which any thread may call. Survives unplugging: operations return UNAVAILABLE until
// Connect() succeeds.
class AptStage : public Stage {
 public:
  AptStage(AptStageOptions options, UsbTransportFactory open_transport);
  ~AptStage() override;

  // Opens the transport, configures the FTDI bridge, reads HW info, enables the channel.
  Status Connect();

  DeviceInfo info() const override { return published_.Get(); }
  double min_z_um() const override { return options_.min_z_um; }
  double max_z_um() const override { return options_.max_z_um; }
  Status Home() override;
  Status MoveTo(double z_um) override;
  StatusOr<double> position_um() override;
  // Status bits and position as the controller reports them (REQ/GET_DCSTATUSUPDATE; DC servo
  // controllers KDC101/TDC001).
  StatusOr<apt::MotorStatus> QueryStatus();

  int32_t CountsFromUm(double z_um) const;
  double UmFromCounts(int32_t counts) const;
  const apt::HwInfo& hw_info() const { return hw_info_; }
  bool homed() const { return homed_; }

 private:
  Status Send(const apt::Message& m);
  // Reads messages until one with `id` arrives; answers status updates with the "server alive"
  // ack, turns controller errors into ABORTED and silence into DEADLINE_EXCEEDED.
  StatusOr<apt::Message> WaitFor(uint16_t id, double timeout_ms, const std::string& what);
  StatusOr<apt::Message> ReadMessage(std::chrono::steady_clock::time_point deadline);
  Status Fail(Status s);  // marks the stage disconnected when s is UNAVAILABLE
  Status CheckConnected() const;
  DeviceInfo BuildInfo() const;
  struct Republish {
    AptStage* s;
    ~Republish() { s->published_.Set(s->BuildInfo()); }
  };

  AptStageOptions options_;
  double counts_per_mm_ = 0.0;
  UsbTransportFactory open_transport_;
  std::unique_ptr<UsbTransport> transport_;
  std::unique_ptr<FtdiSerial> serial_;
  apt::HwInfo hw_info_;
  bool connected_ = false;
  bool homed_ = false;
  std::string last_error_;
  std::optional<int32_t> last_position_counts_;
  PublishedInfo published_;
};

}  // namespace inspection
