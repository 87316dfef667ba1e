// Test rigs for the end-to-end tests: wrap the simulated rig to hold a scan at a chosen frame
// (so a test can act "mid-scan" without sleeping) or to make the camera fail like an unplugged
// device.
#pragma once

#include <condition_variable>
#include <memory>
#include <mutex>

#include "devices/rig.h"
#include "devices/sim/simulated_rig.h"

namespace inspection::testing {

// Shared between the test and the rig: captures block at `hold_at_frame` (counted from the
// rig's creation) until Release(); `fail_from_frame` makes every later capture UNAVAILABLE
// until the rig is reset.
struct RigControl {
  std::mutex mu;
  std::condition_variable cv;
  int captures = 0;
  int hold_at_frame = -1;
  bool released = false;
  bool holding = false;
  int fail_from_frame = -1;
  bool failed = false;

  void Release() {
    std::lock_guard<std::mutex> l(mu);
    released = true;
    cv.notify_all();
  }
  // Blocks until a capture is being held; false if none is within the deadline (a test bug,
  // not a timing assumption: the deadline only keeps a broken test from hanging).
  [[nodiscard]] bool WaitUntilHolding() {
    std::unique_lock<std::mutex> l(mu);
    return cv.wait_for(l, std::chrono::seconds(60), [&] { return holding; });
  }
};

class ControlledCamera final : public Camera {
 public:
  ControlledCamera(Camera& inner, std::shared_ptr<RigControl> control) : inner_(inner), c_(std::move(control)) {}
  DeviceInfo info() const override {
    DeviceInfo i = inner_.info();
    std::lock_guard<std::mutex> l(c_->mu);
    if (c_->failed) {
      i.connected = false;
      i.detail = "camera disappeared (test)";
    }
    return i;
  }
  cv::Size frame_size() const override { return inner_.frame_size(); }
  int bit_depth() const override { return inner_.bit_depth(); }
  Status SetExposure(double us) override { return inner_.SetExposure(us); }
  double exposure_us() const override { return inner_.exposure_us(); }
  Status SetGain(double db) override { return inner_.SetGain(db); }
  StatusOr<cv::Mat> Capture() override {
    {
      std::unique_lock<std::mutex> l(c_->mu);
      const int n = c_->captures++;
      if (c_->fail_from_frame >= 0 && n >= c_->fail_from_frame) c_->failed = true;
      if (c_->failed) return Status::Unavailable("camera disappeared (test): no frame");
      if (n == c_->hold_at_frame) {
        c_->holding = true;
        c_->cv.notify_all();
        c_->cv.wait(l, [&] { return c_->released; });
      }
    }
    return inner_.Capture();
  }

 private:
  Camera& inner_;
  std::shared_ptr<RigControl> c_;
};

class ControlledRig final : public Rig {
 public:
  ControlledRig(std::unique_ptr<Rig> inner, std::shared_ptr<RigControl> control)
      : inner_(std::move(inner)), control_(control), camera_(inner_->camera(), control) {}
  Camera& camera() override { return camera_; }
  Projector& projector() override { return inner_->projector(); }
  Stage& stage() override { return inner_->stage(); }
  double pixel_size_um() const override { return inner_->pixel_size_um(); }
  ScanDefaults scan_defaults() const override { return inner_->scan_defaults(); }
  SimulationControl* simulation() override { return inner_->simulation(); }
  Status Reset() override {
    {
      std::lock_guard<std::mutex> l(control_->mu);
      control_->failed = false;
      control_->fail_from_frame = -1;
    }
    return inner_->Reset();
  }

 private:
  std::unique_ptr<Rig> inner_;
  std::shared_ptr<RigControl> control_;
  ControlledCamera camera_;
};

}  // namespace inspection::testing
