// NullProjector: projector driver "none", for a microscope lit by its own lamp instead of a
// projector. Only uniform patterns are accepted (and do nothing): the thesis's STD illumination
// works, adaptive illumination (thesis 4) cannot and fails with FAILED_PRECONDITION.
#pragma once

#include "devices/projector.h"

namespace inspection {

class NullProjector : public Projector {
 public:
  explicit NullProjector(cv::Size resolution) : resolution_(resolution) {}

  DeviceInfo info() const override;
  cv::Size resolution() const override { return resolution_; }
  Status Show(const cv::Mat& pattern) override;

 private:
  cv::Size resolution_;
};

}  // namespace inspection
