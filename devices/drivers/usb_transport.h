// UsbTransport: the seam between the FTDI/APT stage driver and the USB stack. The production
// implementation goes through libusb (libusb_transport.h); protocol tests record the exact
// control and bulk transfers against a fake (tests/devices/driver_apt_stage_test.cc).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

// One claimed USB interface with one bulk IN and one bulk OUT endpoint. Not thread-safe.
// Error mapping for every call: UNAVAILABLE when the device is gone or the transfer failed,
// DEADLINE_EXCEEDED when it timed out.
class UsbTransport {
 public:
  virtual ~UsbTransport() = default;

  // Vendor request, host to device, recipient device, no data stage (bmRequestType 0x40).
  virtual Status ControlOut(uint8_t request, uint16_t value, uint16_t index, int timeout_ms) = 0;
  virtual Status BulkOut(const std::vector<uint8_t>& data, int timeout_ms) = 0;
  // One bulk IN transfer of exactly max_packet_size() requested bytes; returns what arrived.
  virtual StatusOr<std::vector<uint8_t>> BulkIn(int timeout_ms) = 0;
  // wMaxPacketSize of the bulk IN endpoint (64 on full-speed FTDI bridges).
  virtual int max_packet_size() const = 0;
  // e.g. "usb 001/004 0403:faf0 serial 83812345".
  virtual std::string description() const = 0;
  // USB serial number string; empty when unknown.
  virtual std::string serial() const = 0;
};

// Opens a transport; called again by the stage on reconnect.
using UsbTransportFactory = std::function<StatusOr<std::unique_ptr<UsbTransport>>()>;

}  // namespace inspection
