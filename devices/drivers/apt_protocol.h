// Thorlabs APT host-controller protocol: message framing and the messages a z stage needs
// (identify, hardware info, enable, home, absolute move, position and status). Pure byte
// encoding/decoding; transport in ftdi_serial.h, behaviour in apt_stage.h.
//
// Frame: 6-byte header, little endian. Without data: id(2) param1 param2 dest source.
// With data: id(2) length(2) (dest | 0x80) source, followed by `length` bytes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection::apt {

inline constexpr uint8_t kHostAddress = 0x01;        // the PC
inline constexpr uint8_t kGenericUsbAddress = 0x50;  // single-channel USB controller (KDC101, TDC001, KST101)
inline constexpr uint8_t kDataFollowsFlag = 0x80;
inline constexpr int kHeaderBytes = 6;
inline constexpr uint8_t kChannel1 = 0x01;

enum MessageId : uint16_t {
  kHwReqInfo = 0x0005,
  kHwGetInfo = 0x0006,
  kHwNoFlashProgramming = 0x0018,
  kHwResponse = 0x0080,      // controller error, no data
  kHwRichResponse = 0x0081,  // controller error with text
  kModSetChanEnableState = 0x0210,
  kModIdentify = 0x0223,
  kMotReqPosCounter = 0x0411,
  kMotGetPosCounter = 0x0412,
  kMotMoveHome = 0x0443,
  kMotMoveHomed = 0x0444,
  kMotMoveAbsolute = 0x0453,
  kMotMoveCompleted = 0x0464,
  kMotMoveStop = 0x0465,
  kMotMoveStopped = 0x0466,
  kMotReqDcStatusUpdate = 0x0490,
  kMotGetDcStatusUpdate = 0x0491,
  kMotAckDcStatusUpdate = 0x0492,  // "server alive", expected after status updates
};

// Status bits of the DC status update (MOVE_COMPLETED, MOVE_HOMED payloads, GET_DCSTATUSUPDATE).
inline constexpr uint32_t kStatusCwHardLimit = 0x00000001;
inline constexpr uint32_t kStatusCcwHardLimit = 0x00000002;
inline constexpr uint32_t kStatusMovingCw = 0x00000010;
inline constexpr uint32_t kStatusMovingCcw = 0x00000020;
inline constexpr uint32_t kStatusHoming = 0x00000200;
inline constexpr uint32_t kStatusHomed = 0x00000400;
inline constexpr uint32_t kStatusChannelEnabled = 0x80000000;

struct Message {
  uint16_t id = 0;
  uint8_t param1 = 0;  // header-only messages
  uint8_t param2 = 0;
  uint8_t dest = kGenericUsbAddress;
  uint8_t source = kHostAddress;
  std::vector<uint8_t> data;  // non-empty: a data packet follows the header
};

std::vector<uint8_t> Encode(const Message& m);

// Parses a 6-byte header; returns the message with data left empty, and sets data_length to
// the number of bytes that follow (0 for header-only messages).
Message DecodeHeader(const uint8_t* header, int* data_length);

// Requests (host -> controller).
Message NoFlashProgramming();
Message ReqHwInfo();
Message Identify();
Message EnableChannel(bool enable);
Message MoveHome();
Message MoveAbsolute(int32_t position_counts);
Message MoveStop(bool immediate);
Message ReqPosCounter();
Message ReqDcStatusUpdate();
Message AckDcStatusUpdate();

struct HwInfo {
  uint32_t serial_number = 0;
  std::string model;  // e.g. "KDC101"
  uint16_t hw_type = 0;
  std::string firmware;  // "major.interim.minor"
  uint16_t hw_version = 0;
  uint16_t n_channels = 0;
};
StatusOr<HwInfo> ParseHwInfo(const Message& m);  // HW_GET_INFO, 84 data bytes

// DC status update payload (14 bytes): MOVE_COMPLETED, MOVE_STOPPED, GET_DCSTATUSUPDATE.
struct MotorStatus {
  uint16_t channel = 0;
  int32_t position_counts = 0;
  int16_t velocity = 0;
  uint32_t status_bits = 0;
};
StatusOr<MotorStatus> ParseMotorStatus(const Message& m);
StatusOr<int32_t> ParsePosCounter(const Message& m);  // GET_POSCOUNTER, 6 data bytes
// HW_RESPONSE / HW_RICHRESPONSE as readable text.
std::string DescribeControllerError(const Message& m);

}  // namespace inspection::apt
