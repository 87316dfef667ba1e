// LibusbTransport: UsbTransport over libusb-1.0 for an FTDI bridge found by vendor/product id
// and optionally by USB serial number. Needs write access to /dev/bus/usb/BBB/DDD (udev rule
// in deploy/udev/) and detaches the kernel's ftdi_sio driver from the interface while open.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "devices/drivers/usb_transport.h"

namespace inspection {

struct UsbDeviceSelector {
  uint16_t vendor_id = 0x0403;   // FTDI
  uint16_t product_id = 0xFAF0;  // Thorlabs APT controllers (KDC101, TDC001, KST101)
  std::string serial;            // empty: the first matching device
  int interface_number = 0;
};

// NOT_FOUND-free by design: an absent device is UNAVAILABLE naming the selector, so the rig
// can start degraded and reconnect later.
StatusOr<std::unique_ptr<UsbTransport>> OpenLibusbTransport(const UsbDeviceSelector& selector);

}  // namespace inspection
