// Renderer of the simulated rig: the image formation chain of thesis 5.1.1 (eq. 5.1-5.4).
#include "devices/sim/image_formation.h"

#include <cmath>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace inspection {

FocusBreathingModel LateralOptics::Model(cv::Size frame_size) const {
  FocusBreathingModel m;
  m.frame_size = frame_size;
  m.reference_z_um = reference_z_um;
  m.scale_change_per_100um = breathing_percent_per_100um / 100.0;
  m.shift_x_px_per_100um = drift_x_px_per_100um;
  m.shift_y_px_per_100um = drift_y_px_per_100um;
  return m;
}

Status LateralOptics::Validate() const {
  if (!(std::abs(breathing_percent_per_100um) <= 20.0)) {
    return Status::InvalidArgument("focus_breathing_percent_per_100um must be within +-20");
  }
  if (!(std::abs(drift_x_px_per_100um) <= 100.0) || !(std::abs(drift_y_px_per_100um) <= 100.0)) {
    return Status::InvalidArgument("lateral_drift_x/y_px_per_100um must be within +-100");
  }
  if (!std::isfinite(reference_z_um)) return Status::InvalidArgument("breathing_reference_z_um must be finite");
  return Status::Ok();
}

Status ImageFormationOptions::Validate() const {
  if (camera_size.width < 16 || camera_size.height < 16 || camera_size.width > 8192 || camera_size.height > 8192) {
    return Status::InvalidArgument("camera_size must be 16x16 .. 8192x8192");
  }
  if (projector_size.width < 16 || projector_size.height < 16 || projector_size.width > 8192 ||
      projector_size.height > 8192) {
    return Status::InvalidArgument("projector_size must be 16x16 .. 8192x8192");
  }
  INSPECT_RETURN_IF_ERROR(projector.Validate());
  INSPECT_RETURN_IF_ERROR(geometry.Validate());
  INSPECT_RETURN_IF_ERROR(defocus.Validate());
  INSPECT_RETURN_IF_ERROR(camera.Validate());
  INSPECT_RETURN_IF_ERROR(lateral.Validate());
  return Status::Ok();
}

ImageFormation::ImageFormation(const ImageFormationOptions& options)
    : options_(options),
      geometry_(options.geometry, options.camera_size, options.projector_size),
      prf_table_(options.projector.Table()),
      blur_(options.defocus) {
  geometry_.BuildSamplingMaps(&map_x_, &map_y_);
  // Only the part of the projector the camera sees goes through the prf each frame.
  double x0, x1, y0, y1;
  cv::minMaxLoc(map_x_, &x0, &x1);
  cv::minMaxLoc(map_y_, &y0, &y1);
  const cv::Rect full(cv::Point(0, 0), options_.projector_size);
  projector_roi_ = cv::Rect(cv::Point(static_cast<int>(std::floor(x0)) - 1, static_cast<int>(std::floor(y0)) - 1),
                            cv::Point(static_cast<int>(std::ceil(x1)) + 2, static_cast<int>(std::ceil(y1)) + 2)) &
                   full;
  if (projector_roi_.empty()) projector_roi_ = full;
  map_x_ -= projector_roi_.x;
  map_y_ -= projector_roi_.y;
  // Fixed-point maps (1/32 px): remap runs about twice as fast.
  cv::convertMaps(map_x_, map_y_, fixed_map_xy_, fixed_map_frac_, CV_16SC2);
  map_x_.release();
  map_y_.release();
}

StatusOr<std::unique_ptr<ImageFormation>> ImageFormation::Create(const ImageFormationOptions& options,
                                                                 Specimen specimen) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  std::unique_ptr<ImageFormation> f(new ImageFormation(options));
  INSPECT_RETURN_IF_ERROR(f->SetSpecimen(std::move(specimen)));
  return f;
}

Status ImageFormation::SetSpecimen(Specimen specimen) {
  for (const cv::Mat* m : {&specimen.height_um, &specimen.reflectance, &specimen.texture}) {
    if (m->type() != CV_32FC1 || m->size() != options_.camera_size) {
      return Status::InvalidArgument("specimen '" + specimen.name + "': maps must be CV_32FC1 of the camera size");
    }
  }
  specimen_ = std::move(specimen);
  surface_ = specimen_.reflectance.mul(specimen_.texture);
  return Status::Ok();
}

Status ImageFormation::ValidatePattern(const cv::Mat& pattern) const {
  if (pattern.type() != CV_8UC1 || pattern.size() != options_.projector_size) {
    return Status::InvalidArgument("pattern must be CV_8UC1 of the projector size " +
                                   std::to_string(options_.projector_size.width) + "x" +
                                   std::to_string(options_.projector_size.height) + ", got " +
                                   std::to_string(pattern.cols) + "x" + std::to_string(pattern.rows));
  }
  return Status::Ok();
}

StatusOr<cv::Mat> ImageFormation::ProjectorIrradianceOnCamera(const cv::Mat& pattern) const {
  INSPECT_RETURN_IF_ERROR(ValidatePattern(pattern));
  cv::Mat on_camera;
  ProjectorIrradianceInto(pattern, &on_camera);
  return on_camera;
}

