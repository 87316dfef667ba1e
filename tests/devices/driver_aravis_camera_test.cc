// Aravis camera driver against real GigE Vision on loopback: the arv-fake-gv-camera-0.8 program
// as a child process (software-triggered capture, kill mid-sequence -> UNAVAILABLE, restart ->
// reconnect), and an in-process fake GigE Vision camera serving frames rendered by the simulated
// rig, captured through the driver and reconstructed with SffEngine against ground truth.
#include "devices/drivers/aravis_camera.h"

#if INSPECT_HAVE_DRIVERS  // needs Aravis (INSPECT_BUILD_DRIVERS=ON)

#include <arv.h>
#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/sff/sff_engine.h"
#include "devices/rig_config.h"
#include "devices/sim/simulated_rig.h"
#include "tests/lib/skip_or_fail.h"

extern char** environ;

namespace inspection {
namespace {

using Clock = std::chrono::steady_clock;

#ifndef INSPECT_ARV_FAKE_GV_CAMERA
#define INSPECT_ARV_FAKE_GV_CAMERA ""
#endif

// Every fake GigE Vision camera binds UDP port 3956 on 127.0.0.1: tests (and other binaries
// using the same lock file) take turns.
class GigeLoopbackTest : public ::testing::Test {
 protected:
  void SetUp() override {
    lock_fd_ = ::open("/tmp/inspection-gige-loopback.lock", O_CREAT | O_RDWR | O_CLOEXEC, 0666);
    ASSERT_GE(lock_fd_, 0);
    ASSERT_EQ(::flock(lock_fd_, LOCK_EX), 0);
  }
  void TearDown() override {
    StopFakeCamera();
    if (lock_fd_ >= 0) ::close(lock_fd_);
  }

  static bool FakeProgramPresent() {
    const std::string path = INSPECT_ARV_FAKE_GV_CAMERA;
    return !path.empty() && ::access(path.c_str(), X_OK) == 0;
  }

  void StartFakeCamera(const std::string& serial) {
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
    std::string program = INSPECT_ARV_FAKE_GV_CAMERA;
    std::vector<std::string> args = {program, "-i", "127.0.0.1", "-s", serial};
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ASSERT_EQ(posix_spawn(&child_, program.c_str(), &actions, nullptr, argv.data(), environ), 0);
    posix_spawn_file_actions_destroy(&actions);
  }
  void StopFakeCamera() {
    if (child_ > 0) {
      ::kill(child_, SIGKILL);
      ::waitpid(child_, nullptr, 0);
      child_ = -1;
    }
  }
  // Readiness: retry the real open until it works or the deadline passes.
  static Status ConnectWithin(AravisCamera& camera, std::chrono::seconds limit) {
    const Clock::time_point deadline = Clock::now() + limit;
    Status s;
    do {
      s = camera.Connect();
    } while (!s.ok() && s.code() == StatusCode::kUnavailable && Clock::now() < deadline);
    return s;
  }

