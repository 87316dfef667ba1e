// PublishedInfo: the DeviceInfo snapshot a real driver publishes after every operation, so that
// status RPCs on other threads may call info() while the job worker operates the device.
#pragma once

#include <atomic>
#include <memory>
#include <mutex>
#include <string>

#include "devices/camera.h"

namespace inspection {

class PublishedInfo {
 public:
  // lost: optional flag a library thread raises asynchronously (e.g. GigE heartbeat loss);
  // while it is set, readers see connected == false with lost_detail.
  void Set(DeviceInfo info, std::shared_ptr<const std::atomic<bool>> lost = nullptr, std::string lost_detail = "") {
    std::lock_guard<std::mutex> lock(mu_);
    info_ = std::move(info);
    lost_ = std::move(lost);
    lost_detail_ = std::move(lost_detail);
  }
  DeviceInfo Get() const {
    std::lock_guard<std::mutex> lock(mu_);
    DeviceInfo d = info_;
    if (d.connected && lost_ && lost_->load()) {
      d.connected = false;
      d.detail = lost_detail_;
    }
    return d;
  }

 private:
  mutable std::mutex mu_;
  DeviceInfo info_;
  std::shared_ptr<const std::atomic<bool>> lost_;
  std::string lost_detail_;
};

}  // namespace inspection
