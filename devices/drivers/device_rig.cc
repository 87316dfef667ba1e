// DeviceRig::Reset: reconnect all real devices and report the ones that stay absent.
#include "devices/drivers/device_rig.h"

namespace inspection {

Status DeviceRig::Reset() {
  std::string failures;
  StatusCode code = StatusCode::kOk;
  for (Part& p : parts_) {
    if (!p.connect) continue;
    Status s = p.connect();
    if (!s.ok()) {
      failures += (failures.empty() ? "" : "; ") + s.message();
      if (code == StatusCode::kOk) code = s.code();
    }
  }
  if (!failures.empty()) return Status(code == StatusCode::kOk ? StatusCode::kUnavailable : code, "reset: " + failures);
  return CheckDevices();
}

}  // namespace inspection