void ImageFormation::ProjectorIrradianceInto(const cv::Mat& pattern, cv::Mat* on_camera) const {
  const cv::Mat seen = pattern(projector_roi_);
  cv::Mat irradiance(seen.size(), CV_32FC1);  // eq. 5.1
  for (int r = 0; r < seen.rows; ++r) {
    const uint8_t* p = seen.ptr<uint8_t>(r);
    float* e = irradiance.ptr<float>(r);
    for (int c = 0; c < seen.cols; ++c) e[c] = prf_table_[p[c]];
  }
  // Outside the projector's image there is no light.
  cv::remap(irradiance, *on_camera, fixed_map_xy_, fixed_map_frac_, cv::INTER_LINEAR, cv::BORDER_CONSTANT,
            cv::Scalar(0));
}

void ImageFormation::DefocusSigmaInto(double z_um, cv::Mat* sigma_out) const {
  sigma_out->create(options_.camera_size, CV_32FC1);
  cv::Mat& sigma = *sigma_out;
  const DefocusModel& d = options_.defocus;
  const float s0sq = static_cast<float>(d.in_focus_sigma_px * d.in_focus_sigma_px);
  const float k = static_cast<float>(0.5 * d.blur_radius_px_per_um);
  const float z = static_cast<float>(z_um);
  cv::parallel_for_(cv::Range(0, sigma.rows), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y) {
      const float* h = specimen_.height_um.ptr<float>(y);
      float* s = sigma.ptr<float>(y);
      for (int x = 0; x < sigma.cols; ++x) {
        const float dz = k * (h[x] - z);
        s[x] = std::sqrt(s0sq + dz * dz);
      }
    }
  });
}

StatusOr<cv::Mat> ImageFormation::CameraIrradiance(const cv::Mat& pattern, double z_um) {
  INSPECT_RETURN_IF_ERROR(ValidatePattern(pattern));
  if (!std::isfinite(z_um)) return Status::InvalidArgument("z_um must be finite");
  return CameraIrradianceScratch(pattern, z_um).clone();
}

const cv::Mat& ImageFormation::CameraIrradianceScratch(const cv::Mat& pattern, double z_um) {
  DefocusSigmaInto(z_um, &scratch_sigma_);
  ProjectorIrradianceInto(pattern, &scratch_ep_);
  // Defocus of the projected pattern on the surface. A uniform irradiance stays uniform.
  double lo = 0, hi = 0;
  cv::minMaxLoc(scratch_ep_, &lo, &hi);
  const cv::Mat* ep = &scratch_ep_;
  const BlurPlan plan = blur_.Plan(scratch_sigma_);
  if (hi - lo > 1e-5 * std::max(hi, 1e-12)) {  // float rounding of the mapping: ~1e-7
    blur_.Apply(scratch_ep_, plan, &scratch_ep_blurred_);
    ep = &scratch_ep_blurred_;
  }
  cv::multiply(*ep, surface_, scratch_es_);      // eq. 5.2
  if (options_.defocus.point_spread_imaging) {
    blur_.ApplyScatter(scratch_es_, plan, &scratch_ec_);  // defocus on the way back
  } else {
    blur_.Apply(scratch_es_, plan, &scratch_ec_);
  }
  if (!options_.lateral.active()) return scratch_ec_;
  // The image on the sensor is the specimen's through the breathing optics. Beyond the specimen
  // maps the scene continues mirrored (the camera at low magnification sees past their edge).
  cv::warpAffine(scratch_ec_, scratch_lateral_, CameraFromSpecimen(z_um), scratch_ec_.size(), cv::INTER_LANCZOS4,
                 cv::BORDER_REFLECT_101);
  return scratch_lateral_;
}

cv::Matx23d ImageFormation::CameraFromSpecimen(double z_um) const {
  return options_.lateral.Model(options_.camera_size).FrameFromReference(z_um, options_.lateral.reference_z_um);
}

StatusOr<cv::Mat> ImageFormation::Render(const cv::Mat& pattern, double z_um, double exposure_us, double gain_db,
                                         uint64_t noise_seed) {
  INSPECT_RETURN_IF_ERROR(ValidatePattern(pattern));
  if (!std::isfinite(z_um)) return Status::InvalidArgument("z_um must be finite");
  if (!(exposure_us > 0.0 && exposure_us <= 1e8)) return Status::InvalidArgument("exposure_us must be in (0, 1e8]");
  if (!(gain_db >= 0.0 && gain_db <= 48.0)) return Status::InvalidArgument("gain_db must be in [0, 48]");
  const cv::Mat& ec = CameraIrradianceScratch(pattern, z_um);
  return ExposeAndDigitise(ec, exposure_us, gain_db, options_.camera, noise_seed);
}

double ImageFormation::ExposureForMeanGrey(int projector_grey, double target_grey) const {
  const CameraResponse& cam = options_.camera;
  const double target = target_grey * cam.max_dn() / 255.0;
  const double e = options_.projector.Irradiance(projector_grey);
  // Subsample the surface; the mean grey is monotonic in exposure, so bisect in log space.
  std::vector<float> samples;
  const int step = std::max(1, static_cast<int>(std::sqrt(surface_.total() / 40000.0)));
  for (int r = 0; r < surface_.rows; r += step) {
    for (int c = 0; c < surface_.cols; c += step) samples.push_back(surface_.at<float>(r, c) * static_cast<float>(e));
  }
  auto mean_grey = [&](double exposure_us) {
    const double scale = exposure_us * cam.sensitivity_e_per_us / cam.full_well_e;
    double sum = 0;
    for (float s : samples) sum += cam.GreyForRelativeExposure(s * scale);
    return sum / samples.size();
  };
  double lo = std::log(0.1), hi = std::log(1e8);
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (mean_grey(std::exp(mid)) < target ? lo : hi) = mid;
  }
  return std::exp(0.5 * (lo + hi));
}

}  // namespace inspection
