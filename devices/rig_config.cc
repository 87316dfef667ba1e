// Rig configuration: JSON parsing with key-naming errors, and CreateRig (see rig_config.h).
#include "devices/rig_config.h"

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "devices/drivers/device_rig.h"
#include "devices/drivers/null_projector.h"

namespace inspection {
namespace {

using nlohmann::json;

Status ConfigError(const std::string& key, const std::string& what) {
  return Status::InvalidArgument("rig config: " + key + " " + what);
}

// Typed access to one JSON object; remembers which keys were read so unknown ones (typos)
// can be reported by name.
class Section {
 public:
  Section(const json* j, std::string path) : j_(j), path_(std::move(path)) {}

  std::string key(const std::string& k) const { return path_.empty() ? k : path_ + "." + k; }
  bool has(const std::string& k) {
    seen_.insert(k);
    return j_ && j_->contains(k);
  }

  Status Number(const std::string& k, double* out) { return Typed(k, &json::is_number, "must be a number", out); }
  Status Int(const std::string& k, int* out) { return Typed(k, &json::is_number_integer, "must be an integer", out); }
  Status UInt64(const std::string& k, uint64_t* out) {
    return Typed(k, &json::is_number_unsigned, "must be a non-negative integer", out);  // JSON's 5, not -5 or 5.0
  }
  Status Bool(const std::string& k, bool* out) { return Typed(k, &json::is_boolean, "must be true or false", out); }
  Status String(const std::string& k, std::string* out) { return Typed(k, &json::is_string, "must be a string", out); }
  // USB ids as "0x0403" strings or integers.
  Status UsbId(const std::string& k, uint16_t* out) {
    if (!has(k)) return Status::Ok();
    const json& v = (*j_)[k];
    long value = -1;
    if (v.is_number_integer()) {
      value = v.get<long>();
    } else if (v.is_string()) {
      try {
        size_t used = 0;
        value = std::stol(v.get<std::string>(), &used, 0);
        if (used != v.get<std::string>().size()) value = -1;
      } catch (const std::exception&) {
        value = -1;
      }
    }
    if (value < 0 || value > 0xFFFF) return ConfigError(key(k), "must be a 16-bit USB id such as \"0x0403\"");
    *out = static_cast<uint16_t>(value);
    return Status::Ok();
  }
  StatusOr<Section> Object(const std::string& k) {
    if (!has(k)) return Section(nullptr, key(k));
    const json& v = (*j_)[k];
    if (!v.is_object()) return ConfigError(key(k), "must be an object");
    return Section(&v, key(k));
  }
  bool present() const { return j_ != nullptr; }

  Status NoUnknownKeys() const {
    if (!j_) return Status::Ok();
    for (auto it = j_->begin(); it != j_->end(); ++it) {
      if (!seen_.count(it.key())) return ConfigError(key(it.key()), "is not a known key");
    }
    return Status::Ok();
  }