  int lock_fd_ = -1;
  pid_t child_ = -1;
};

AravisCameraOptions FakeOptions(const std::string& serial) {
  AravisCameraOptions o;
  o.device_id = "Aravis-Fake-" + serial;
  o.exposure_us = 2000.0;
  o.frame_timeout_ms = 1000.0;
  o.region_width = 64;
  o.region_height = 48;
  return o;
}

TEST_F(GigeLoopbackTest, SoftwareTriggeredCaptureSurvivesCameraRestart) {
  if (!FakeProgramPresent()) INSPECT_SKIP_OR_FAIL() << "arv-fake-gv-camera-0.8 not installed";
  StartFakeCamera("DRVKILL");
  AravisCamera camera(FakeOptions("DRVKILL"));
  ASSERT_TRUE(ConnectWithin(camera, std::chrono::seconds(20)).ok());
  DeviceInfo info = camera.info();
  EXPECT_TRUE(info.connected);
  EXPECT_EQ(info.driver, "aravis");
  EXPECT_EQ(info.serial, "DRVKILL");
  EXPECT_EQ(camera.frame_size(), cv::Size(64, 48));
  EXPECT_EQ(camera.bit_depth(), 8);
  ASSERT_TRUE(camera.SetExposure(3000.0).ok());
  EXPECT_DOUBLE_EQ(camera.exposure_us(), 3000.0);

  for (int step = 0; step < 3; ++step) {  // one trigger per z step
    StatusOr<cv::Mat> frame = camera.Capture();
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    EXPECT_EQ(frame->type(), CV_8UC1);
    EXPECT_EQ(frame->size(), cv::Size(64, 48));
    double lo = 0, hi = 0;
    cv::minMaxLoc(*frame, &lo, &hi);
    EXPECT_LT(lo, hi) << "the fake camera's diagonal ramp is not uniform";
  }

  StopFakeCamera();  // the camera disappears mid-scan
  StatusOr<cv::Mat> lost = camera.Capture();
  EXPECT_EQ(lost.status().code(), StatusCode::kUnavailable) << lost.status().ToString();
  EXPECT_THAT(lost.status().message(), ::testing::HasSubstr("gone"));
  EXPECT_FALSE(camera.info().connected);
  EXPECT_EQ(camera.Capture().status().code(), StatusCode::kUnavailable);

  StartFakeCamera("DRVKILL");  // plugged back in
  ASSERT_TRUE(ConnectWithin(camera, std::chrono::seconds(30)).ok());
  EXPECT_TRUE(camera.info().connected);
  StatusOr<cv::Mat> again = camera.Capture();
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(again->size(), cv::Size(64, 48));
}

TEST_F(GigeLoopbackTest, OpensBySerialAndHonoursPixelFormat) {
  if (!FakeProgramPresent()) INSPECT_SKIP_OR_FAIL() << "arv-fake-gv-camera-0.8 not installed";
  StartFakeCamera("DRVFMT");
  AravisCameraOptions o = FakeOptions("DRVFMT");
  o.device_id.clear();  // discovery by serial number
  o.serial = "DRVFMT";
  o.pixel_format = "Mono16";
  {
    AravisCamera camera(o);
    ASSERT_TRUE(ConnectWithin(camera, std::chrono::seconds(20)).ok());
    EXPECT_EQ(camera.bit_depth(), 16);
    StatusOr<cv::Mat> frame = camera.Capture();
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    EXPECT_EQ(frame->type(), CV_16UC1);
    EXPECT_EQ(frame->size(), cv::Size(64, 48));
  }  // GigE Vision grants control to one client at a time: release it

  // The built-in fake offers Mono8 and Mono16 only: Mono12 is a configuration error.
  o.pixel_format = "Mono12";
  AravisCamera mono12(o);
  Status s = mono12.Connect();
  EXPECT_EQ(s.code(), StatusCode::kFailedPrecondition) << s.ToString();
  EXPECT_THAT(s.message(), ::testing::HasSubstr("Mono16"));

  // A frame that does not arrive while the camera still answers is DEADLINE_EXCEEDED.
  o.pixel_format = "Mono8";
  o.frame_timeout_ms = 0.001;
  AravisCamera hasty(o);
  ASSERT_TRUE(ConnectWithin(hasty, std::chrono::seconds(20)).ok());
  EXPECT_EQ(hasty.Capture().status().code(), StatusCode::kDeadlineExceeded);
  EXPECT_TRUE(hasty.info().connected);
}

// Rig level: a degraded start without the camera, the camera appearing, a reset picking it up,
// the camera vanishing mid-scan and a reset reconnecting it again.
TEST_F(GigeLoopbackTest, RigResetReconnectsTheCamera) {
  if (!FakeProgramPresent()) INSPECT_SKIP_OR_FAIL() << "arv-fake-gv-camera-0.8 not installed";
  StatusOr<RigConfig> config = ParseRigConfig(R"({
    "name": "loopback", "pixel_size_um": 1.0,
    "camera": {"driver": "aravis", "device_id": "Aravis-Fake-DRVRIG", "frame_timeout_ms": 1000,
               "region": {"width": 32, "height": 24}},
    "stage": {"driver": "apt-usb", "serial": "27999998"},
    "projector": {"driver": "none", "width": 32, "height": 24}})");
  ASSERT_TRUE(config.ok()) << config.status().ToString();
  StatusOr<std::unique_ptr<Rig>> created = CreateRig(*config, RigStartOptions{.allow_degraded = true});
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  Rig& rig = **created;
  EXPECT_FALSE(rig.camera().info().connected);
  EXPECT_THAT(rig.CheckDevices().message(), ::testing::HasSubstr("camera (aravis"));

  auto reset_until_camera = [&rig] {
    const Clock::time_point deadline = Clock::now() + std::chrono::seconds(30);
    Status s;
    do {
      s = rig.Reset();  // the stage stays absent: UNAVAILABLE naming it
    } while (!rig.camera().info().connected && Clock::now() < deadline);
    return s;
  };
  StartFakeCamera("DRVRIG");
  Status reset = reset_until_camera();
  ASSERT_TRUE(rig.camera().info().connected) << reset.ToString();
  EXPECT_EQ(reset.code(), StatusCode::kUnavailable);
  EXPECT_THAT(reset.message(), ::testing::HasSubstr("27999998"));
  ASSERT_TRUE(rig.camera().Capture().ok());

