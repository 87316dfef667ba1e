// The APT stage through real libusb against a replayed KDC101 (umockdev): enumeration by
// vendor/product id and serial, FTDI control transfers and APT bulk traffic as recorded in
// data/kdc101_move.ioctl. Runs only under umockdev-run (ctest does that); not sanitised, since
// umockdev's LD_PRELOAD and ASan do not mix.
#include <gtest/gtest.h>

#include <cstdlib>

#include "devices/drivers/apt_stage.h"
#include "devices/drivers/libusb_transport.h"
#include "tests/lib/skip_or_fail.h"

namespace inspection {
namespace {

bool UnderUmockdev() { return std::getenv("UMOCKDEV_DIR") != nullptr; }

TEST(AptUmockdevTest, WrongSerialIsUnavailable) {
  if (!UnderUmockdev()) INSPECT_SKIP_OR_FAIL() << "run under umockdev-run (see tests/drivers/CMakeLists.txt)";
  UsbDeviceSelector sel;
  sel.serial = "12345678";
  StatusOr<std::unique_ptr<UsbTransport>> t = OpenLibusbTransport(sel);
  EXPECT_EQ(t.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(t.status().message().find("serial 12345678 not found"), std::string::npos) << t.status().ToString();
}

TEST(AptUmockdevTest, ConnectMoveAndReadPositionThroughLibusb) {
  if (!UnderUmockdev()) INSPECT_SKIP_OR_FAIL() << "run under umockdev-run (see tests/drivers/CMakeLists.txt)";
  UsbDeviceSelector sel;
  sel.serial = "27000001";
  AptStageOptions o;
  o.stage_type = "MTS25-Z8";
  o.settle_ms = 0.0;
  o.line.purge_dwell_ms = 0;
  AptStage stage(o, [sel] { return OpenLibusbTransport(sel); });
  Status connected = stage.Connect();
  ASSERT_TRUE(connected.ok()) << connected.ToString();
  const DeviceInfo info = stage.info();
  EXPECT_TRUE(info.connected);
  EXPECT_EQ(info.model, "KDC101 + MTS25-Z8");
  EXPECT_EQ(info.serial, "27000001");
  EXPECT_NE(info.detail.find("0403:faf0"), std::string::npos) << info.detail;
  EXPECT_EQ(stage.hw_info().firmware, "3.0.7");

  Status moved = stage.MoveTo(1000.0);  // 34304 counts on the wire
  ASSERT_TRUE(moved.ok()) << moved.ToString();
  StatusOr<double> z = stage.position_um();
  ASSERT_TRUE(z.ok()) << z.status().ToString();
  EXPECT_DOUBLE_EQ(*z, 1000.0);
}

}  // namespace
}  // namespace inspection
