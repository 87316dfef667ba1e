// Thorlabs APT message encoding and decoding (see apt_protocol.h).
#include "devices/drivers/apt_protocol.h"

#include <cstdio>

namespace inspection::apt {
namespace {

void PutU16(std::vector<uint8_t>& b, uint16_t v) {
  b.push_back(static_cast<uint8_t>(v & 0xFF));
  b.push_back(static_cast<uint8_t>(v >> 8));
}
void PutU32(std::vector<uint8_t>& b, uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<uint8_t>((v >> (8 * i)) & 0xFF));
}
uint16_t GetU16(const std::vector<uint8_t>& b, size_t at) { return static_cast<uint16_t>(b[at] | (b[at + 1] << 8)); }
uint32_t GetU32(const std::vector<uint8_t>& b, size_t at) {
  return static_cast<uint32_t>(b[at]) | (static_cast<uint32_t>(b[at + 1]) << 8) |
         (static_cast<uint32_t>(b[at + 2]) << 16) | (static_cast<uint32_t>(b[at + 3]) << 24);
}
std::string GetString(const std::vector<uint8_t>& b, size_t at, size_t n) {
  std::string s;
  for (size_t i = at; i < at + n && b[i] != 0; ++i) s.push_back(static_cast<char>(b[i]));
  return s;
}
Message Short(uint16_t id, uint8_t p1 = 0, uint8_t p2 = 0) {
  Message m;
  m.id = id;
  m.param1 = p1;
  m.param2 = p2;
  return m;
}
std::string Hex(uint16_t v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "0x%04X", v);
  return buf;
}

}  // namespace

std::vector<uint8_t> Encode(const Message& m) {
  std::vector<uint8_t> b;
  b.reserve(kHeaderBytes + m.data.size());
  PutU16(b, m.id);
  if (m.data.empty()) {
    b.push_back(m.param1);
    b.push_back(m.param2);
    b.push_back(m.dest);
  } else {
    PutU16(b, static_cast<uint16_t>(m.data.size()));
    b.push_back(static_cast<uint8_t>(m.dest | kDataFollowsFlag));
  }
  b.push_back(m.source);
  b.insert(b.end(), m.data.begin(), m.data.end());
  return b;
}

Message DecodeHeader(const uint8_t* h, int* data_length) {
  Message m;
  m.id = static_cast<uint16_t>(h[0] | (h[1] << 8));
  m.source = h[5];
  if (h[4] & kDataFollowsFlag) {
    m.dest = static_cast<uint8_t>(h[4] & ~kDataFollowsFlag);
    *data_length = h[2] | (h[3] << 8);
  } else {
    m.dest = h[4];
    m.param1 = h[2];
    m.param2 = h[3];
    *data_length = 0;
  }
  return m;
}

Message NoFlashProgramming() { return Short(kHwNoFlashProgramming); }
Message ReqHwInfo() { return Short(kHwReqInfo); }
Message Identify() { return Short(kModIdentify); }
Message EnableChannel(bool enable) { return Short(kModSetChanEnableState, kChannel1, enable ? 0x01 : 0x02); }
Message MoveHome() { return Short(kMotMoveHome, kChannel1); }
Message MoveStop(bool immediate) { return Short(kMotMoveStop, kChannel1, immediate ? 0x01 : 0x02); }
Message ReqPosCounter() { return Short(kMotReqPosCounter, kChannel1); }
Message ReqDcStatusUpdate() { return Short(kMotReqDcStatusUpdate, kChannel1); }
Message AckDcStatusUpdate() { return Short(kMotAckDcStatusUpdate); }

Message MoveAbsolute(int32_t position_counts) {
  Message m;
  m.id = kMotMoveAbsolute;
  PutU16(m.data, kChannel1);
  PutU32(m.data, static_cast<uint32_t>(position_counts));
  return m;
}

StatusOr<HwInfo> ParseHwInfo(const Message& m) {
  if (m.id != kHwGetInfo || m.data.size() < 84) {
    return Status::DataLoss("HW_GET_INFO: expected 84 data bytes, got " + std::to_string(m.data.size()));
  }
  HwInfo info;
  info.serial_number = GetU32(m.data, 0);
  info.model = GetString(m.data, 4, 8);
  info.hw_type = GetU16(m.data, 12);
  // Firmware: minor, interim, major, unused.
  info.firmware = std::to_string(m.data[16]) + "." + std::to_string(m.data[15]) + "." + std::to_string(m.data[14]);
  info.hw_version = GetU16(m.data, 78);
  info.n_channels = GetU16(m.data, 82);
  return info;
}

StatusOr<MotorStatus> ParseMotorStatus(const Message& m) {
  if (m.data.size() < 14) {
    return Status::DataLoss("APT message " + Hex(m.id) + ": expected 14 status bytes, got " +
                            std::to_string(m.data.size()));
  }
  MotorStatus s;
  s.channel = GetU16(m.data, 0);
  s.position_counts = static_cast<int32_t>(GetU32(m.data, 2));
  s.velocity = static_cast<int16_t>(GetU16(m.data, 6));
  s.status_bits = GetU32(m.data, 10);
  return s;
}

StatusOr<int32_t> ParsePosCounter(const Message& m) {
  if (m.id != kMotGetPosCounter || m.data.size() < 6) {
    return Status::DataLoss("GET_POSCOUNTER: expected 6 data bytes, got " + std::to_string(m.data.size()));
  }
  return static_cast<int32_t>(GetU32(m.data, 2));
}

std::string DescribeControllerError(const Message& m) {
  if (m.id == kHwRichResponse && m.data.size() >= 4) {
    return "controller error " + std::to_string(GetU16(m.data, 2)) + " on message " + Hex(GetU16(m.data, 0)) + ": " +
           GetString(m.data, 4, m.data.size() - 4);
  }
  return "controller reported an error (HW_RESPONSE)";
}

}  // namespace inspection::apt