  StopFakeCamera();
  EXPECT_EQ(rig.camera().Capture().status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(rig.CheckDevices().message(), ::testing::HasSubstr("camera (aravis"));
  StartFakeCamera("DRVRIG");
  reset = reset_until_camera();
  ASSERT_TRUE(rig.camera().info().connected) << reset.ToString();
  EXPECT_EQ(reset.code(), StatusCode::kUnavailable);  // the stage is still absent
  StatusOr<cv::Mat> frame = rig.camera().Capture();
  ASSERT_TRUE(frame.ok()) << frame.status().ToString();
  EXPECT_EQ(frame->size(), cv::Size(32, 24));
}

// Mono12 end to end: the fake camera's GenICam description extended by a Mono12 entry, frames
// of 12-bit values in 16-bit containers served in-process and received unchanged.
void FillMono12Ramp(ArvBuffer* buffer, void* data, guint32, guint32, ArvPixelFormat format) {
  auto* fake = static_cast<ArvFakeCamera*>(data);
  auto* out = static_cast<uint16_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
  const gint w = arv_buffer_get_image_width(buffer);
  const gint h = arv_buffer_get_image_height(buffer);
  if (out == nullptr || format != ARV_PIXEL_FORMAT_MONO_12 ||
      arv_fake_camera_get_payload(fake) < static_cast<size_t>(w) * h * 2) {
    return;
  }
  for (gint y = 0; y < h; ++y)
    for (gint x = 0; x < w; ++x) out[y * w + x] = static_cast<uint16_t>((x * 61 + y * 127) & 0x0FFF);
}

TEST_F(GigeLoopbackTest, Mono12FramesArriveUnchanged) {
  ArvFakeCamera* plain = arv_fake_camera_new("XMLSRC");
  size_t xml_size = 0;
  std::string xml(arv_fake_camera_get_genicam_xml(plain, &xml_size));
  g_object_unref(plain);
  const std::string anchor = "<pValue>PixelFormatRegister</pValue>";
  const size_t at = xml.find(anchor);
  ASSERT_NE(at, std::string::npos);
  xml.insert(at, "<EnumEntry Name=\"Mono12\" NameSpace=\"Standard\"><Value>" +
                     std::to_string(ARV_PIXEL_FORMAT_MONO_12) + "</Value></EnumEntry>\n\t\t");
  const std::string path = "/tmp/inspection-fake-mono12-" + std::to_string(::getpid()) + ".xml";
  {
    FILE* f = std::fopen(path.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fwrite(xml.data(), 1, xml.size(), f);
    std::fclose(f);
  }
  ArvGvFakeCamera* gv = arv_gv_fake_camera_new_full("127.0.0.1", "MONO12", path.c_str());
  ASSERT_NE(gv, nullptr);
  ASSERT_TRUE(arv_gv_fake_camera_is_running(gv));
  ArvFakeCamera* fake = arv_gv_fake_camera_get_fake_camera(gv);
  arv_fake_camera_set_fill_pattern(fake, FillMono12Ramp, fake);
  {
    AravisCameraOptions o = FakeOptions("MONO12");
    o.pixel_format = "Mono12";
    AravisCamera camera(o);
    Status connected = ConnectWithin(camera, std::chrono::seconds(20));
    ASSERT_TRUE(connected.ok()) << connected.ToString();
    EXPECT_EQ(camera.bit_depth(), 12);
    StatusOr<cv::Mat> frame = camera.Capture();
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    ASSERT_EQ(frame->type(), CV_16UC1);
    ASSERT_EQ(frame->size(), cv::Size(64, 48));
    cv::Mat expected(48, 64, CV_16UC1);
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 64; ++x) expected.at<uint16_t>(y, x) = static_cast<uint16_t>((x * 61 + y * 127) & 0x0FFF);
    EXPECT_EQ(cv::norm(*frame, expected, cv::NORM_INF), 0.0);
    double hi = 0;
    cv::minMaxLoc(*frame, nullptr, &hi);
    EXPECT_LE(hi, 4095.0);
  }
  g_object_unref(gv);
  std::remove(path.c_str());
}

TEST_F(GigeLoopbackTest, AbsentCameraIsUnavailable) {
  AravisCameraOptions o = FakeOptions("NOSUCHCAM");
  AravisCamera camera(o);
  Status s = camera.Connect();
  EXPECT_EQ(s.code(), StatusCode::kUnavailable);
  EXPECT_THAT(s.message(), ::testing::HasSubstr("Aravis-Fake-NOSUCHCAM"));
  EXPECT_FALSE(camera.info().connected);
  EXPECT_EQ(camera.Capture().status().code(), StatusCode::kUnavailable);
}

// Serves pre-rendered frames, one per trigger, from the fake camera's streaming thread.
struct FrameSource {
  std::vector<cv::Mat> frames;
  std::atomic<int> served{0};
  ArvFakeCamera* fake = nullptr;
};

void FillFromSource(ArvBuffer* buffer, void* data, guint32, guint32, ArvPixelFormat) {
  auto* source = static_cast<FrameSource*>(data);
  const int k = source->served.fetch_add(1);
  const cv::Mat& f = source->frames[static_cast<size_t>(k) % source->frames.size()];
  // The fake camera checked that the buffer holds its payload (width x height of the region,
  // which the test sets to the frame size) before calling us; the buffer's received size is
  // only set after this callback, so it cannot bound the copy.
  auto* out = static_cast<uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
  if (out != nullptr && static_cast<int>(arv_fake_camera_get_payload(source->fake)) >= static_cast<int>(f.total())) {
    std::memcpy(out, f.data, f.total());
  }
}

TEST_F(GigeLoopbackTest, ServesSimulatedRigFramesOverGigeAndReconstructsDepth) {
  SimulatedRigOptions sim;
  sim.specimen = "skew5";
  sim.camera_size = {128, 96};
  StatusOr<std::unique_ptr<Rig>> rig = CreateSimulatedRig(sim);
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  const ScanDefaults d = (*rig)->scan_defaults();
  ASSERT_TRUE((*rig)->projector().ShowUniform(128).ok());
  FrameSource source;
  std::vector<double> zs;
  for (double z = d.z_start_um; z <= d.z_end_um + 1e-9; z += d.z_step_um) {
    ASSERT_TRUE((*rig)->stage().MoveTo(z).ok());
    StatusOr<cv::Mat> f = (*rig)->camera().Capture();
    ASSERT_TRUE(f.ok());
    ASSERT_EQ(f->type(), CV_8UC1);
    source.frames.push_back(f->clone());
    zs.push_back(z);
  }

  ArvGvFakeCamera* gv = arv_gv_fake_camera_new("127.0.0.1", "SIMRIG");
  ASSERT_NE(gv, nullptr);
  ASSERT_TRUE(arv_gv_fake_camera_is_running(gv));
  source.fake = arv_gv_fake_camera_get_fake_camera(gv);
  arv_fake_camera_set_fill_pattern(source.fake, FillFromSource, &source);

  AravisCameraOptions o = FakeOptions("SIMRIG");
  o.region_width = 128;
  o.region_height = 96;
  auto camera_ptr = std::make_unique<AravisCamera>(o);
  AravisCamera& camera = *camera_ptr;
  Status connected = ConnectWithin(camera, std::chrono::seconds(20));
  ASSERT_TRUE(connected.ok()) << connected.ToString();
  const int served_before = source.served.load();

  auto engine = SffEngine::Create(SffOptions{}, camera.frame_size(), CV_8UC1);
  ASSERT_TRUE(engine.ok());
  for (size_t k = 0; k < zs.size(); ++k) {
    StatusOr<cv::Mat> frame = camera.Capture();
    ASSERT_TRUE(frame.ok()) << "frame " << k << ": " << frame.status().ToString();
    const cv::Mat& sent = source.frames[(static_cast<size_t>(served_before) + k) % source.frames.size()];
    ASSERT_EQ(cv::norm(*frame, sent, cv::NORM_INF), 0.0) << "frame " << k << " changed on the wire";
    ASSERT_TRUE((*engine)->PushFrame(*frame, zs[(static_cast<size_t>(served_before) + k) % zs.size()]).ok());
  }
  camera_ptr.reset();  // release control and stream while the server still answers
  g_object_unref(gv);
  ASSERT_EQ(served_before, 0) << "the fake camera served frames before the first trigger";

  StatusOr<DepthResult> depth = (*engine)->Finish();
  ASSERT_TRUE(depth.ok());
  const cv::Mat truth = (*rig)->simulation()->GroundTruthDepthUm();
  double sum = 0;
  int n = 0, total = 0;
  const int border = 8;
  for (int r = border; r < truth.rows - border; ++r) {
    for (int c = border; c < truth.cols - border; ++c) {
      ++total;
      const float z = depth->depth_um.at<float>(r, c);
      if (!std::isfinite(z)) continue;
      sum += (z - truth.at<float>(r, c)) * (z - truth.at<float>(r, c));
      ++n;
    }
  }
  const double rmse = n ? std::sqrt(sum / n) : 1e9;
  const double valid = static_cast<double>(n) / total;
  std::printf("GigE loopback skew5 128x96: %zu frames, depth rmse %.3f um (step %.2f um), valid %.3f\n", zs.size(),
              rmse, d.z_step_um, valid);
  EXPECT_LT(rmse, 0.25 * d.z_step_um);
  EXPECT_GT(valid, 0.95);
}

}  // namespace
}  // namespace inspection

#endif  // INSPECT_HAVE_DRIVERS
