// FtdiSerial: a UART behind an FTDI USB bridge (FT232BM/FT232R, as inside Thorlabs KDC101,
// TDC001 and KST101 controllers), driven with FTDI's vendor "SIO" control requests over a
// UsbTransport. Strips the two modem-status bytes FTDI prepends to every bulk IN packet.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <vector>

#include "core/util/status.h"
#include "devices/drivers/usb_transport.h"

namespace inspection {

// FTDI SIO request codes (bRequest of the vendor control transfer).
namespace ftdi {
inline constexpr uint8_t kSioReset = 0x00;         // wValue: 0 reset, 1 purge RX, 2 purge TX
inline constexpr uint8_t kSioSetModemCtrl = 0x01;  // wValue: (mask << 8) | state; DTR bit 0, RTS bit 1
inline constexpr uint8_t kSioSetFlowCtrl = 0x02;   // wIndex: (mode << 8) | interface
inline constexpr uint8_t kSioSetBaudRate = 0x03;   // wValue/wIndex: encoded divisor
inline constexpr uint8_t kSioSetData = 0x04;       // wValue: bits | parity << 8 | stop << 11
inline constexpr uint8_t kSioSetLatencyTimer = 0x09;
inline constexpr uint16_t kResetSio = 0;
inline constexpr uint16_t kPurgeRx = 1;
inline constexpr uint16_t kPurgeTx = 2;
inline constexpr uint16_t kFlowRtsCts = 0x0100;  // mode byte 0x01, in the high byte of wIndex
inline constexpr uint16_t kSetRtsHigh = 0x0202;
inline constexpr int kModemStatusBytes = 2;  // at the start of every bulk IN packet

struct BaudDivisor {
  uint16_t value = 0;
  uint16_t index = 0;
};
// Divisor of the 3 MHz UART clock of FT232BM/FT232R in 1/8 steps, encoded as the chips expect
// (integer part in bits 0-13, fraction code in bits 14-15 of wValue and bit 0 of wIndex).
// INVALID_ARGUMENT outside 183 .. 3000000 baud.
StatusOr<BaudDivisor> EncodeBaudDivisor(int baud);
}  // namespace ftdi

struct FtdiLineSettings {
  int baud = 115200;  // Thorlabs APT: 115200 baud, 8 data bits, 1 stop bit, no parity
  bool rts_cts_flow_control = true;
  int interface_index = 0;  // 0 on single-port chips (FT232)
  int purge_dwell_ms = 50;  // Thorlabs: pause before and after purging; 0 in tests
  int control_timeout_ms = 1000;
};

// Not thread-safe. Does not own the transport.
class FtdiSerial {
 public:
  explicit FtdiSerial(UsbTransport* transport) : transport_(transport) {}

  // Reset, baud rate, 8N1, purge, flow control, RTS: the Thorlabs-recommended bring-up order.
  Status Configure(const FtdiLineSettings& settings);
  Status Write(const std::vector<uint8_t>& bytes, int timeout_ms);
  // Exactly n payload bytes or DEADLINE_EXCEEDED at the deadline (buffered bytes stay buffered).
  StatusOr<std::vector<uint8_t>> Read(size_t n, std::chrono::steady_clock::time_point deadline);

 private:
  UsbTransport* transport_;
  std::deque<uint8_t> rx_;
};

}  // namespace inspection
