// Projector driver "none": uniform patterns are a no-op, anything else is refused.
#include "devices/drivers/null_projector.h"

namespace inspection {

DeviceInfo NullProjector::info() const {
  DeviceInfo d;
  d.role = "projector";
  d.driver = "none";
  d.model = "no projector";
  d.connected = true;
  d.detail = "uniform illumination only (microscope lamp)";
  return d;
}

Status NullProjector::Show(const cv::Mat& pattern) {
  if (pattern.type() != CV_8UC1 || pattern.size() != resolution_) {
    return Status::InvalidArgument("pattern must be CV_8UC1 of " + std::to_string(resolution_.width) + "x" +
                                   std::to_string(resolution_.height));
  }
  double lo = 0, hi = 0;
  cv::minMaxLoc(pattern, &lo, &hi);
  if (lo != hi) {
    return Status::FailedPrecondition(
        "this rig has no projector (projector.driver = none): only uniform illumination is possible");
  }
  return Status::Ok();
}

}  // namespace inspection
