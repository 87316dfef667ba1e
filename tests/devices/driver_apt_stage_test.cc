// Thorlabs APT stage over the FTDI bridge: the exact control transfers and APT bytes on the
// wire, encoder counts <-> µm per stage type, timeouts, controller errors and unplugging,
// against a fake controller behind the UsbTransport seam.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <memory>

#include "devices/drivers/apt_stage.h"

namespace inspection {
namespace {

using Bytes = std::vector<uint8_t>;

struct ControlCall {
  uint8_t request;
  uint16_t value;
  uint16_t index;
  bool operator==(const ControlCall& o) const { return request == o.request && value == o.value && index == o.index; }
};

// Emulates a KDC101: answers APT requests, frames replies as FTDI bulk IN packets (two status
// bytes, then up to 62 payload bytes per 64-byte packet).
struct FakeController {
  std::vector<ControlCall> control;
  std::vector<Bytes> written;  // one entry per bulk OUT transfer
  std::deque<uint8_t> pending;
  bool silent_moves = false;  // MOVE_ABSOLUTE never completes
  bool unplugged = false;
  bool reject_moves = false;  // answer MOVE_ABSOLUTE with HW_RICHRESPONSE
  bool chatter = false;       // send an unsolicited status update before each reply
  int32_t position = 0;

  void Queue(const Bytes& b) { pending.insert(pending.end(), b.begin(), b.end()); }
  static Bytes Status14(int32_t pos, uint32_t bits) {
    Bytes d = {0x01, 0x00};
    for (int i = 0; i < 4; ++i) d.push_back(static_cast<uint8_t>((static_cast<uint32_t>(pos) >> (8 * i)) & 0xFF));
    d.insert(d.end(), {0, 0, 0, 0});
    for (int i = 0; i < 4; ++i) d.push_back(static_cast<uint8_t>((bits >> (8 * i)) & 0xFF));
    return d;
  }
  static Bytes Reply(uint16_t id, const Bytes& data) {
    Bytes b = {static_cast<uint8_t>(id & 0xFF),
               static_cast<uint8_t>(id >> 8),
               static_cast<uint8_t>(data.size()),
               0,
               0x81,
               0x50};
    b.insert(b.end(), data.begin(), data.end());
    return b;
  }
  void OnWrite(const Bytes& b) {
    written.push_back(b);
    const uint16_t id = static_cast<uint16_t>(b[0] | (b[1] << 8));
    if (chatter && id != apt::kMotAckDcStatusUpdate)
      Queue(Reply(apt::kMotGetDcStatusUpdate, Status14(position, 0x80000400)));
    switch (id) {
      case apt::kHwReqInfo: {
        Bytes d(84, 0);
        const uint32_t serial = 27000001;
        for (int i = 0; i < 4; ++i) d[i] = static_cast<uint8_t>((serial >> (8 * i)) & 0xFF);
        const char model[] = "KDC101";
        std::copy(model, model + 6, d.begin() + 4);
        d[12] = 16;  // hw type
        d[14] = 7;
        d[15] = 0;
        d[16] = 3;  // firmware minor, interim, major
        d[78] = 2;  // hw version
        d[82] = 1;  // channels
        Queue(Reply(apt::kHwGetInfo, d));
        break;
      }
      case apt::kMotMoveHome:
        position = 0;
        Queue({0x44, 0x04, 0x01, 0x00, 0x01, 0x50});
        break;
      case apt::kMotMoveAbsolute: {
        if (silent_moves) break;
        if (reject_moves) {
          Bytes d = {0x53, 0x04, 0x2A, 0x00};
          const char text[] = "Position outside soft limits";
          d.insert(d.end(), text, text + sizeof text - 1);
          d.resize(68, 0);
          Queue(Reply(apt::kHwRichResponse, d));
          break;
        }
        position = static_cast<int32_t>(b[8] | (b[9] << 8) | (b[10] << 16) | (static_cast<uint32_t>(b[11]) << 24));
        Queue(Reply(apt::kMotMoveCompleted, Status14(position, 0x80000400)));
        break;
      }
      case apt::kMotReqDcStatusUpdate:
        Queue(Reply(apt::kMotGetDcStatusUpdate, Status14(position, 0x80000400 | 0x10)));
        break;
      case apt::kMotReqPosCounter: {
        Bytes d = {0x01, 0x00};
        for (int i = 0; i < 4; ++i)
          d.push_back(static_cast<uint8_t>((static_cast<uint32_t>(position) >> (8 * i)) & 0xFF));
        Queue(Reply(apt::kMotGetPosCounter, d));
        break;
      }
      default:
        break;
    }
  }
};

class FakeTransport : public UsbTransport {
 public:
  explicit FakeTransport(std::shared_ptr<FakeController> c) : c_(std::move(c)) {}
  Status ControlOut(uint8_t request, uint16_t value, uint16_t index, int) override {
    if (c_->unplugged) return Status::Unavailable("control request: LIBUSB_ERROR_NO_DEVICE");
    c_->control.push_back({request, value, index});
    return Status::Ok();
  }
  Status BulkOut(const std::vector<uint8_t>& data, int) override {
    if (c_->unplugged) return Status::Unavailable("bulk write: LIBUSB_ERROR_NO_DEVICE");
    c_->OnWrite(data);
    return Status::Ok();
  }
  StatusOr<std::vector<uint8_t>> BulkIn(int) override {
    if (c_->unplugged) return Status::Unavailable("bulk read: LIBUSB_ERROR_NO_DEVICE");
    Bytes packet = {0x31, 0x60};  // modem status, line status
    while (!c_->pending.empty() && packet.size() < 64) {
      packet.push_back(c_->pending.front());
      c_->pending.pop_front();
    }
    return packet;
  }
  int max_packet_size() const override { return 64; }
  std::string description() const override { return "fake 0403:faf0"; }
  std::string serial() const override { return "27000001"; }

