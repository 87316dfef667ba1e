// libusb-1.0 implementation of UsbTransport (see libusb_transport.h).
#include "devices/drivers/libusb_transport.h"

#include <libusb.h>

#include <cstdio>
#include <fstream>
#include <string>

namespace inspection {
namespace {

Status FromLibusb(int rc, const std::string& what) {
  const std::string msg = what + ": " + libusb_error_name(rc);
  if (rc == LIBUSB_ERROR_TIMEOUT) return Status::DeadlineExceeded(msg);
  if (rc == LIBUSB_ERROR_ACCESS)
    return Status::Unavailable(msg + " (no permission: install deploy/udev/70-inspection-devices.rules)");
  return Status::Unavailable(msg);
}

std::string Hex4(uint16_t v) {
  char b[8];
  std::snprintf(b, sizeof b, "%04x", v);
  return b;
}

// The kernel's copy of the serial string: /sys/bus/usb/devices/<bus>-<port>.<port>/serial.
// Avoids a GET_DESCRIPTOR control transfer, so it also works on devices that are busy.
std::string SysfsSerial(libusb_device* dev) {
  uint8_t ports[8];
  const int n = libusb_get_port_numbers(dev, ports, 8);
  if (n <= 0) return "";
  std::string path = "/sys/bus/usb/devices/" + std::to_string(libusb_get_bus_number(dev)) + "-";
  for (int i = 0; i < n; ++i) path += (i ? "." : "") + std::to_string(ports[i]);
  std::ifstream f(path + "/serial");
  std::string s;
  std::getline(f, s);
  return s;
}

class LibusbTransport : public UsbTransport {
 public:
  LibusbTransport(libusb_context* ctx, libusb_device_handle* h, int iface, uint8_t ep_in, uint8_t ep_out,
                  int max_packet, std::string desc, std::string serial)
      : ctx_(ctx),
        h_(h),
        iface_(iface),
        ep_in_(ep_in),
        ep_out_(ep_out),
        max_packet_(max_packet),
        desc_(std::move(desc)),
        serial_(std::move(serial)) {}
  ~LibusbTransport() override {
    libusb_release_interface(h_, iface_);
    libusb_close(h_);
    libusb_exit(ctx_);
  }

  Status ControlOut(uint8_t request, uint16_t value, uint16_t index, int timeout_ms) override {
    const int rc = libusb_control_transfer(h_, static_cast<uint8_t>(0x40) /* OUT | VENDOR | DEVICE */, request, value,
                                           index, nullptr, 0, static_cast<unsigned>(timeout_ms));
    if (rc < 0) return FromLibusb(rc, "control request " + std::to_string(request));
    return Status::Ok();
  }

  Status BulkOut(const std::vector<uint8_t>& data, int timeout_ms) override {
    int sent = 0;
    std::vector<uint8_t> copy = data;  // libusb takes a non-const buffer
    const int rc = libusb_bulk_transfer(h_, ep_out_, copy.data(), static_cast<int>(copy.size()), &sent,
                                        static_cast<unsigned>(timeout_ms));
    if (rc < 0) return FromLibusb(rc, "bulk write");
    if (sent != static_cast<int>(data.size())) {
      return Status::Unavailable("bulk write: " + std::to_string(sent) + " of " + std::to_string(data.size()) +
                                 " bytes sent");
    }
    return Status::Ok();
  }

  StatusOr<std::vector<uint8_t>> BulkIn(int timeout_ms) override {
    std::vector<uint8_t> buf(static_cast<size_t>(max_packet_));
    int got = 0;
    const int rc = libusb_bulk_transfer(h_, ep_in_, buf.data(), max_packet_, &got, static_cast<unsigned>(timeout_ms));
    if (rc < 0 && !(rc == LIBUSB_ERROR_TIMEOUT && got > 0)) return FromLibusb(rc, "bulk read");
    buf.resize(static_cast<size_t>(got));
    return buf;
  }

  int max_packet_size() const override { return max_packet_; }
  std::string description() const override { return desc_; }
  std::string serial() const override { return serial_; }

