#include "devices/rig.h"

namespace inspection {

Status Projector::ShowUniform(int grey) {
  if (grey < 0 || grey > 255) return Status::InvalidArgument("uniform grey must be 0..255");
  return Show(cv::Mat(resolution(), CV_8UC1, cv::Scalar(grey)));
}

Status Rig::CheckDevices() {
  for (const DeviceInfo& d : {camera().info(), projector().info(), stage().info()}) {
    if (!d.connected) {
      return Status::Unavailable(d.role + " (" + d.driver + (d.model.empty() ? "" : " " + d.model) +
                                 ") is not connected" + (d.detail.empty() ? "" : ": " + d.detail));
    }
  }
  return Status::Ok();
}

}  // namespace inspection
