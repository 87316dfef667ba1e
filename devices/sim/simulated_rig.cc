// Simulated rig: Camera, Projector and Stage sharing one ImageFormation renderer (thesis 5.1.1),
// plus the simulation-only control (specimen choice, ground truth).
#include "devices/sim/simulated_rig.h"

#include <cmath>
#include <random>

#include "devices/sim/image_formation.h"
#include "devices/sim/specimen.h"

namespace inspection {

Status SimulatedRigOptions::Validate() const {
  if (camera_size.width < 16 || camera_size.height < 16 || camera_size.width > 8192 ||
      camera_size.height > 8192) {
    return Status::InvalidArgument("camera_size must be 16x16 .. 8192x8192");
  }
  if (camera_bit_depth != 8 && camera_bit_depth != 12) {
    return Status::InvalidArgument("camera_bit_depth must be 8 or 12");
  }
  if (projector_size.width < 16 || projector_size.height < 16 || projector_size.width > 8192 ||
      projector_size.height > 8192) {
    return Status::InvalidArgument("projector_size must be 16x16 .. 8192x8192");
  }
  if (!(pixel_size_um > 0.01 && pixel_size_um < 100.0)) {
    return Status::InvalidArgument("pixel_size_um must be in (0.01, 100)");
  }
  if (!(stage_repeatability_um >= 0.0 && stage_repeatability_um <= 100.0)) {
    return Status::InvalidArgument("stage_repeatability_um must be in [0, 100]");
  }
  if (!(read_noise_dn >= 0.0 && read_noise_dn <= 50.0)) {
    return Status::InvalidArgument("read_noise_dn must be in [0, 50]");
  }
  if (specimen.empty()) return Status::InvalidArgument("specimen must not be empty");
  return Status::Ok();
}

StatusOr<ImageFormationOptions> ImageFormationOptionsFor(const SimulatedRigOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  ImageFormationOptions f;
  f.camera_size = options.camera_size;
  f.projector_size = options.projector_size;
  f.camera.bit_depth = options.camera_bit_depth;
  f.camera.read_noise_dn8 = options.read_noise_dn;
  f.camera.shot_noise = options.shot_noise;
  // 10x / NA 0.3 objective: geometric blur radius tan(asin(0.3)) per um of defocus.
  f.defocus.blur_radius_px_per_um = std::tan(std::asin(0.3)) / options.pixel_size_um;
  INSPECT_RETURN_IF_ERROR(f.Validate());
  return f;
}

ScanDefaults ScanDefaultsFor(std::pair<double, double> z_range_um, double exposure_us) {
  ScanDefaults d;
  d.z_step_um = 5.0;
  const double margin = 4.0 * d.z_step_um;
  d.z_start_um = std::max(0.0, std::floor(z_range_um.first - margin));
  d.z_end_um = std::ceil(z_range_um.second + margin);
  d.exposure_us = exposure_us;
  return d;
}

namespace {

constexpr double kStageMinUm = 0.0;
constexpr double kStageMaxUm = 25000.0;

// State shared by the three simulated devices.
struct SimState {
  SimulatedRigOptions options;
  std::unique_ptr<ImageFormation> renderer;
  std::string specimen_name;
  std::pair<double, double> z_range_um{0.0, 0.0};
  double default_exposure_us = 10000.0;
  cv::Mat pattern;
  double stage_z_um = 0.0;  // actual position, including the repeatability error
  double exposure_us = 10000.0;
  double gain_db = 0.0;
  uint64_t frames = 0;
  std::mt19937_64 stage_rng;

  Status LoadSpecimen(const std::string& name) {
    SpecimenGrid grid{options.camera_size, options.pixel_size_um, options.seed};
    INSPECT_ASSIGN_OR_RETURN(Specimen s, MakeSpecimen(name, grid));
    double lo = 0, hi = 0;
    cv::minMaxLoc(s.height_um, &lo, &hi);
    if (renderer) {
      INSPECT_RETURN_IF_ERROR(renderer->SetSpecimen(std::move(s)));
    } else {
      INSPECT_ASSIGN_OR_RETURN(ImageFormationOptions f, ImageFormationOptionsFor(options));
      INSPECT_ASSIGN_OR_RETURN(renderer, ImageFormation::Create(f, std::move(s)));
    }
    specimen_name = name;
    z_range_um = {lo, hi};
    // Whole microseconds, like a real camera's exposure register.
    default_exposure_us = std::max(1.0, std::round(renderer->ExposureForMeanGrey(128, 128.0)));
    exposure_us = default_exposure_us;
    return Status::Ok();
  }
};

class SimulatedCamera : public Camera {
 public:
  explicit SimulatedCamera(SimState* s) : s_(s) {}
  DeviceInfo info() const override {
    return {"camera", "simulated",
            "SimCam " + std::to_string(s_->options.camera_size.width) + "x" +
                std::to_string(s_->options.camera_size.height),
            "SIM-" + std::to_string(s_->options.seed), true, "specimen " + s_->specimen_name};
  }
  cv::Size frame_size() const override { return s_->options.camera_size; }
  int bit_depth() const override { return s_->options.camera_bit_depth; }
  Status SetExposure(double exposure_us) override {
    if (!(exposure_us >= 1.0 && exposure_us <= 1e7)) {
      return Status::InvalidArgument("exposure_us must be in [1, 1e7], got " + std::to_string(exposure_us));
    }
    s_->exposure_us = exposure_us;
    return Status::Ok();
  }
  double exposure_us() const override { return s_->exposure_us; }
  Status SetGain(double gain_db) override {
    if (!(gain_db >= 0.0 && gain_db <= 24.0)) {
      return Status::InvalidArgument("gain_db must be in [0, 24], got " + std::to_string(gain_db));
    }
    s_->gain_db = gain_db;
    return Status::Ok();
  }
  StatusOr<cv::Mat> Capture() override {
    const uint64_t noise_seed = MixSeed(s_->options.seed, ++s_->frames);
    return s_->renderer->Render(s_->pattern, s_->stage_z_um, s_->exposure_us, s_->gain_db, noise_seed);
  }