 private:
  libusb_context* ctx_;
  libusb_device_handle* h_;
  int iface_;
  uint8_t ep_in_, ep_out_;
  int max_packet_;
  std::string desc_, serial_;
};

}  // namespace

StatusOr<std::unique_ptr<UsbTransport>> OpenLibusbTransport(const UsbDeviceSelector& sel) {
  const std::string what = "USB device " + Hex4(sel.vendor_id) + ":" + Hex4(sel.product_id) +
                           (sel.serial.empty() ? "" : " serial " + sel.serial);
  libusb_context* ctx = nullptr;
  if (int rc = libusb_init(&ctx); rc < 0) return FromLibusb(rc, "libusb_init");
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(ctx, &list);
  if (n < 0) {
    libusb_exit(ctx);
    return FromLibusb(static_cast<int>(n), "listing USB devices");
  }
  libusb_device_handle* h = nullptr;
  libusb_device* found = nullptr;
  std::string serial;
  Status last_error = Status::Unavailable(what + " not found (is it plugged in and powered?)");
  for (ssize_t i = 0; i < n && h == nullptr; ++i) {
    libusb_device_descriptor dd{};
    if (libusb_get_device_descriptor(list[i], &dd) != 0) continue;
    if (dd.idVendor != sel.vendor_id || dd.idProduct != sel.product_id) continue;
    std::string s = SysfsSerial(list[i]);
    libusb_device_handle* candidate = nullptr;
    if (int rc = libusb_open(list[i], &candidate); rc < 0) {
      last_error = FromLibusb(rc, "opening " + what);
      continue;
    }
    if (s.empty() && dd.iSerialNumber != 0) {
      unsigned char buf[128];
      const int len = libusb_get_string_descriptor_ascii(candidate, dd.iSerialNumber, buf, sizeof buf);
      if (len > 0) s.assign(reinterpret_cast<char*>(buf), static_cast<size_t>(len));
    }
    if (!sel.serial.empty() && s != sel.serial) {
      libusb_close(candidate);
      continue;
    }
    h = candidate;
    found = list[i];
    serial = s;
  }
  if (h == nullptr) {
    libusb_free_device_list(list, 1);
    libusb_exit(ctx);
    return last_error;
  }
  // Bulk endpoints of the interface.
  uint8_t ep_in = 0, ep_out = 0;
  int max_packet = 64;
  libusb_config_descriptor* cfg = nullptr;
  if (libusb_get_active_config_descriptor(found, &cfg) == 0 || libusb_get_config_descriptor(found, 0, &cfg) == 0) {
    if (sel.interface_number < cfg->bNumInterfaces && cfg->interface[sel.interface_number].num_altsetting > 0) {
      const libusb_interface_descriptor& alt = cfg->interface[sel.interface_number].altsetting[0];
      for (int e = 0; e < alt.bNumEndpoints; ++e) {
        const libusb_endpoint_descriptor& ep = alt.endpoint[e];
        if ((ep.bmAttributes & 0x03) != LIBUSB_TRANSFER_TYPE_BULK) continue;
        if (ep.bEndpointAddress & LIBUSB_ENDPOINT_IN) {
          ep_in = ep.bEndpointAddress;
          max_packet = ep.wMaxPacketSize;
        } else {
          ep_out = ep.bEndpointAddress;
        }
      }
    }
    libusb_free_config_descriptor(cfg);
  }
  const std::string desc = "usb " + std::to_string(libusb_get_bus_number(found)) + "/" +
                           std::to_string(libusb_get_device_address(found)) + " " + Hex4(sel.vendor_id) + ":" +
                           Hex4(sel.product_id) + (serial.empty() ? "" : " serial " + serial);
  libusb_free_device_list(list, 1);
  auto close_all = [&](Status s) {
    libusb_close(h);
    libusb_exit(ctx);
    return s;
  };
  if (ep_in == 0 || ep_out == 0)
    return close_all(
        Status::Unavailable(desc + ": no bulk IN/OUT endpoints on interface " + std::to_string(sel.interface_number)));
  // Thorlabs controllers bind to the kernel's ftdi_sio (ttyUSB) driver by default.
  if (libusb_kernel_driver_active(h, sel.interface_number) == 1) {
    if (int rc = libusb_detach_kernel_driver(h, sel.interface_number); rc < 0) {
      return close_all(FromLibusb(rc, desc + ": detaching ftdi_sio"));
    }
  }
  if (int rc = libusb_claim_interface(h, sel.interface_number); rc < 0) {
    return close_all(FromLibusb(rc, desc + ": claiming interface"));
  }
  return std::unique_ptr<UsbTransport>(
      new LibusbTransport(ctx, h, sel.interface_number, ep_in, ep_out, max_packet, desc, serial));
}

}  // namespace inspection