 private:
  // The value of key k, when present, as T; `is_type` checks its JSON type first.
  template <typename T>
  Status Typed(const std::string& k, bool (json::*is_type)() const noexcept, const char* must, T* out) {
    if (!has(k)) return Status::Ok();
    const json& v = (*j_)[k];
    if (!(v.*is_type)()) return ConfigError(key(k), must);
    *out = v.get<T>();
    return Status::Ok();
  }
  const json* j_;
  std::string path_;
  std::set<std::string> seen_;
};

Status Positive(const std::string& key, double v) { return v > 0.0 ? Status::Ok() : ConfigError(key, "must be > 0"); }

Status ParseSimulation(Section s, SimulatedRigOptions* o) {
  INSPECT_RETURN_IF_ERROR(s.String("specimen", &o->specimen));
  INSPECT_RETURN_IF_ERROR(s.UInt64("seed", &o->seed));
  INSPECT_RETURN_IF_ERROR(s.Int("camera_width", &o->camera_size.width));
  INSPECT_RETURN_IF_ERROR(s.Int("camera_height", &o->camera_size.height));
  INSPECT_RETURN_IF_ERROR(s.Int("camera_bit_depth", &o->camera_bit_depth));
  INSPECT_RETURN_IF_ERROR(s.Int("projector_width", &o->projector_size.width));
  INSPECT_RETURN_IF_ERROR(s.Int("projector_height", &o->projector_size.height));
  INSPECT_RETURN_IF_ERROR(s.Number("pixel_size_um", &o->pixel_size_um));
  INSPECT_RETURN_IF_ERROR(s.Number("stage_repeatability_um", &o->stage_repeatability_um));
  INSPECT_RETURN_IF_ERROR(s.Number("read_noise_dn", &o->read_noise_dn));
  INSPECT_RETURN_IF_ERROR(s.Bool("shot_noise", &o->shot_noise));
  INSPECT_RETURN_IF_ERROR(s.Number("focus_breathing_percent_per_100um", &o->focus_breathing_percent_per_100um));
  INSPECT_RETURN_IF_ERROR(s.Number("lateral_drift_x_px_per_100um", &o->lateral_drift_x_px_per_100um));
  INSPECT_RETURN_IF_ERROR(s.Number("lateral_drift_y_px_per_100um", &o->lateral_drift_y_px_per_100um));
  INSPECT_RETURN_IF_ERROR(s.Number("breathing_reference_z_um", &o->breathing_reference_z_um));
  INSPECT_RETURN_IF_ERROR(s.NoUnknownKeys());
  if (o->camera_size.width <= 0 || o->camera_size.height <= 0) {
    return ConfigError(s.key("camera_width/camera_height"), "must be > 0");
  }
  if (o->camera_bit_depth != 8 && o->camera_bit_depth != 12)
    return ConfigError(s.key("camera_bit_depth"), "must be 8 or 12");
  if (o->projector_size.width <= 0 || o->projector_size.height <= 0) {
    return ConfigError(s.key("projector_width/projector_height"), "must be > 0");
  }
  INSPECT_RETURN_IF_ERROR(Positive(s.key("pixel_size_um"), o->pixel_size_um));
  if (!(o->stage_repeatability_um >= 0.0)) return ConfigError(s.key("stage_repeatability_um"), "must be >= 0");
  if (!(o->read_noise_dn >= 0.0)) return ConfigError(s.key("read_noise_dn"), "must be >= 0");
  if (!(std::abs(o->focus_breathing_percent_per_100um) <= 20.0)) {
    return ConfigError(s.key("focus_breathing_percent_per_100um"), "must be within +-20");
  }
  for (auto [key, v] : {std::pair{"lateral_drift_x_px_per_100um", o->lateral_drift_x_px_per_100um},
                        std::pair{"lateral_drift_y_px_per_100um", o->lateral_drift_y_px_per_100um}}) {
    if (!(std::abs(v) <= 100.0)) return ConfigError(s.key(key), "must be within +-100");
  }
  return Status::Ok();
}

Status ParseCamera(Section s, RigConfig* c) {
  AravisCameraOptions& o = c->camera;
  INSPECT_RETURN_IF_ERROR(s.String("device_id", &o.device_id));
  INSPECT_RETURN_IF_ERROR(s.String("serial", &o.serial));
  INSPECT_RETURN_IF_ERROR(s.String("pixel_format", &o.pixel_format));
  INSPECT_RETURN_IF_ERROR(s.Number("exposure_us", &o.exposure_us));
  INSPECT_RETURN_IF_ERROR(s.Number("gain_db", &o.gain_db));
  INSPECT_RETURN_IF_ERROR(s.Number("frame_timeout_ms", &o.frame_timeout_ms));
  INSPECT_RETURN_IF_ERROR(s.Int("n_buffers", &o.n_buffers));
  INSPECT_RETURN_IF_ERROR(s.Int("packet_size", &o.packet_size));
  INSPECT_ASSIGN_OR_RETURN(Section region, s.Object("region"));
  INSPECT_RETURN_IF_ERROR(region.Int("x", &o.region_x));
  INSPECT_RETURN_IF_ERROR(region.Int("y", &o.region_y));
  INSPECT_RETURN_IF_ERROR(region.Int("width", &o.region_width));
  INSPECT_RETURN_IF_ERROR(region.Int("height", &o.region_height));
  INSPECT_RETURN_IF_ERROR(region.NoUnknownKeys());
  INSPECT_RETURN_IF_ERROR(s.NoUnknownKeys());
  if (o.region_x < 0 || o.region_y < 0 || o.region_width < 0 || o.region_height < 0) {
    return ConfigError(region.key("x/y/width/height"), "must be >= 0");
  }
  if (!AravisPixelFormatBits(o.pixel_format).ok()) {
    return ConfigError(s.key("pixel_format"),
                       "'" + o.pixel_format + "' is not supported (Mono8, Mono10, Mono12, Mono16)");
  }
  INSPECT_RETURN_IF_ERROR(Positive(s.key("exposure_us"), o.exposure_us));
  INSPECT_RETURN_IF_ERROR(Positive(s.key("frame_timeout_ms"), o.frame_timeout_ms));
  if (o.n_buffers < 1) return ConfigError(s.key("n_buffers"), "must be >= 1");
  if (o.packet_size < 0) return ConfigError(s.key("packet_size"), "must be >= 0 (0 = negotiate)");
  return Status::Ok();
}

Status ParseStage(Section s, RigConfig* c) {
  AptStageOptions& o = c->stage;
  INSPECT_RETURN_IF_ERROR(s.String("stage_type", &o.stage_type));
  INSPECT_RETURN_IF_ERROR(s.Number("counts_per_mm", &o.counts_per_mm));
  StatusOr<AptStageType> type = LookupAptStageType(o.stage_type);
  if (!type.ok()) return ConfigError(s.key("stage_type"), type.status().message());
  o.max_z_um = type->travel_mm * 1000.0;
  INSPECT_RETURN_IF_ERROR(s.Number("min_z_um", &o.min_z_um));
  INSPECT_RETURN_IF_ERROR(s.Number("max_z_um", &o.max_z_um));
  INSPECT_RETURN_IF_ERROR(s.Number("move_timeout_ms", &o.move_timeout_ms));
  INSPECT_RETURN_IF_ERROR(s.Number("home_timeout_ms", &o.home_timeout_ms));
  INSPECT_RETURN_IF_ERROR(s.Number("settle_ms", &o.settle_ms));
  INSPECT_RETURN_IF_ERROR(s.Bool("home_on_connect", &o.home_on_connect));
  INSPECT_RETURN_IF_ERROR(s.Bool("identify_on_connect", &o.identify_on_connect));
  INSPECT_RETURN_IF_ERROR(s.Int("baud", &o.line.baud));
  INSPECT_RETURN_IF_ERROR(s.String("serial", &c->stage_usb.serial));
  INSPECT_RETURN_IF_ERROR(s.UsbId("vendor_id", &c->stage_usb.vendor_id));
  INSPECT_RETURN_IF_ERROR(s.UsbId("product_id", &c->stage_usb.product_id));
  INSPECT_RETURN_IF_ERROR(s.Int("interface", &c->stage_usb.interface_number));
  INSPECT_RETURN_IF_ERROR(s.NoUnknownKeys());
  o.line.interface_index = c->stage_usb.interface_number;
  if (o.counts_per_mm < 0.0) return ConfigError(s.key("counts_per_mm"), "must be >= 0 (0 = from stage_type)");
  if (!(o.min_z_um >= 0.0)) return ConfigError(s.key("min_z_um"), "must be >= 0");
  if (!(o.max_z_um <= type->travel_mm * 1000.0)) {
    return ConfigError(s.key("max_z_um"), "must be <= the " + o.stage_type + " travel (" +
                                              std::to_string(static_cast<int>(type->travel_mm * 1000.0)) + " µm)");
  }
  if (!(o.min_z_um < o.max_z_um)) return ConfigError(s.key("min_z_um"), "must be < max_z_um");
  INSPECT_RETURN_IF_ERROR(Positive(s.key("move_timeout_ms"), o.move_timeout_ms));
  INSPECT_RETURN_IF_ERROR(Positive(s.key("home_timeout_ms"), o.home_timeout_ms));
  if (!(o.settle_ms >= 0.0)) return ConfigError(s.key("settle_ms"), "must be >= 0");
  if (o.line.baud < 183 || o.line.baud > 3000000) return ConfigError(s.key("baud"), "must be 183..3000000");
  if (c->stage_usb.interface_number < 0) return ConfigError(s.key("interface"), "must be >= 0");
  return Status::Ok();
}

Status ParseFramebuffer(Section s, RigConfig* c) {
  FramebufferProjectorOptions& o = c->projector;
  INSPECT_RETURN_IF_ERROR(s.String("device", &o.device));
  INSPECT_ASSIGN_OR_RETURN(Section mode, s.Object("mode"));
  if (mode.present()) {
    FramebufferMode m;
    INSPECT_RETURN_IF_ERROR(mode.Int("width", &m.width));
    INSPECT_RETURN_IF_ERROR(mode.Int("height", &m.height));
    INSPECT_RETURN_IF_ERROR(mode.Int("bits_per_pixel", &m.bits_per_pixel));
    INSPECT_RETURN_IF_ERROR(mode.Int("line_length_bytes", &m.line_length_bytes));
    INSPECT_RETURN_IF_ERROR(mode.Int("x_offset", &m.x_offset));
    INSPECT_RETURN_IF_ERROR(mode.Int("y_offset", &m.y_offset));
    if (m.bits_per_pixel == 16) {  // RGB565 unless stated
      m.red = {11, 5};
      m.green = {5, 6};
      m.blue = {0, 5};
    }
    for (auto [name, field] : {std::pair<const char*, FramebufferBitfield*>{"red", &m.red},
                               {"green", &m.green},
                               {"blue", &m.blue},
                               {"transp", &m.transp}}) {
      INSPECT_ASSIGN_OR_RETURN(Section bf, mode.Object(name));
      INSPECT_RETURN_IF_ERROR(bf.Int("offset", &field->offset));
      INSPECT_RETURN_IF_ERROR(bf.Int("length", &field->length));
      INSPECT_RETURN_IF_ERROR(bf.NoUnknownKeys());
    }
    INSPECT_RETURN_IF_ERROR(mode.NoUnknownKeys());
    if (Status v = m.Validate(); !v.ok()) return Status::InvalidArgument("rig config: projector." + v.message());
    o.mode = m;
  }
  INSPECT_ASSIGN_OR_RETURN(Section region, s.Object("region"));
  INSPECT_RETURN_IF_ERROR(region.Int("x", &o.region_x));
  INSPECT_RETURN_IF_ERROR(region.Int("y", &o.region_y));
  INSPECT_RETURN_IF_ERROR(region.Int("width", &o.region_width));
  INSPECT_RETURN_IF_ERROR(region.Int("height", &o.region_height));
  INSPECT_RETURN_IF_ERROR(region.NoUnknownKeys());
  INSPECT_RETURN_IF_ERROR(s.Bool("flip_horizontal", &o.flip_horizontal));
  INSPECT_RETURN_IF_ERROR(s.Bool("flip_vertical", &o.flip_vertical));
  INSPECT_RETURN_IF_ERROR(s.NoUnknownKeys());
  if (o.device.empty()) return ConfigError(s.key("device"), "must name a framebuffer, e.g. /dev/fb1");
  if (o.region_x < 0 || o.region_y < 0 || o.region_width < 0 || o.region_height < 0) {
    return ConfigError(region.key("x/y/width/height"), "must be >= 0");
  }
  return Status::Ok();
}

}  // namespace

StatusOr<RigConfig> ParseRigConfig(const std::string& text) {
  json root;
  try {
    root = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, and out_of_range for a number overflow
    return Status::InvalidArgument(std::string("rig config: not valid JSON: ") + e.what());
  }
  if (!root.is_object()) return Status::InvalidArgument("rig config: the top level must be a JSON object");
  RigConfig c;
  Section top(&root, "");
  INSPECT_RETURN_IF_ERROR(top.String("name", &c.name));
  INSPECT_ASSIGN_OR_RETURN(Section camera, top.Object("camera"));
  INSPECT_ASSIGN_OR_RETURN(Section stage, top.Object("stage"));
  INSPECT_ASSIGN_OR_RETURN(Section projector, top.Object("projector"));
  INSPECT_RETURN_IF_ERROR(camera.String("driver", &c.camera_driver));
  INSPECT_RETURN_IF_ERROR(stage.String("driver", &c.stage_driver));
  INSPECT_RETURN_IF_ERROR(projector.String("driver", &c.projector_driver));

  const bool cam_sim = c.camera_driver == "simulated";
  const bool stage_sim = c.stage_driver == "simulated";
  const bool proj_sim = c.projector_driver == "simulated";
  if (!cam_sim && c.camera_driver != "aravis") {
    return ConfigError("camera.driver", "'" + c.camera_driver + "' is unknown (simulated, aravis)");
  }
  if (!stage_sim && c.stage_driver != "apt-usb") {
    return ConfigError("stage.driver", "'" + c.stage_driver + "' is unknown (simulated, apt-usb)");
  }
  if (!proj_sim && c.projector_driver != "framebuffer" && c.projector_driver != "none") {
    return ConfigError("projector.driver", "'" + c.projector_driver + "' is unknown (simulated, framebuffer, none)");
  }
  c.simulated = cam_sim && stage_sim && proj_sim;
  if (!c.simulated && (cam_sim || stage_sim || proj_sim)) {
    return Status::InvalidArgument("rig config: camera.driver = " + c.camera_driver +
                                   ", stage.driver = " + c.stage_driver + ", projector.driver = " + c.projector_driver +
                                   ": mixing simulated and real devices is not supported");
  }

  INSPECT_ASSIGN_OR_RETURN(Section sim, top.Object("simulation"));
  if (c.simulated) {
    INSPECT_RETURN_IF_ERROR(camera.NoUnknownKeys());
    INSPECT_RETURN_IF_ERROR(stage.NoUnknownKeys());
    INSPECT_RETURN_IF_ERROR(projector.NoUnknownKeys());
    INSPECT_RETURN_IF_ERROR(ParseSimulation(sim, &c.simulation));
    if (top.has("pixel_size_um") || top.has("scan_defaults")) {
      return ConfigError(top.has("pixel_size_um") ? "pixel_size_um" : "scan_defaults",
                         "applies to real rigs only (the simulated rig takes simulation.pixel_size_um)");
    }
    INSPECT_RETURN_IF_ERROR(top.NoUnknownKeys());
    return c;
  }
  if (sim.present()) return ConfigError("simulation", "applies only when every driver is \"simulated\"");

  if (!top.has("pixel_size_um"))
    return ConfigError("pixel_size_um", "is required for a real rig (µm per camera pixel on the specimen)");
  INSPECT_RETURN_IF_ERROR(top.Number("pixel_size_um", &c.pixel_size_um));
  INSPECT_RETURN_IF_ERROR(Positive("pixel_size_um", c.pixel_size_um));
  INSPECT_RETURN_IF_ERROR(ParseCamera(camera, &c));
  INSPECT_RETURN_IF_ERROR(ParseStage(stage, &c));
  if (c.projector_driver == "framebuffer") {
    INSPECT_RETURN_IF_ERROR(ParseFramebuffer(projector, &c));
  } else {
    INSPECT_RETURN_IF_ERROR(projector.Int("width", &c.projector_none_resolution.width));
    INSPECT_RETURN_IF_ERROR(projector.Int("height", &c.projector_none_resolution.height));
    INSPECT_RETURN_IF_ERROR(projector.NoUnknownKeys());
    if (c.projector_none_resolution.width <= 0 || c.projector_none_resolution.height <= 0) {
      return ConfigError("projector.width/height", "must be > 0");
    }
  }
  // Scan defaults: the first 100 µm of the stage travel unless stated.
  c.scan_defaults.z_start_um = c.stage.min_z_um;
  c.scan_defaults.z_end_um = std::min(c.stage.max_z_um, c.stage.min_z_um + 100.0);
  c.scan_defaults.exposure_us = c.camera.exposure_us;
  INSPECT_ASSIGN_OR_RETURN(Section scan, top.Object("scan_defaults"));
  INSPECT_RETURN_IF_ERROR(scan.Number("z_start_um", &c.scan_defaults.z_start_um));
  INSPECT_RETURN_IF_ERROR(scan.Number("z_end_um", &c.scan_defaults.z_end_um));
  INSPECT_RETURN_IF_ERROR(scan.Number("z_step_um", &c.scan_defaults.z_step_um));
  INSPECT_RETURN_IF_ERROR(scan.Number("exposure_us", &c.scan_defaults.exposure_us));
  INSPECT_RETURN_IF_ERROR(scan.Number("focus_search_step_um", &c.scan_defaults.focus_search_step_um));
  INSPECT_RETURN_IF_ERROR(scan.NoUnknownKeys());
  if (!(c.scan_defaults.focus_search_step_um >= 0.0) || !std::isfinite(c.scan_defaults.focus_search_step_um)) {
    return ConfigError("scan_defaults.focus_search_step_um", "must be >= 0 (0: 4 z steps)");
  }
  INSPECT_RETURN_IF_ERROR(Positive("scan_defaults.z_step_um", c.scan_defaults.z_step_um));
  INSPECT_RETURN_IF_ERROR(Positive("scan_defaults.exposure_us", c.scan_defaults.exposure_us));
  for (auto [key, z] : {std::pair<const char*, double>{"scan_defaults.z_start_um", c.scan_defaults.z_start_um},
                        {"scan_defaults.z_end_um", c.scan_defaults.z_end_um}}) {
    if (z < c.stage.min_z_um || z > c.stage.max_z_um)
      return ConfigError(key, "must lie within stage.min_z_um..max_z_um");
  }
  INSPECT_RETURN_IF_ERROR(top.NoUnknownKeys());
  return c;
}

StatusOr<RigConfig> LoadRigConfig(const std::filesystem::path& path) {
  std::ifstream f(path);
  if (!f) return Status::NotFound("rig config: cannot read " + path.string());
  std::stringstream ss;
  ss << f.rdbuf();
  StatusOr<RigConfig> c = ParseRigConfig(ss.str());
  if (!c.ok()) return c.status().WithContext(path.string());
  return c;
}

StatusOr<std::unique_ptr<Rig>> CreateRig(const RigConfig& config, const RigStartOptions& options) {
  if (config.simulated) {
    if (Status s = config.simulation.Validate(); !s.ok()) return s.WithContext("rig config: simulation");
    return CreateSimulatedRig(config.simulation);
  }
#if INSPECT_HAVE_DRIVERS
  std::string absent;
  auto check = [&](const Status& s) {
    if (!s.ok()) absent += (absent.empty() ? "" : "; ") + s.message();
    // Configuration mistakes discovered on contact (e.g. a region that does not fit the
    // screen) are not "absent devices": they fail even when starting degraded.
    return s.ok() || s.code() == StatusCode::kUnavailable;
  };

  auto camera = std::make_unique<AravisCamera>(config.camera);
  AravisCamera* cam = camera.get();
  Status cam_status = cam->Connect();
  if (!check(cam_status)) return cam_status;

  const UsbDeviceSelector usb = config.stage_usb;
  auto stage = std::make_unique<AptStage>(config.stage, [usb] { return OpenLibusbTransport(usb); });
  AptStage* st = stage.get();
  Status stage_status = st->Connect();
  if (!check(stage_status)) return stage_status;

  std::unique_ptr<Projector> projector;
  DeviceRig::Part projector_part;
  if (config.projector_driver == "framebuffer") {
    auto fb = std::make_unique<FramebufferProjector>(config.projector);
    FramebufferProjector* p = fb.get();
    Status fb_status = p->Connect();
    if (!check(fb_status)) return fb_status;
    projector_part.connect = [p] { return p->Connect(); };
    projector = std::move(fb);
  } else {
    projector = std::make_unique<NullProjector>(config.projector_none_resolution);
  }
  if (!absent.empty() && !options.allow_degraded) {
    return Status::Unavailable("rig " + (config.name.empty() ? std::string("(unnamed)") : "'" + config.name + "'") +
                               ": " + absent + " (start degraded to run without it)");
  }
  auto rig = std::make_unique<DeviceRig>(std::move(camera), DeviceRig::Part{[cam] { return cam->Connect(); }},
                                         std::move(stage), DeviceRig::Part{[st] { return st->Connect(); }},
                                         std::move(projector), std::move(projector_part), config.pixel_size_um,
                                         config.scan_defaults);
  return std::unique_ptr<Rig>(std::move(rig));
#else
  (void)options;
  return Status::Unimplemented("rig config selects real drivers, but this build has none (INSPECT_BUILD_DRIVERS=OFF)");
#endif
}

}  // namespace inspection
