// FTDI SIO set-up and the modem-status framing of bulk IN packets (see ftdi_serial.h).
#include "devices/drivers/ftdi_serial.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <thread>

namespace inspection {
namespace ftdi {

StatusOr<BaudDivisor> EncodeBaudDivisor(int baud) {
  if (baud < 183 || baud > 3000000) {
    return Status::InvalidArgument("baud rate " + std::to_string(baud) + " outside 183..3000000");
  }
  // Divisor in eighths of the 3 MHz clock, rounded to nearest.
  const long eighths = std::lround(3000000.0 * 8.0 / baud);
  long integer = eighths / 8;
  int fraction = static_cast<int>(eighths % 8);
  // Chip encoding of the fraction (in eighths) 0..7 -> code 0..7.
  static constexpr int kFractionCode[8] = {0, 3, 2, 4, 1, 5, 6, 7};
  uint32_t encoded;
  if (integer == 1 && fraction == 0) {
    encoded = 0;  // 3 Mbaud
  } else if (integer == 1 && fraction == 4) {
    encoded = 1;  // 2 Mbaud
  } else {
    if (integer > 0x3FFF) return Status::InvalidArgument("baud rate " + std::to_string(baud) + " too low");
    encoded = static_cast<uint32_t>(integer) | (static_cast<uint32_t>(kFractionCode[fraction]) << 14);
  }
  return BaudDivisor{static_cast<uint16_t>(encoded & 0xFFFF), static_cast<uint16_t>(encoded >> 16)};
}

}  // namespace ftdi

Status FtdiSerial::Configure(const FtdiLineSettings& s) {
  const int t = s.control_timeout_ms;
  const auto iface = static_cast<uint16_t>(s.interface_index);
  INSPECT_ASSIGN_OR_RETURN(ftdi::BaudDivisor divisor, ftdi::EncodeBaudDivisor(s.baud));
  INSPECT_RETURN_IF_ERROR(transport_->ControlOut(ftdi::kSioReset, ftdi::kResetSio, iface, t).WithContext("FTDI reset"));
  INSPECT_RETURN_IF_ERROR(
      transport_
          ->ControlOut(ftdi::kSioSetBaudRate, divisor.value,
                       // Single-port chips take divisor bit 16 in wIndex; multi-port chips move it to the high
                       // byte and put the port number in the low byte.
                       iface == 0 ? divisor.index : static_cast<uint16_t>((divisor.index << 8) | iface), t)
          .WithContext("FTDI baud rate"));
  // 8 data bits, no parity (0 << 8), 1 stop bit (0 << 11).
  INSPECT_RETURN_IF_ERROR(
      transport_->ControlOut(ftdi::kSioSetData, 0x0008, iface, t).WithContext("FTDI line properties"));
  if (s.purge_dwell_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(s.purge_dwell_ms));
  INSPECT_RETURN_IF_ERROR(
      transport_->ControlOut(ftdi::kSioReset, ftdi::kPurgeRx, iface, t).WithContext("FTDI purge RX"));
  INSPECT_RETURN_IF_ERROR(
      transport_->ControlOut(ftdi::kSioReset, ftdi::kPurgeTx, iface, t).WithContext("FTDI purge TX"));
  if (s.purge_dwell_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(s.purge_dwell_ms));
  const uint16_t flow = s.rts_cts_flow_control ? ftdi::kFlowRtsCts : 0;
  INSPECT_RETURN_IF_ERROR(transport_->ControlOut(ftdi::kSioSetFlowCtrl, 0, static_cast<uint16_t>(flow | iface), t)
                              .WithContext("FTDI flow control"));
  INSPECT_RETURN_IF_ERROR(
      transport_->ControlOut(ftdi::kSioSetModemCtrl, ftdi::kSetRtsHigh, iface, t).WithContext("FTDI RTS"));
  rx_.clear();
  return Status::Ok();
}

Status FtdiSerial::Write(const std::vector<uint8_t>& bytes, int timeout_ms) {
  return transport_->BulkOut(bytes, timeout_ms);
}

StatusOr<std::vector<uint8_t>> FtdiSerial::Read(size_t n, std::chrono::steady_clock::time_point deadline) {
  const size_t packet = static_cast<size_t>(std::max(transport_->max_packet_size(), ftdi::kModemStatusBytes + 1));
  while (rx_.size() < n) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      return Status::DeadlineExceeded("no reply from the controller: " + std::to_string(rx_.size()) + " of " +
                                      std::to_string(n) + " bytes received");
    }
    StatusOr<std::vector<uint8_t>> chunk = transport_->BulkIn(static_cast<int>(std::max<long>(1, left.count())));
    if (!chunk.ok()) {
      if (chunk.status().code() == StatusCode::kDeadlineExceeded) continue;  // re-check our own deadline
      return chunk.status();
    }
    // Every max-packet-size slice of the transfer starts with two modem-status bytes.
    const std::vector<uint8_t>& raw = *chunk;
    for (size_t off = 0; off < raw.size(); off += packet) {
      const size_t end = std::min(raw.size(), off + packet);
      for (size_t i = off + ftdi::kModemStatusBytes; i < end; ++i) rx_.push_back(raw[i]);
    }
  }
  std::vector<uint8_t> out(rx_.begin(), rx_.begin() + static_cast<long>(n));
  rx_.erase(rx_.begin(), rx_.begin() + static_cast<long>(n));
  return out;
}

}  // namespace inspection