 private:
  SimState* s_;
};

class SimulatedProjector : public Projector {
 public:
  explicit SimulatedProjector(SimState* s) : s_(s) {}
  DeviceInfo info() const override {
    return {"projector", "simulated",
            "SimProjector " + std::to_string(s_->options.projector_size.width) + "x" +
                std::to_string(s_->options.projector_size.height),
            "SIM-" + std::to_string(s_->options.seed), true, ""};
  }
  cv::Size resolution() const override { return s_->options.projector_size; }
  Status Show(const cv::Mat& pattern) override {
    if (pattern.type() != CV_8UC1 || pattern.size() != s_->options.projector_size) {
      return Status::InvalidArgument("pattern must be CV_8UC1 " + std::to_string(s_->options.projector_size.width) +
                                     "x" + std::to_string(s_->options.projector_size.height) + ", got " +
                                     std::to_string(pattern.cols) + "x" + std::to_string(pattern.rows));
    }
    pattern.copyTo(s_->pattern);
    return Status::Ok();
  }

 private:
  SimState* s_;
};

class SimulatedStage : public Stage {
 public:
  explicit SimulatedStage(SimState* s) : s_(s) {}
  DeviceInfo info() const override {
    return {"stage", "simulated", "SimStage z", "SIM-" + std::to_string(s_->options.seed), true, ""};
  }
  double min_z_um() const override { return kStageMinUm; }
  double max_z_um() const override { return kStageMaxUm; }
  Status Home() override {
    s_->stage_z_um = 0.0;
    return Status::Ok();
  }
  Status MoveTo(double z_um) override {
    if (!(z_um >= kStageMinUm && z_um <= kStageMaxUm)) {
      return Status::OutOfRange("z_um " + std::to_string(z_um) + " outside stage travel [0, 25000]");
    }
    const double r = s_->options.stage_repeatability_um;
    std::uniform_real_distribution<double> err(-r, r);
    s_->stage_z_um = z_um + (r > 0.0 ? err(s_->stage_rng) : 0.0);
    return Status::Ok();
  }
  StatusOr<double> position_um() override { return s_->stage_z_um; }

 private:
  SimState* s_;
};

class SimulatedRig : public Rig, public SimulationControl {
 public:
  explicit SimulatedRig(std::unique_ptr<SimState> s)
      : s_(std::move(s)), camera_(s_.get()), projector_(s_.get()), stage_(s_.get()) {}

  Camera& camera() override { return camera_; }
  Projector& projector() override { return projector_; }
  Stage& stage() override { return stage_; }
  double pixel_size_um() const override { return s_->options.pixel_size_um; }
  ScanDefaults scan_defaults() const override { return ScanDefaultsFor(s_->z_range_um, s_->default_exposure_us); }
  SimulationControl* simulation() override { return this; }

  std::vector<std::string> specimen_names() const override { return BuiltinSpecimenNames(); }
  std::string specimen() const override { return s_->specimen_name; }
  Status SetSpecimen(const std::string& name) override { return s_->LoadSpecimen(name); }
  cv::Mat GroundTruthDepthUm() const override { return s_->renderer->specimen().height_um.clone(); }
  std::pair<double, double> SpecimenZRangeUm() const override { return s_->z_range_um; }

 private:
  std::unique_ptr<SimState> s_;
  SimulatedCamera camera_;
  SimulatedProjector projector_;
  SimulatedStage stage_;
};

}  // namespace

StatusOr<std::unique_ptr<Rig>> CreateSimulatedRig(const SimulatedRigOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  auto state = std::make_unique<SimState>();
  state->options = options;
  state->stage_rng.seed(MixSeed(options.seed, 0x57A6E));
  state->pattern = cv::Mat(options.projector_size, CV_8UC1, cv::Scalar(128));
  INSPECT_RETURN_IF_ERROR(state->LoadSpecimen(options.specimen).WithContext("specimen: "));
  return std::unique_ptr<Rig>(new SimulatedRig(std::move(state)));
}

}  // namespace inspection