 private:
  std::shared_ptr<FakeController> c_;
};

AptStageOptions TestOptions(const std::string& type = "Z825") {
  AptStageOptions o;
  o.stage_type = type;
  o.max_z_um = 12000.0;
  o.settle_ms = 0.0;
  o.move_timeout_ms = 30.0;
  o.line.purge_dwell_ms = 0;
  return o;
}

class AptStageTest : public ::testing::Test {
 protected:
  std::unique_ptr<AptStage> Make(AptStageOptions o = TestOptions()) {
    auto c = controller_;
    return std::make_unique<AptStage>(o, [c]() -> StatusOr<std::unique_ptr<UsbTransport>> {
      return std::unique_ptr<UsbTransport>(new FakeTransport(c));
    });
  }
  std::shared_ptr<FakeController> controller_ = std::make_shared<FakeController>();
};

TEST(FtdiBaudDivisorTest, MatchesChipEncoding) {
  auto d = ftdi::EncodeBaudDivisor(115200);
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d->value, 0x001A);
  EXPECT_EQ(d->index, 0);
  d = ftdi::EncodeBaudDivisor(9600);  // 312.5 -> fraction 1/2 (code 1)
  EXPECT_EQ(d->value, 0x4138);
  d = ftdi::EncodeBaudDivisor(921600);  // 3.25 -> fraction 1/4 (code 2)
  EXPECT_EQ(d->value, 0x8003);
  EXPECT_EQ(ftdi::EncodeBaudDivisor(3000000)->value, 0);
  EXPECT_EQ(ftdi::EncodeBaudDivisor(2000000)->value, 1);
  d = ftdi::EncodeBaudDivisor(38400 * 8 / 7);  // 68.36 -> 68 + 3/8 (code 4 -> wIndex bit)
  EXPECT_EQ(d->value, 68);
  EXPECT_EQ(d->index, 1);
  EXPECT_EQ(ftdi::EncodeBaudDivisor(100).status().code(), StatusCode::kInvalidArgument);
}

TEST(AptProtocolTest, EncodesHeaderOnlyAndDataMessages) {
  EXPECT_EQ(apt::Encode(apt::MoveHome()), (Bytes{0x43, 0x04, 0x01, 0x00, 0x50, 0x01}));
  EXPECT_EQ(apt::Encode(apt::Identify()), (Bytes{0x23, 0x02, 0x00, 0x00, 0x50, 0x01}));
  EXPECT_EQ(apt::Encode(apt::MoveAbsolute(-2)),
            (Bytes{0x53, 0x04, 0x06, 0x00, 0xD0, 0x01, 0x01, 0x00, 0xFE, 0xFF, 0xFF, 0xFF}));
  int len = -1;
  const uint8_t header[] = {0x64, 0x04, 0x0E, 0x00, 0x81, 0x50};
  apt::Message m = apt::DecodeHeader(header, &len);
  EXPECT_EQ(m.id, apt::kMotMoveCompleted);
  EXPECT_EQ(len, 14);
  EXPECT_EQ(m.dest, 0x01);
  EXPECT_EQ(m.source, 0x50);
}

TEST_F(AptStageTest, ConnectSetsUpFtdiAndIdentifiesController) {
  AptStageOptions o = TestOptions();
  o.identify_on_connect = true;
  auto stage = Make(o);
  ASSERT_TRUE(stage->Connect().ok());
  // Reset, 115200 baud, 8N1, purge RX, purge TX, RTS/CTS flow control, RTS on.
  EXPECT_THAT(controller_->control,
              ::testing::ElementsAre(ControlCall{0x00, 0x0000, 0x0000}, ControlCall{0x03, 0x001A, 0x0000},
                                     ControlCall{0x04, 0x0008, 0x0000}, ControlCall{0x00, 0x0001, 0x0000},
                                     ControlCall{0x00, 0x0002, 0x0000}, ControlCall{0x02, 0x0000, 0x0100},
                                     ControlCall{0x01, 0x0202, 0x0000}));
  EXPECT_THAT(controller_->written,
              ::testing::ElementsAre(Bytes{0x18, 0x00, 0x00, 0x00, 0x50, 0x01},    // NO_FLASH_PROGRAMMING
                                     Bytes{0x05, 0x00, 0x00, 0x00, 0x50, 0x01},    // HW_REQ_INFO
                                     Bytes{0x10, 0x02, 0x01, 0x01, 0x50, 0x01},    // enable channel 1
                                     Bytes{0x23, 0x02, 0x00, 0x00, 0x50, 0x01}));  // MOD_IDENTIFY
  const DeviceInfo info = stage->info();
  EXPECT_TRUE(info.connected);
  EXPECT_EQ(info.driver, "apt-usb");
  EXPECT_EQ(info.model, "KDC101 + Z825");
  EXPECT_EQ(info.serial, "27000001");
  EXPECT_EQ(stage->hw_info().firmware, "3.0.7");
  EXPECT_EQ(stage->hw_info().n_channels, 1);
}

TEST_F(AptStageTest, MoveAbsoluteSendsEncoderCountsAndAcknowledgesCompletion) {
  auto stage = Make();
  ASSERT_TRUE(stage->Connect().ok());
  controller_->written.clear();
  ASSERT_TRUE(stage->MoveTo(1000.0).ok());
  // Z8 series: 34554.96 counts/mm -> 1000 µm = 34555 counts = 0x000086FB.
  EXPECT_THAT(controller_->written,
              ::testing::ElementsAre(Bytes{0x53, 0x04, 0x06, 0x00, 0xD0, 0x01, 0x01, 0x00, 0xFB, 0x86, 0x00, 0x00},
                                     Bytes{0x92, 0x04, 0x00, 0x00, 0x50, 0x01}));  // ACK_DCSTATUSUPDATE
  controller_->written.clear();
  StatusOr<double> z = stage->position_um();
  ASSERT_TRUE(z.ok()) << z.status().ToString();
  EXPECT_THAT(controller_->written, ::testing::ElementsAre(Bytes{0x11, 0x04, 0x01, 0x00, 0x50, 0x01}));
  EXPECT_NEAR(*z, 34555 * 1000.0 / 34554.96, 1e-9);
}

TEST_F(AptStageTest, StatusRequestReportsBitsAndIsAcknowledged) {
  auto stage = Make();
  ASSERT_TRUE(stage->Connect().ok());
  ASSERT_TRUE(stage->MoveTo(250.0).ok());
  EXPECT_FALSE(stage->homed());
  controller_->written.clear();
  StatusOr<apt::MotorStatus> st = stage->QueryStatus();
  ASSERT_TRUE(st.ok()) << st.status().ToString();
  EXPECT_THAT(controller_->written,
              ::testing::ElementsAre(Bytes{0x90, 0x04, 0x01, 0x00, 0x50, 0x01},    // REQ_DCSTATUSUPDATE
                                     Bytes{0x92, 0x04, 0x00, 0x00, 0x50, 0x01}));  // ACK
  EXPECT_EQ(st->channel, 1);
  EXPECT_EQ(st->position_counts, stage->CountsFromUm(250.0));
  EXPECT_EQ(st->status_bits, 0x80000410u);  // enabled, homed, moving forward
  EXPECT_TRUE(stage->homed());
}

TEST_F(AptStageTest, MtsStageUsesItsOwnScale) {
  auto stage = Make(TestOptions("MTS50-Z8"));
  ASSERT_TRUE(stage->Connect().ok());
  EXPECT_EQ(stage->CountsFromUm(1000.0), 34304);
  EXPECT_EQ(stage->CountsFromUm(2.5), 86);  // 85.76 rounds up
  EXPECT_DOUBLE_EQ(stage->UmFromCounts(34304), 1000.0);
  controller_->written.clear();
  ASSERT_TRUE(stage->MoveTo(1000.0).ok());
  EXPECT_EQ(controller_->written.at(0),
            (Bytes{0x53, 0x04, 0x06, 0x00, 0xD0, 0x01, 0x01, 0x00, 0x00, 0x86, 0x00, 0x00}));
}

TEST_F(AptStageTest, HomeWaitsForHomedAndSkipsUnsolicitedStatus) {
  controller_->chatter = true;
  auto stage = Make();
  ASSERT_TRUE(stage->Connect().ok());
  controller_->written.clear();
  controller_->pending.clear();  // drop the chatter provoked by the enable request
  ASSERT_TRUE(stage->Home().ok());
  EXPECT_TRUE(stage->homed());
  ASSERT_GE(controller_->written.size(), 2u);
  EXPECT_EQ(controller_->written[0], (Bytes{0x43, 0x04, 0x01, 0x00, 0x50, 0x01}));
  // Both the unsolicited status update and MOVE_HOMED were acknowledged.
  EXPECT_EQ(
      std::count(controller_->written.begin(), controller_->written.end(), Bytes{0x92, 0x04, 0x00, 0x00, 0x50, 0x01}),
      2);
}

TEST_F(AptStageTest, TravelLimitsRejectMovesWithoutTouchingTheBus) {
  auto stage = Make();
  ASSERT_TRUE(stage->Connect().ok());
  controller_->written.clear();
  EXPECT_EQ(stage->MoveTo(12000.5).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(stage->MoveTo(-1.0).code(), StatusCode::kOutOfRange);
  EXPECT_TRUE(controller_->written.empty());
}

TEST_F(AptStageTest, MoveTimeoutIsDeadlineExceededAndStopsTheMotor) {
  controller_->silent_moves = true;
  auto stage = Make();
  ASSERT_TRUE(stage->Connect().ok());
  controller_->written.clear();
  Status s = stage->MoveTo(500.0);
  EXPECT_EQ(s.code(), StatusCode::kDeadlineExceeded) << s.ToString();
  EXPECT_THAT(s.message(), ::testing::HasSubstr("MOVE_COMPLETED"));
  ASSERT_EQ(controller_->written.size(), 2u);
  EXPECT_EQ(controller_->written[1], (Bytes{0x65, 0x04, 0x01, 0x02, 0x50, 0x01}));  // profiled MOVE_STOP
  EXPECT_TRUE(stage->info().connected);  // a slow stage is not a missing stage
}

TEST_F(AptStageTest, ControllerErrorIsAbortedWithItsText) {
  controller_->reject_moves = true;
  auto stage = Make();
  ASSERT_TRUE(stage->Connect().ok());
  Status s = stage->MoveTo(100.0);
  EXPECT_EQ(s.code(), StatusCode::kAborted);
  EXPECT_THAT(s.message(), ::testing::HasSubstr("Position outside soft limits"));
}

TEST_F(AptStageTest, UnplugIsUnavailableAndConnectRecovers) {
  auto stage = Make();
  ASSERT_TRUE(stage->Connect().ok());
  controller_->unplugged = true;
  Status s = stage->MoveTo(100.0);
  EXPECT_EQ(s.code(), StatusCode::kUnavailable);
  EXPECT_FALSE(stage->info().connected);
  EXPECT_THAT(stage->info().detail, ::testing::HasSubstr("NO_DEVICE"));
  EXPECT_EQ(stage->position_um().status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(stage->Connect().code(), StatusCode::kUnavailable);
  controller_->unplugged = false;  // plugged back in
  ASSERT_TRUE(stage->Connect().ok());
  EXPECT_TRUE(stage->MoveTo(100.0).ok());
}

TEST_F(AptStageTest, AbsentDeviceIsUnavailableNamingIt) {
  AptStage stage(TestOptions(), []() -> StatusOr<std::unique_ptr<UsbTransport>> {
    return Status::Unavailable("USB device 0403:faf0 serial 27000001 not found");
  });
  Status s = stage.Connect();
  EXPECT_EQ(s.code(), StatusCode::kUnavailable);
  EXPECT_THAT(s.message(), ::testing::HasSubstr("27000001"));
  EXPECT_FALSE(stage.info().connected);
  EXPECT_EQ(stage.MoveTo(10.0).code(), StatusCode::kUnavailable);
}

TEST(AptStageOptionsTest, ValidateNamesTheField) {
  AptStageOptions o;
  o.stage_type = "Z806";
  o.max_z_um = 7000.0;  // beyond 6 mm travel
  EXPECT_THAT(o.Validate().message(), ::testing::HasSubstr("travel"));
  o.stage_type = "Z999";
  EXPECT_THAT(o.Validate().message(), ::testing::HasSubstr("stage_type"));
}

}  // namespace
}  // namespace inspection
