// Aravis camera driver: open, configure, software-triggered capture, loss detection.
#include "devices/drivers/aravis_camera.h"

#include <arv.h>

#include <atomic>
#include <chrono>
#include <cstring>

namespace inspection {
namespace {

std::string TakeError(GError*& e) {
  std::string m = e ? e->message : "unknown error";
  if (e) g_clear_error(&e);
  return m;
}

// GigE Vision: the control channel reports heartbeat loss through the "control-lost" signal.
void OnControlLost(ArvGvDevice*, gpointer flag) { static_cast<std::atomic<bool>*>(flag)->store(true); }

constexpr const char* kControlLost = "control channel lost (no heartbeat answer)";

}  // namespace

struct AravisCamera::Handles {
  ArvCamera* camera = nullptr;
  ArvStream* stream = nullptr;
  // Shared with the published info so status readers see a heartbeat loss at once.
  std::shared_ptr<std::atomic<bool>> lost_flag = std::make_shared<std::atomic<bool>>(false);
  std::atomic<bool>& control_lost = *lost_flag;
  gulong lost_handler = 0;

  ~Handles() {
    if (camera && lost_handler) g_signal_handler_disconnect(arv_camera_get_device(camera), lost_handler);
    if (stream) g_object_unref(stream);
    if (camera) g_object_unref(camera);
  }
};

AravisCamera::AravisCamera(AravisCameraOptions options) : options_(std::move(options)) {
  bits_ = AravisPixelFormatBits(options_.pixel_format).ok() ? *AravisPixelFormatBits(options_.pixel_format) : 8;
  Publish();
}

void AravisCamera::Publish() { published_.Set(BuildInfo(), h_ ? h_->lost_flag : nullptr, kControlLost); }

AravisCamera::~AravisCamera() {
  Disconnect("closed");
  if (reaper_.joinable()) reaper_.join();
}

void AravisCamera::Disconnect(const std::string& reason) {
  if (h_ && h_->camera && !h_->control_lost.load()) {
    GError* e = nullptr;
    arv_camera_stop_acquisition(h_->camera, &e);
    g_clear_error(&e);
  }
  h_.reset();
  last_error_ = reason;
}

Status AravisCamera::Lost(const std::string& what) {
  // Releasing stream and device on a dead link costs several GVCP timeouts (~10 s): do it on a
  // reaper thread so the failing call returns now; Connect() and the destructor join it.
  if (reaper_.joinable()) reaper_.join();
  if (h_) {
    h_->control_lost.store(true);
    reaper_ = std::thread([h = std::move(h_)]() mutable { h.reset(); });
  }
  last_error_ = what;
  return Status::Unavailable("camera (aravis " + (device_id_.empty() ? options_.device_id : device_id_) +
                             ") is gone: " + what);
}

Status AravisCamera::Connect() {
  Republish publish{this};
  Disconnect("reconnecting");
  if (reaper_.joinable()) reaper_.join();
  INSPECT_RETURN_IF_ERROR(options_.Validate());
  auto fail = [this](const std::string& m) {
    Disconnect(m);
    return Status::Unavailable("camera (aravis): " + m);
  };
  std::string id = options_.device_id;
  if (id.empty()) {
    arv_update_device_list();  // discovery, ~1 s on GigE: only here, never per frame
    const unsigned n = arv_get_n_devices();
    for (unsigned i = 0; i < n && id.empty(); ++i) {
      const char* serial = arv_get_device_serial_nbr(i);
      if (options_.serial.empty() || (serial && options_.serial == serial)) id = arv_get_device_id(i);
    }
    if (id.empty()) {
      return fail(options_.serial.empty() ? "no camera found" : "no camera with serial " + options_.serial + " found");
    }
  }
  auto h = std::make_unique<Handles>();
  GError* e = nullptr;
  h->camera = arv_camera_new(id.c_str(), &e);
  if (!h->camera) return fail("cannot open '" + id + "': " + TakeError(e));
  device_id_ = id;
  const char* model = arv_camera_get_model_name(h->camera, &e);
  g_clear_error(&e);
  model_ = model ? model : "";
  const char* serial = arv_camera_get_device_serial_number(h->camera, &e);
  g_clear_error(&e);
  serial_ = serial ? serial : "";
  if (!options_.serial.empty() && serial_ != options_.serial) {
    return fail("'" + id + "' has serial " + serial_ + ", expected " + options_.serial);
  }
  if (arv_camera_is_gv_device(h->camera)) {
    // As root, the packet-socket receiver sees nothing on loopback; sockets work everywhere.
    arv_camera_gv_set_stream_options(h->camera, ARV_GV_STREAM_OPTION_PACKET_SOCKET_DISABLED);
    if (options_.packet_size > 0) {
      arv_camera_gv_set_packet_size(h->camera, options_.packet_size, &e);
    } else {
      arv_camera_gv_auto_packet_size(h->camera, &e);
    }
    g_clear_error(&e);
    h->lost_handler = g_signal_connect(arv_camera_get_device(h->camera), "control-lost", G_CALLBACK(OnControlLost),
                                       h->lost_flag.get());
  }
  {
    // An unsupported pixel format is a configuration error, not an absent camera.
    guint n_formats = 0;
    const char** formats = arv_camera_dup_available_pixel_formats_as_strings(h->camera, &n_formats, &e);
    g_clear_error(&e);
    bool supported = formats == nullptr;  // cannot tell: let the camera decide below
    std::string available;
    for (guint i = 0; formats && i < n_formats; ++i) {
      if (!formats[i]) continue;
      supported = supported || options_.pixel_format == formats[i];
      available += (available.empty() ? "" : ", ") + std::string(formats[i]);
    }
    g_free(formats);
    if (!supported) {
      Disconnect("pixel format " + options_.pixel_format + " not supported");
      return Status::FailedPrecondition("camera (aravis " + id + "): pixel_format " + options_.pixel_format +
                                        " is not supported (available: " + available + ")");
    }
  }
  arv_camera_set_pixel_format_from_string(h->camera, options_.pixel_format.c_str(), &e);
  if (e) return fail("pixel_format " + options_.pixel_format + ": " + TakeError(e));
  if (options_.region_width > 0 && options_.region_height > 0) {
    arv_camera_set_region(h->camera, options_.region_x, options_.region_y, options_.region_width,
                          options_.region_height, &e);
    if (e) {
      Disconnect("region rejected");
      return Status::FailedPrecondition("camera (aravis " + id + "): region " + std::to_string(options_.region_width) +
                                        "x" + std::to_string(options_.region_height) + ": " + TakeError(e));
    }
  }
  arv_camera_set_exposure_time(h->camera, options_.exposure_us, &e);
  if (e) return fail("exposure_us: " + TakeError(e));
  if (arv_camera_is_gain_available(h->camera, nullptr)) {
    arv_camera_set_gain(h->camera, options_.gain_db, &e);
    if (e) return fail("gain_db: " + TakeError(e));
  }
  arv_camera_set_acquisition_mode(h->camera, ARV_ACQUISITION_MODE_CONTINUOUS, &e);
  g_clear_error(&e);
  // Frame start on software trigger: one exposure per z step.
  arv_camera_set_trigger(h->camera, "Software", &e);
  if (e) {
    g_clear_error(&e);
    arv_camera_set_string(h->camera, "TriggerMode", "On", &e);
    if (!e) arv_camera_set_string(h->camera, "TriggerSource", "Software", &e);
    if (e) return fail("software trigger: " + TakeError(e));
  }
  gint x = 0, y = 0, w = 0, ht = 0;
  arv_camera_get_region(h->camera, &x, &y, &w, &ht, &e);
  if (e) return fail("region: " + TakeError(e));
  size_ = cv::Size(w, ht);
  const guint payload = arv_camera_get_payload(h->camera, &e);
  if (e) return fail("payload: " + TakeError(e));
  h->stream = arv_camera_create_stream(h->camera, nullptr, nullptr, &e);
  if (!h->stream) return fail("stream: " + TakeError(e));
  for (int i = 0; i < options_.n_buffers; ++i) arv_stream_push_buffer(h->stream, arv_buffer_new(payload, nullptr));
  arv_camera_start_acquisition(h->camera, &e);
  if (e) return fail("start acquisition: " + TakeError(e));
  h_ = std::move(h);
  last_error_.clear();
  return Status::Ok();
}

DeviceInfo AravisCamera::BuildInfo() const {
  DeviceInfo d;
  d.role = "camera";
  d.driver = "aravis";
  d.model = model_;
  d.serial = serial_.empty() ? options_.serial : serial_;
  d.connected = h_ != nullptr && !h_->control_lost.load();
  d.detail = d.connected ? device_id_ + ", " + options_.pixel_format + ", " + std::to_string(size_.width) + "x" +
                               std::to_string(size_.height)
                         : (h_ ? kControlLost : last_error_);
  return d;
}

cv::Size AravisCamera::frame_size() const { return size_; }
int AravisCamera::bit_depth() const { return bits_; }

Status AravisCamera::SetExposure(double exposure_us) {
  Republish publish{this};
  if (!(exposure_us > 0.0)) return Status::InvalidArgument("exposure_us must be > 0");
  if (!h_) return Status::Unavailable("camera (aravis) is not connected: " + last_error_);
  GError* e = nullptr;
  arv_camera_set_exposure_time(h_->camera, exposure_us, &e);
  if (e) return Lost("setting exposure: " + TakeError(e));
  options_.exposure_us = exposure_us;
  return Status::Ok();
}

Status AravisCamera::SetGain(double gain_db) {
  Republish publish{this};
  if (!h_) return Status::Unavailable("camera (aravis) is not connected: " + last_error_);
  GError* e = nullptr;
  arv_camera_set_gain(h_->camera, gain_db, &e);
  if (e) {
    const std::string m = TakeError(e);
    // Out-of-range values are the caller's problem; a dead control channel is ours.
    if (!h_->control_lost.load() && arv_camera_get_payload(h_->camera, &e) > 0 && !e) {
      return Status::InvalidArgument("gain_db " + std::to_string(gain_db) + ": " + m);
    }
    g_clear_error(&e);
    return Lost("setting gain: " + m);
  }
  options_.gain_db = gain_db;
  return Status::Ok();
}

StatusOr<cv::Mat> AravisCamera::Capture() {
  Republish publish{this};
  if (!h_) return Status::Unavailable("camera (aravis) is not connected: " + last_error_);
  if (h_->control_lost.load()) return Lost("control channel lost (heartbeat)");
  // Drop frames left over from an earlier, timed-out trigger.
  while (ArvBuffer* stale = arv_stream_try_pop_buffer(h_->stream)) arv_stream_push_buffer(h_->stream, stale);

  GError* e = nullptr;
  arv_camera_software_trigger(h_->camera, &e);
  if (e) return Lost("software trigger: " + TakeError(e));
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::microseconds(static_cast<int64_t>(options_.frame_timeout_ms * 1000));
  for (;;) {
    const auto left =
        std::chrono::duration_cast<std::chrono::microseconds>(deadline - std::chrono::steady_clock::now());
    ArvBuffer* buffer =
        left.count() > 0 ? arv_stream_timeout_pop_buffer(h_->stream, static_cast<guint64>(left.count())) : nullptr;
    if (!buffer) {
      // No frame: is the camera still there? A control read answers that.
      arv_camera_get_payload(h_->camera, &e);
      if (e || h_->control_lost.load()) return Lost("no frame and no answer on the control channel: " + TakeError(e));
      return Status::DeadlineExceeded("camera (aravis " + device_id_ + "): no frame within " +
                                      std::to_string(static_cast<int>(options_.frame_timeout_ms)) +
                                      " ms of the trigger");
    }
    if (arv_buffer_get_status(buffer) != ARV_BUFFER_STATUS_SUCCESS) {
      // Incomplete frame (lost packets): trigger again while time remains.
      arv_stream_push_buffer(h_->stream, buffer);
      arv_camera_software_trigger(h_->camera, &e);
      if (e) return Lost("software trigger: " + TakeError(e));
      continue;
    }
    const int w = arv_buffer_get_image_width(buffer);
    const int ht = arv_buffer_get_image_height(buffer);
    const ArvPixelFormat format = arv_buffer_get_image_pixel_format(buffer);
    size_t size = 0;
    const void* data = arv_buffer_get_image_data(buffer, &size);
    const bool eight = format == ARV_PIXEL_FORMAT_MONO_8;
    const bool sixteen =
        format == ARV_PIXEL_FORMAT_MONO_10 || format == ARV_PIXEL_FORMAT_MONO_12 || format == ARV_PIXEL_FORMAT_MONO_16;
    const size_t needed = static_cast<size_t>(w) * ht * (eight ? 1 : 2);
    if ((!eight && !sixteen) || data == nullptr || size < needed) {
      arv_stream_push_buffer(h_->stream, buffer);
      return Status::DataLoss("camera (aravis " + device_id_ + "): unexpected frame (pixel format 0x" +
                              std::to_string(format) + ", " + std::to_string(size) + " bytes for " + std::to_string(w) +
                              "x" + std::to_string(ht) + ")");
    }
    cv::Mat frame;
    cv::Mat(ht, w, eight ? CV_8UC1 : CV_16UC1, const_cast<void*>(data)).copyTo(frame);
    arv_stream_push_buffer(h_->stream, buffer);
    if (sixteen && bits_ < 16) {
      // Unpacked MonoN keeps values in the low N bits; mask stray high bits so the documented
      // range [0, 2^N - 1] holds.
      frame &= cv::Scalar((1 << bits_) - 1);
    }
    size_ = frame.size();
    return frame;
  }
}

}  // namespace inspection
