// Simulated rig: Camera, Projector and Stage sharing one ImageFormation renderer (thesis 5.1.1),
// plus the simulation-only control (specimen choice, ground truth).
#include "devices/sim/simulated_rig.h"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <opencv2/imgproc.hpp>
#include <random>

#include "core/sff/z_range_search.h"
#include "devices/sim/image_formation.h"
#include "devices/sim/specimen.h"

namespace inspection {

namespace {
LateralOptics LateralOpticsOf(const SimulatedRigOptions& o) {
  LateralOptics l;
  l.breathing_percent_per_100um = o.focus_breathing_percent_per_100um;
  l.drift_x_px_per_100um = o.lateral_drift_x_px_per_100um;
  l.drift_y_px_per_100um = o.lateral_drift_y_px_per_100um;
  l.reference_z_um = o.breathing_reference_z_um;
  return l;
}
}  // namespace

Status SimulatedRigOptions::Validate() const {
  if (camera_size.width < 16 || camera_size.height < 16 || camera_size.width > 8192 || camera_size.height > 8192) {
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
  if (!(numerical_aperture >= 0.02 && numerical_aperture <= 0.95)) {
    return Status::InvalidArgument("numerical_aperture must be in [0.02, 0.95]");
  }
  if (!(stage_repeatability_um >= 0.0 && stage_repeatability_um <= 100.0)) {
    return Status::InvalidArgument("stage_repeatability_um must be in [0, 100]");
  }
  if (!(read_noise_dn >= 0.0 && read_noise_dn <= 50.0)) {
    return Status::InvalidArgument("read_noise_dn must be in [0, 50]");
  }
  if (specimen.empty()) return Status::InvalidArgument("specimen must not be empty");
  if (!(std::abs(z_scale_error) <= 0.2)) return Status::InvalidArgument("z_scale_error must be in [-0.2, 0.2]");
  if (!(std::abs(lateral_scale_error_x) <= 0.2)) {
    return Status::InvalidArgument("lateral_scale_error_x must be in [-0.2, 0.2]");
  }
  if (!(std::abs(lateral_scale_error_y) <= 0.2)) {
    return Status::InvalidArgument("lateral_scale_error_y must be in [-0.2, 0.2]");
  }
  if (!(std::abs(flatness_bow_um) <= 100.0)) return Status::InvalidArgument("flatness_bow_um must be in [-100, 100]");
  if (!(extra_noise_um >= 0.0 && extra_noise_um <= 10.0)) {
    return Status::InvalidArgument("extra_noise_um must be in [0, 10]");
  }
  if (!(extra_noise_correlation_px >= 0.5 && extra_noise_correlation_px <= 50.0)) {
    return Status::InvalidArgument("extra_noise_correlation_px must be in [0.5, 50]");
  }
  return LateralOpticsOf(*this).Validate();
}

StatusOr<ImageFormationOptions> ImageFormationOptionsFor(const SimulatedRigOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  ImageFormationOptions f;
  f.camera_size = options.camera_size;
  f.projector_size = options.projector_size;
  f.camera.bit_depth = options.camera_bit_depth;
  f.camera.read_noise_dn8 = options.read_noise_dn;
  f.camera.shot_noise = options.shot_noise;
  // Geometric blur-circle radius tan(asin(NA)) per um of defocus; diffraction-limited in-focus
  // PSF sigma ~0.21 lambda / NA (lambda 0.55 um), at least the 0.55 px of the thesis rig.
  const double na = options.numerical_aperture;
  f.defocus.blur_radius_px_per_um = std::tan(std::asin(na)) / options.pixel_size_um;
  f.defocus.in_focus_sigma_px = std::clamp(0.21 * 0.55 / na / options.pixel_size_um, 0.55, 5.0);
  f.defocus.point_spread_imaging = options.point_spread_imaging;
  f.lateral = LateralOpticsOf(options);
  INSPECT_RETURN_IF_ERROR(f.Validate());
  return f;
}

StatusOr<std::unique_ptr<ImageFormation>> CreateSimulatedRenderer(const SimulatedRigOptions& options) {
  INSPECT_ASSIGN_OR_RETURN(ImageFormationOptions f, ImageFormationOptionsFor(options));
  INSPECT_ASSIGN_OR_RETURN(
      Specimen s,
      MakeSpecimen(options.specimen, SpecimenGrid{options.camera_size, options.pixel_size_um, options.seed}));
  return ImageFormation::Create(f, std::move(s));
}

uint64_t SimulatedFrameNoiseSeed(uint64_t seed, uint64_t frame_number) { return MixSeed(seed, frame_number); }

ScanDefaults ScanDefaultsFor(std::pair<double, double> z_range_um, double exposure_us) {
  ScanDefaults d;
  d.z_step_um = 5.0;
  const double margin = 4.0 * d.z_step_um;
  d.z_start_um = std::max(0.0, std::floor(z_range_um.first - margin));
  // The end lies on the start + k * step grid, so every frame of the scan is a whole step.
  const double steps = std::ceil((z_range_um.second + margin - d.z_start_um) / d.z_step_um - 1e-9);
  d.z_end_um = d.z_start_um + std::max(2.0, steps) * d.z_step_um;
  d.exposure_us = exposure_us;
  return d;
}

cv::Mat SimulatedDepthNoiseField(const SimulatedRigOptions& options, uint64_t draw) {
  if (!(options.extra_noise_um > 0.0)) return cv::Mat();
  cv::Mat n(options.camera_size, CV_32FC1);
  cv::RNG rng(MixSeed(MixSeed(options.seed, 0x4E4F495345ull), draw) | 1u);
  rng.fill(n, cv::RNG::NORMAL, 0.0, 1.0);
  cv::GaussianBlur(n, n, cv::Size(0, 0), options.extra_noise_correlation_px, options.extra_noise_correlation_px,
                   cv::BORDER_REFLECT);
  cv::Scalar mean, stddev;
  cv::meanStdDev(n, mean, stddev);
  return (n - mean[0]) * (options.extra_noise_um / std::max(stddev[0], 1e-12));
}

namespace {

// The specimen as an instrument with the options' errors shows it (SimulatedRigOptions):
// lateral scale about the image centre on every map, then the z scale and the bow on heights.
void ApplyOpticsErrors(const SimulatedRigOptions& o, Specimen* s) {
  const cv::Size size = s->height_um.size();
  const double cx = (size.width - 1) / 2.0, cy = (size.height - 1) / 2.0;
  if (o.lateral_scale_error_x != 0.0 || o.lateral_scale_error_y != 0.0) {
    // Camera pixel (c, r) sees the true point ((c - cx) / (1 + ex) + cx, ...): a feature of
    // length L um spans (1 + ex) L / pixel_size camera pixels.
    const double sx = 1.0 / (1.0 + o.lateral_scale_error_x), sy = 1.0 / (1.0 + o.lateral_scale_error_y);
    const cv::Matx23d camera_to_true(sx, 0, cx - sx * cx, 0, sy, cy - sy * cy);
    for (cv::Mat* m : {&s->height_um, &s->reflectance, &s->texture}) {
      if (m->empty()) continue;
      cv::Mat seen;
      cv::warpAffine(*m, seen, camera_to_true, size, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_REFLECT_101);
      *m = seen;
    }
  }
  if (o.z_scale_error != 0.0) s->height_um *= 1.0 + o.z_scale_error;
  if (o.flatness_bow_um != 0.0) {
    const double r2_corner = cx * cx + cy * cy;
    for (int r = 0; r < size.height; ++r) {
      float* h = s->height_um.ptr<float>(r);
      for (int c = 0; c < size.width; ++c) {
        h[c] += float(o.flatness_bow_um * ((c - cx) * (c - cx) + (r - cy) * (r - cy)) / r2_corner);
      }
    }
  }
}

constexpr double kStageMinUm = 0.0;
constexpr double kStageMaxUm = 25000.0;

// State shared by the three simulated devices. Every device call takes `mu`, so a specimen
// switch from another thread (e.g. an RPC) cannot tear a frame being rendered.
struct SimState {
  mutable std::mutex mu;
  SimulatedRigOptions options;
  std::unique_ptr<ImageFormation> renderer;
  std::string specimen_name;
  std::pair<double, double> z_range_um{0.0, 0.0};  // including z_offset_um
  double z_offset_um = 0.0;                        // SetSpecimenZOffsetUm
  SimulatedPlacement placement;                    // SetSimulatedPlacement
  double default_exposure_us = 10000.0;
  double focus_search_step_um = 0.0;  // from the optics, ScanDefaults
  cv::Mat pattern;
  double stage_z_um = 0.0;  // actual position, including the repeatability error
  double exposure_us = 10000.0;
  double gain_db = 0.0;
  uint64_t frames = 0;
  std::mt19937_64 stage_rng;
  SimulatedFaults faults;
  cv::Mat truth_height_um;  // the specimen's true surface (with offset and placement), no errors
  Specimen seen;            // as the optics show it, before the extra noise
  int64_t noise_draw = 0;   // SimulatedDepthNoiseField draw of the current scan

  // Hands the renderer the seen specimen plus the current noise draw.
  Status ShowSeen() {
    Specimen s{seen.name, seen.height_um.clone(), seen.reflectance, seen.texture};
    if (options.extra_noise_um > 0.0) s.height_um += SimulatedDepthNoiseField(options, uint64_t(noise_draw));
    if (renderer) return renderer->SetSpecimen(std::move(s));
    INSPECT_ASSIGN_OR_RETURN(ImageFormationOptions f, ImageFormationOptionsFor(options));
    INSPECT_ASSIGN_OR_RETURN(renderer, ImageFormation::Create(f, std::move(s)));
    return Status::Ok();
  }

  Status LoadSpecimen(const std::string& name) {
    SpecimenGrid grid{options.camera_size, options.pixel_size_um, options.seed};
    INSPECT_ASSIGN_OR_RETURN(Specimen s, MakeSpecimen(name, grid));
    if (placement.dx_um != 0.0 || placement.dy_um != 0.0) {
      // The part moved on the stage: every map of it moves with it (sub-pixel, linear).
      const cv::Matx23d shift(1, 0, placement.dx_um / options.pixel_size_um, 0, 1,
                              placement.dy_um / options.pixel_size_um);
      for (cv::Mat* m : {&s.height_um, &s.reflectance, &s.texture}) {
        if (m->empty()) continue;
        cv::Mat moved;
        cv::warpAffine(*m, moved, shift, m->size(), cv::INTER_LINEAR, cv::BORDER_REFLECT_101);
        *m = moved;
      }
    }
    s.height_um += z_offset_um + placement.dz_um;
    cv::Mat truth = s.height_um.clone();
    ApplyOpticsErrors(options, &s);
    double lo = 0, hi = 0;
    cv::minMaxLoc(s.height_um, &lo, &hi);
    if (lo < kStageMinUm || hi > kStageMaxUm) {
      return Status::InvalidArgument("specimen_z_offset_um " + std::to_string(z_offset_um) + " puts specimen " + name +
                                     " at z " + std::to_string(lo) + " .. " + std::to_string(hi) +
                                     ", outside the stage travel");
    }
    Specimen previous = std::move(seen);
    seen = std::move(s);
    if (Status st = ShowSeen(); !st.ok()) {
      seen = std::move(previous);
      return st;
    }
    truth_height_um = truth;
    specimen_name = name;
    z_range_um = {lo, hi};
    // Whole microseconds, like a real camera's exposure register, within the camera's range
    // (a black user scene would otherwise ask for an endless exposure).
    default_exposure_us = std::clamp(std::round(renderer->ExposureForMeanGrey(128, 128.0)), 1.0, 1e7);
    exposure_us = default_exposure_us;
    return Status::Ok();
  }
};

class SimulatedCamera : public Camera {
 public:
  explicit SimulatedCamera(SimState* s) : s_(s) {}
  DeviceInfo info() const override {
    std::lock_guard<std::mutex> lock(s_->mu);
    const bool up = !s_->faults.camera_unplugged;
    return {"camera",
            "simulated",
            "SimCam " + std::to_string(s_->options.camera_size.width) + "x" +
                std::to_string(s_->options.camera_size.height),
            "SIM-" + std::to_string(s_->options.seed),
            up,
            up ? "specimen " + s_->specimen_name : "simulated fault: unplugged"};
  }
  cv::Size frame_size() const override { return s_->options.camera_size; }
  int bit_depth() const override { return s_->options.camera_bit_depth; }
  Status SetExposure(double exposure_us) override {
    std::lock_guard<std::mutex> lock(s_->mu);
    if (s_->faults.camera_unplugged) return Unplugged();
    if (!(exposure_us >= 1.0 && exposure_us <= 1e7)) {
      return Status::InvalidArgument("exposure_us must be in [1, 1e7], got " + std::to_string(exposure_us));
    }
    s_->exposure_us = exposure_us;
    return Status::Ok();
  }
  double exposure_us() const override {
    std::lock_guard<std::mutex> lock(s_->mu);
    return s_->exposure_us;
  }
  Status SetGain(double gain_db) override {
    std::lock_guard<std::mutex> lock(s_->mu);
    if (s_->faults.camera_unplugged) return Unplugged();
    if (!(gain_db >= 0.0 && gain_db <= 24.0)) {
      return Status::InvalidArgument("gain_db must be in [0, 24], got " + std::to_string(gain_db));
    }
    s_->gain_db = gain_db;
    return Status::Ok();
  }
  StatusOr<cv::Mat> Capture() override {
    std::lock_guard<std::mutex> lock(s_->mu);
    if (s_->faults.camera_unplugged) return Unplugged();
    if (s_->faults.camera_frame_timeouts > 0) {
      --s_->faults.camera_frame_timeouts;
      return Status::DeadlineExceeded("simulated camera: frame timeout (simulated fault)");
    }
    const uint64_t noise_seed = SimulatedFrameNoiseSeed(s_->options.seed, ++s_->frames);
    return s_->renderer->Render(s_->pattern, s_->stage_z_um, s_->exposure_us, s_->gain_db, noise_seed);
  }

 private:
  static Status Unplugged() { return Status::Unavailable("simulated camera is unplugged (simulated fault)"); }
  SimState* s_;
};

class SimulatedProjector : public Projector {
 public:
  explicit SimulatedProjector(SimState* s) : s_(s) {}
  DeviceInfo info() const override {
    const bool up = !s_->faults.projector_unplugged;
    return {"projector",
            "simulated",
            "SimProjector " + std::to_string(s_->options.projector_size.width) + "x" +
                std::to_string(s_->options.projector_size.height),
            "SIM-" + std::to_string(s_->options.seed),
            up,
            up ? "" : "simulated fault: unplugged"};
  }
  cv::Size resolution() const override { return s_->options.projector_size; }
  Status Show(const cv::Mat& pattern) override {
    std::lock_guard<std::mutex> lock(s_->mu);
    if (s_->faults.projector_unplugged) {
      return Status::Unavailable("simulated projector is unplugged (simulated fault)");
    }
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
    std::lock_guard<std::mutex> lock(s_->mu);
    const bool up = !s_->faults.stage_unplugged;
    return {"stage",      "simulated",
            "SimStage z", "SIM-" + std::to_string(s_->options.seed),
            up,           up ? "" : "simulated fault: unplugged"};
  }
  double min_z_um() const override { return kStageMinUm; }
  double max_z_um() const override { return kStageMaxUm; }
  Status Home() override {
    std::lock_guard<std::mutex> lock(s_->mu);
    if (s_->faults.stage_unplugged) return Unplugged();
    s_->stage_z_um = 0.0;
    return Status::Ok();
  }
  Status MoveTo(double z_um) override {
    if (!(z_um >= kStageMinUm && z_um <= kStageMaxUm)) {
      return Status::OutOfRange("z_um " + std::to_string(z_um) + " outside stage travel [0, 25000]");
    }
    std::lock_guard<std::mutex> lock(s_->mu);
    if (s_->faults.stage_unplugged) return Unplugged();
    if (s_->faults.stage_move_timeouts > 0) {
      --s_->faults.stage_move_timeouts;
      return Status::DeadlineExceeded("simulated stage: move timeout (simulated fault)");
    }
    if (s_->options.extra_noise_um > 0.0 && z_um < s_->stage_z_um - 1e-6) {
      // A move down starts a new scan: the next draw of the extra depth noise.
      ++s_->noise_draw;
      INSPECT_RETURN_IF_ERROR(s_->ShowSeen());
    }
    const double r = s_->options.stage_repeatability_um;
    std::uniform_real_distribution<double> err(-r, r);
    s_->stage_z_um = z_um + (r > 0.0 ? err(s_->stage_rng) : 0.0);
    return Status::Ok();
  }
  double repeatability_um() const override {
    std::lock_guard<std::mutex> lock(s_->mu);
    return s_->options.stage_repeatability_um;
  }
  StatusOr<double> position_um() override {
    std::lock_guard<std::mutex> lock(s_->mu);
    if (s_->faults.stage_unplugged) return Unplugged();
    return s_->stage_z_um;
  }

 private:
  static Status Unplugged() { return Status::Unavailable("simulated stage is unplugged (simulated fault)"); }
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
  ScanDefaults scan_defaults() const override {
    std::lock_guard<std::mutex> lock(s_->mu);
    // The unshifted range: the rig's default range does not know where a part was placed.
    ScanDefaults d = ScanDefaultsFor(
        {s_->z_range_um.first - s_->z_offset_um, s_->z_range_um.second - s_->z_offset_um}, s_->default_exposure_us);
    d.focus_search_step_um = s_->focus_search_step_um;
    return d;
  }
  SimulationControl* simulation() override { return this; }

  std::vector<std::string> specimen_names() const override {
    std::vector<std::string> names = BuiltinSpecimenNames();
    if (s_->options.material_measures) {
      for (const std::string& n : MaterialMeasureSpecimenNames()) names.push_back(n);
    }
    return names;
  }
  std::string specimen() const override {
    std::lock_guard<std::mutex> lock(s_->mu);
    return s_->specimen_name;
  }
  Status SetSpecimen(const std::string& name) override {
    std::lock_guard<std::mutex> lock(s_->mu);
    return s_->LoadSpecimen(name);
  }
  Status SetSpecimenZOffsetUm(double offset_um) override {
    if (!std::isfinite(offset_um)) return Status::InvalidArgument("specimen_z_offset_um must be finite");
    std::lock_guard<std::mutex> lock(s_->mu);
    const double previous = s_->z_offset_um;
    s_->z_offset_um = offset_um;
    Status st = s_->LoadSpecimen(s_->specimen_name);
    if (!st.ok()) s_->z_offset_um = previous;  // the loaded specimen is untouched on error
    return st;
  }
  Status SetPlacement(const SimulatedPlacement& p) {
    std::lock_guard<std::mutex> lock(s_->mu);
    const SimulatedPlacement previous = s_->placement;
    s_->placement = p;
    Status st = s_->LoadSpecimen(s_->specimen_name);
    if (!st.ok()) s_->placement = previous;  // the loaded specimen is untouched on error
    return st;
  }
  void SetFaults(const SimulatedFaults& faults) {
    std::lock_guard<std::mutex> lock(s_->mu);
    s_->faults = faults;
  }

  cv::Mat GroundTruthDepthUm() const override {
    std::lock_guard<std::mutex> lock(s_->mu);
    return s_->truth_height_um.clone();
  }
  std::vector<MaterialMeasure> material_measures() const override {
    return s_->options.material_measures ? SimulatedMaterialMeasures() : std::vector<MaterialMeasure>{};
  }
  int64_t noise_draw() const {
    std::lock_guard<std::mutex> lock(s_->mu);
    return s_->noise_draw;
  }
  StatusOr<cv::Mat> GroundTruthTexture(const cv::Mat& pattern, double exposure_us) const override {
    Specimen flat;
    SimulatedRigOptions clean;
    double gain_db = 0.0;
    {
      std::lock_guard<std::mutex> lock(s_->mu);
      const Specimen& s = s_->renderer->specimen();
      // Every point at height 0 and the stage at 0: in focus everywhere (defocus by |h - z|).
      flat = {s.name, cv::Mat(s.height_um.size(), CV_32FC1, cv::Scalar(0.0f)), s.reflectance.clone(),
              s.texture.clone()};
      clean = s_->options;
      gain_db = s_->gain_db;
    }
    // A renderer of its own: the rig's keeps its scratch buffers and noise untouched.
    clean.read_noise_dn = 0.0;
    clean.shot_noise = false;
    INSPECT_ASSIGN_OR_RETURN(ImageFormationOptions options, ImageFormationOptionsFor(clean));
    INSPECT_ASSIGN_OR_RETURN(std::unique_ptr<ImageFormation> renderer,
                             ImageFormation::Create(options, std::move(flat)));
    return renderer->Render(pattern, 0.0, exposure_us, gain_db, 1);
  }
  cv::Mat GroundTruthInCameraGridUm(double z_um) const override {
    std::lock_guard<std::mutex> lock(s_->mu);
    const cv::Mat& h = s_->truth_height_um;
    if (!s_->renderer->options().lateral.active()) return h.clone();
    cv::Mat out;
    cv::warpAffine(h, out, s_->renderer->CameraFromSpecimen(z_um), h.size(), cv::INTER_NEAREST, cv::BORDER_REFLECT_101);
    return out;
  }
  std::pair<double, double> SpecimenZRangeUm() const override {
    std::lock_guard<std::mutex> lock(s_->mu);
    return s_->z_range_um;
  }

 private:
  std::unique_ptr<SimState> s_;
  SimulatedCamera camera_;
  SimulatedProjector projector_;
  SimulatedStage stage_;
};

}  // namespace

Status SetSimulatedFaults(Rig& rig, const SimulatedFaults& faults) {
  auto* sim = dynamic_cast<SimulatedRig*>(&rig);
  if (sim == nullptr) return Status::InvalidArgument("rig: not a simulated rig");
  if (faults.camera_frame_timeouts < 0 || faults.stage_move_timeouts < 0) {
    return Status::InvalidArgument("faults: timeout counts must be >= 0");
  }
  sim->SetFaults(faults);
  return Status::Ok();
}

Status SetSimulatedPlacement(Rig& rig, const SimulatedPlacement& placement) {
  auto* sim = dynamic_cast<SimulatedRig*>(rig.simulation());
  if (sim == nullptr) return Status::InvalidArgument("rig: not a simulated rig");
  if (!std::isfinite(placement.dx_um) || !std::isfinite(placement.dy_um) || !std::isfinite(placement.dz_um)) {
    return Status::InvalidArgument("placement: dx_um, dy_um and dz_um must be finite");
  }
  return sim->SetPlacement(placement);
}

SimulatedPlacement RandomSimulatedPlacement(uint64_t seed, uint64_t draw, double sigma_xy_um, double sigma_z_um) {
  // Its own stream per draw (not the stage's), so a study's placements do not depend on how many
  // moves came before.
  std::seed_seq seq{uint32_t(seed), uint32_t(seed >> 32), uint32_t(draw), uint32_t(draw >> 32), 0x706c6163u};
  std::mt19937_64 rng(seq);
  std::normal_distribution<double> unit(0.0, 1.0);
  SimulatedPlacement p;
  p.dx_um = sigma_xy_um * unit(rng);
  p.dy_um = sigma_xy_um * unit(rng);
  p.dz_um = sigma_z_um * unit(rng);
  return p;
}

int64_t SimulatedNoiseDraw(Rig& rig) {
  auto* sim = dynamic_cast<SimulatedRig*>(rig.simulation());
  return sim != nullptr ? sim->noise_draw() : -1;
}

cv::Mat GroundTruthInCameraGrid(Rig& rig, double z_um) {
  // Through simulation(): a rig wrapping the simulated one (the server's) forwards it.
  SimulationControl* control = rig.simulation();
  return control != nullptr ? control->GroundTruthInCameraGridUm(z_um) : cv::Mat();
}

StatusOr<std::unique_ptr<Rig>> CreateSimulatedRig(const SimulatedRigOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  auto state = std::make_unique<SimState>();
  state->options = options;
  state->stage_rng.seed(MixSeed(options.seed, 0x57A6E));
  state->pattern = cv::Mat(options.projector_size, CV_8UC1, cv::Scalar(128));
  {
    INSPECT_ASSIGN_OR_RETURN(ImageFormationOptions f, ImageFormationOptionsFor(options));
    state->focus_search_step_um =
        SearchPatternCoarseStepUm(f.defocus.blur_radius_px_per_um, f.geometry.camera_px_per_projector_px);
  }
  INSPECT_RETURN_IF_ERROR(state->LoadSpecimen(options.specimen).WithContext("specimen"));
  return std::unique_ptr<Rig>(new SimulatedRig(std::move(state)));
}

}  // namespace inspection
