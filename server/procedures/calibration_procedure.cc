// Calibration procedure (thesis 4.3, 5.4.1): captures for every step on a Rig, core estimators,
// figures per step. Frames per step with default options on the full-size simulated rig
// (exposure searches and the autofocus sweep of each new target included): crf 39, prf 95
// (52 levels, re-captured at half exposure while saturated), geometry 119 (black, 40 Gray code,
// 64 dot grids), PSF 36 (7 defocus steps), scatter 72 (64 dot grids, black, test pattern),
// IPSF 20 (17 stack frames).
#include "server/procedures/calibration_procedure.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "core/calibration/camera_response.h"
#include "core/calibration/geometric_calibration.h"
#include "core/calibration/projector_response.h"
#include "core/calibration/psf_calibration.h"
#include "core/calibration/scatter_matrix.h"
#include "core/registration/stack_alignment.h"
#include "server/procedures/z_linearity_calibration.h"

namespace inspection {
namespace {

using Clock = std::chrono::steady_clock;

std::string UtcNow() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// Grey value below which a fraction q of the pixels lie (8- or 16-bit single channel).
double Percentile(const cv::Mat& m, double q) {
  const int levels = m.depth() == CV_8U ? 256 : 65536;
  std::vector<int> hist(levels, 0);
  for (int y = 0; y < m.rows; ++y) {
    if (m.depth() == CV_8U) {
      const uint8_t* p = m.ptr<uint8_t>(y);
      for (int x = 0; x < m.cols; ++x) ++hist[p[x]];
    } else {
      const uint16_t* p = m.ptr<uint16_t>(y);
      for (int x = 0; x < m.cols; ++x) ++hist[p[x]];
    }
  }
  const double want = q * static_cast<double>(m.total());
  double acc = 0;
  for (int v = 0; v < levels; ++v) {
    acc += hist[v];
    if (acc >= want) return v;
  }
  return levels - 1;
}

cv::Mat Checkerboard(cv::Size size, int square_px) {
  cv::Mat p(size, CV_8UC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) p.at<uint8_t>(y, x) = ((x / square_px + y / square_px) % 2) ? 255 : 0;
  return p;
}

// Everything a step needs to drive the rig: capture with cancellation, progress, frame count.
class Session {
 public:
  Session(Rig& rig, const std::function<void(const CalibrationProgress&)>& on_progress, const std::atomic<bool>& cancel)
      : rig_(rig), on_progress_(on_progress), cancel_(cancel) {
    max_grey_ = (1 << rig.camera().bit_depth()) - 1;
  }

  Rig& rig() { return rig_; }
  int max_grey() const { return max_grey_; }
  int frames() const { return frames_; }
  cv::Size projector_size() { return rig_.projector().resolution(); }
  cv::Size camera_size() { return rig_.camera().frame_size(); }

  void BeginStep(const std::string& name, int index, int count, int items) {
    progress_ = {name, index, count, 0, items, ""};
    Report("started");
  }
  void Item(const std::string& message) {
    ++progress_.item;
    progress_.item_count = std::max(progress_.item_count, progress_.item);
    Report(message);
  }
  void Report(const std::string& message) {
    progress_.message = message;
    if (on_progress_) on_progress_(progress_);
  }

  Status CheckCancel() const { return cancel_.load() ? Status::Cancelled("calibration cancelled") : Status::Ok(); }

  StatusOr<cv::Mat> Capture(const cv::Mat& pattern, double exposure_us) {
    INSPECT_RETURN_IF_ERROR(CheckCancel());
    if (!shown_.empty() && shown_.size() == pattern.size() && cv::norm(shown_, pattern, cv::NORM_INF) == 0) {
      // Same pattern already on the display.
    } else {
      INSPECT_RETURN_IF_ERROR(rig_.projector().Show(pattern));
      shown_ = pattern.clone();
    }
    if (rig_.camera().exposure_us() != exposure_us) INSPECT_RETURN_IF_ERROR(rig_.camera().SetExposure(exposure_us));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, rig_.camera().Capture());
    ++frames_;
    return frame;
  }

  Status MoveTo(double z_um) {
    INSPECT_RETURN_IF_ERROR(CheckCancel());
    return rig_.stage().MoveTo(z_um);
  }

  // Exposure at which the q-percentile of the image of `pattern` is near target (fraction of
  // full scale). Multiplicative search; saturation divides by 4.
  StatusOr<double> AutoExposure(const cv::Mat& pattern, double q, double target_fraction, double start_us) {
    double dt = std::clamp(start_us, 1.0, 1e6);
    const double target = target_fraction * max_grey_;
    for (int it = 0; it < 12; ++it) {
      INSPECT_ASSIGN_OR_RETURN(cv::Mat f, Capture(pattern, dt));
      const double p = Percentile(f, q);
      if (p >= max_grey_ - 1) {
        dt = std::max(1.0, dt / 4);
        continue;
      }
      if (std::abs(p - target) < 0.06 * target) return dt;
      const double ratio = std::clamp(target / std::max(p, 1.0), 0.25, 8.0);
      const double next = std::clamp(dt * ratio, 1.0, 1e6);
      if (next == dt) return dt;
      dt = next;
    }
    return dt;
  }

 private:
  Rig& rig_;
  const std::function<void(const CalibrationProgress&)>& on_progress_;
  const std::atomic<bool>& cancel_;
  CalibrationProgress progress_;
  cv::Mat shown_;
  int frames_ = 0;
  int max_grey_ = 255;
};

// Restores specimen (simulated rig), camera exposure and a uniform projector on scope exit.
class RigRestorer {
 public:
  explicit RigRestorer(Rig& rig) : rig_(rig), exposure_us_(rig.camera().exposure_us()) {
    if (rig.simulation()) specimen_ = rig.simulation()->specimen();
  }
  ~RigRestorer() {
    if (rig_.simulation() && !specimen_.empty() && rig_.simulation()->specimen() != specimen_) {
      rig_.simulation()->SetSpecimen(specimen_).IgnoreError();
    }
    rig_.camera().SetExposure(exposure_us_).IgnoreError();
    rig_.projector().ShowUniform(128).IgnoreError();
  }

 private:
  Rig& rig_;
  double exposure_us_;
  std::string specimen_;
};

// Switches the simulated target and focuses on it (autofocus unless options fix focus_z_um).
// Returns the focus z. Cached per target.
class Targeting {
 public:
  Targeting(Session& s, const CalibrationOptions& o) : s_(s), o_(o) {}

  StatusOr<double> Use(const std::string& target) {
    SimulationControl* sim = s_.rig().simulation();
    if (sim && !target.empty() && sim->specimen() != target) {
      INSPECT_RETURN_IF_ERROR(sim->SetSpecimen(target));
    }
    const std::string key = sim ? sim->specimen() : std::string("real");
    auto it = focus_.find(key);
    double z = 0;
    if (std::isfinite(o_.focus_z_um)) {
      z = o_.focus_z_um;
    } else if (it != focus_.end()) {
      z = it->second;
    } else {
      INSPECT_ASSIGN_OR_RETURN(z, Autofocus());
      focus_[key] = z;
    }
    INSPECT_RETURN_IF_ERROR(s_.MoveTo(z));
    return z;
  }

 private:
  StatusOr<double> Autofocus() {
    Rig& rig = s_.rig();
    const ScanDefaults d = rig.scan_defaults();
    double lo = std::min(d.z_start_um, d.z_end_um), hi = std::max(d.z_start_um, d.z_end_um);
    lo = std::max(lo, rig.stage().min_z_um());
    hi = std::min(hi, rig.stage().max_z_um());
    const double step = d.z_step_um > 0 ? d.z_step_um : 5.0;
    if (!(hi > lo)) return Status::FailedPrecondition("autofocus: empty z range; set focus_z_um");
    const cv::Mat pattern = Checkerboard(s_.projector_size(), 1);
    INSPECT_ASSIGN_OR_RETURN(double dt, s_.AutoExposure(cv::Mat(s_.projector_size(), CV_8UC1, cv::Scalar(255)), 0.99,
                                                        0.6, rig.camera().exposure_us()));
    std::vector<double> zs, fm;
    for (double z = lo; z <= hi + 1e-9; z += step) {
      INSPECT_RETURN_IF_ERROR(s_.MoveTo(z));
      INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s_.Capture(pattern, dt));
      cv::Mat ff, lap;
      f.convertTo(ff, CV_32F);
      cv::Laplacian(ff, lap, CV_32F, 3);
      zs.push_back(z);
      fm.push_back(cv::mean(lap.mul(lap))[0]);
      s_.Report("focus sweep z = " + std::to_string(z));
    }
    const size_t best = std::max_element(fm.begin(), fm.end()) - fm.begin();
    double z = zs[best];
    if (best > 0 && best + 1 < fm.size()) {
      // Parabola through the peak and its neighbours in log focus measure (Gaussian peak).
      const double a = std::log(fm[best - 1]), b = std::log(fm[best]), c = std::log(fm[best + 1]);
      const double den = a - 2 * b + c;
      if (den < 0) z += step * 0.5 * (a - c) / den;
    }
    return z;
  }

  Session& s_;
  const CalibrationOptions& o_;
  std::map<std::string, double> focus_;
};

// --- Steps -------------------------------------------------------------------------------------

Status RunCameraResponse(Session& s, Targeting& t, const CalibrationOptions& o, CalibrationBundle& b,
                         CalibrationStepReport& rep) {
  INSPECT_RETURN_IF_ERROR(t.Use(o.simulated_target).status());
  const cv::Mat pattern(s.projector_size(), CV_8UC1, cv::Scalar(o.crf_projector_grey));
  INSPECT_ASSIGN_OR_RETURN(double mid, s.AutoExposure(pattern, 0.5, 0.5, s.rig().camera().exposure_us()));
  std::vector<cv::Mat> images;
  std::vector<double> dts;
  const int n = o.crf_exposure_count;
  for (int j = 0; j < n; ++j) {
    const double dt = std::clamp(mid * std::pow(o.crf_exposure_span, (j / double(n - 1)) - 0.5), 1.0, 1e7);
    if (!dts.empty() && std::round(dt) == dts.back()) continue;
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s.Capture(pattern, std::round(dt)));
    images.push_back(f);
    dts.push_back(std::round(dt));
    s.Item("exposure " + std::to_string(dts.back()) + " us");
  }
  CameraResponseOptions co;
  co.levels = s.max_grey() + 1;
  co.smoothness_lambda = o.crf_smoothness_lambda;
  co.sample_pixel_count = o.crf_sample_pixels;
  INSPECT_ASSIGN_OR_RETURN(CameraResponseFunction crf, EstimateCameraResponse(images, dts, co));
  rep.figures["fit_rms_residual_ln"] = crf.fit_rms_residual;
  rep.figures["sample_pixels"] = crf.sample_pixel_count;
  rep.figures["images"] = crf.image_count;
  rep.figures["exposure_min_us"] = dts.front();
  rep.figures["exposure_max_us"] = dts.back();
  rep.figures["smoothness_lambda"] = o.crf_smoothness_lambda;
  rep.figures["log_exposure_range_ln"] = crf.log_exposure.back() - crf.log_exposure.front();
  b.camera_response = std::move(crf);
  return Status::Ok();
}

Status RunProjectorResponse(Session& s, Targeting& t, const CalibrationOptions& o, CalibrationBundle& b,
                            CalibrationStepReport& rep) {
  INSPECT_RETURN_IF_ERROR(t.Use(o.simulated_target).status());
  const cv::Size ps = s.projector_size();
  // dt_min: grey 255 with its 99th percentile at 80 % of full scale.
  INSPECT_ASSIGN_OR_RETURN(
      double dt_min, s.AutoExposure(cv::Mat(ps, CV_8UC1, cv::Scalar(255)), 0.99, 0.8, s.rig().camera().exposure_us()));
  const double dt_max = std::min(dt_min * o.prf_exposure_span, 1e7);
  std::vector<int> levels;
  for (int g = 0; g < 255; g += o.prf_level_step) levels.push_back(g);
  levels.push_back(255);
  std::vector<ProjectorResponseCapture> caps;
  for (int g : levels) {
    const cv::Mat pattern(ps, CV_8UC1, cv::Scalar(g));
    double dt = std::round(ProjectorCalibrationExposureUs(g, dt_min, dt_max));
    cv::Mat f;
    // eq. 4.8 assumes a log-linear prf; halve the exposure while > 1 % of pixels saturate.
    for (int tries = 0; tries < 8; ++tries) {
      INSPECT_ASSIGN_OR_RETURN(f, s.Capture(pattern, dt));
      if (Percentile(f, 0.99) < s.max_grey() - 2 || dt <= 1) break;
      dt = std::max(1.0, std::round(dt / 2));
    }
    caps.push_back({g, dt, f});
    s.Item("grey " + std::to_string(g));
  }
  ProjectorResponseOptions po;
  if (b.geometry) {
    // Restrict to the lit area when the geometry is known.
    cv::Mat lit(b.geometry->camera_size, CV_8UC1);
    for (int y = 0; y < lit.rows; ++y)
      for (int x = 0; x < lit.cols; ++x)
        lit.at<uint8_t>(y, x) = std::isfinite(b.geometry->camera_to_projector.at<cv::Vec2f>(y, x)[0]) ? 255 : 0;
    po.roi = cv::boundingRect(lit);
  }
  INSPECT_ASSIGN_OR_RETURN(ProjectorResponseFunction prf, EstimateProjectorResponse(caps, *b.camera_response, po));
  rep.figures["levels_measured"] = static_cast<double>(prf.measured_levels.size());
  rep.figures["prf_0"] = prf.relative_irradiance[0];
  rep.figures["prf_64"] = prf.relative_irradiance[64];
  rep.figures["prf_128"] = prf.relative_irradiance[128];
  rep.figures["prf_192"] = prf.relative_irradiance[192];
  rep.figures["pixel_ratio_cv"] = prf.pixel_ratio_cv;
  rep.figures["exposure_min_us"] = prf.exposure_min_us;
  rep.figures["exposure_max_us"] = prf.exposure_max_us;
  b.projector_response = std::move(prf);
  return Status::Ok();
}

Status RunGeometry(Session& s, Targeting& t, const CalibrationOptions& o, CalibrationBundle& b,
                   CalibrationStepReport& rep) {
  INSPECT_RETURN_IF_ERROR(t.Use(o.simulated_geometry_target).status());
  const cv::Size ps = s.projector_size();
  INSPECT_ASSIGN_OR_RETURN(
      double dt, s.AutoExposure(cv::Mat(ps, CV_8UC1, cv::Scalar(255)), 0.99, 0.75, s.rig().camera().exposure_us()));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat black, s.Capture(cv::Mat::zeros(ps, CV_8UC1), dt));
  s.Item("black");
  const auto gray = MakeGrayCodePatterns(ps, o.gray_code_finest_stripe_px);
  std::vector<cv::Mat> gray_caps;
  for (size_t k = 0; k < gray.size(); ++k) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s.Capture(gray[k].pattern, dt));
    gray_caps.push_back(f);
    s.Item("gray code " + std::to_string(k + 1) + "/" + std::to_string(gray.size()));
  }
  INSPECT_ASSIGN_OR_RETURN(cv::Mat decoded, DecodeGrayCode(gray, gray_caps, ps, 0.05 * s.max_grey()));
  int decodable = 0;
  for (int y = 0; y < decoded.rows; ++y)
    for (int x = 0; x < decoded.cols; ++x) decodable += std::isfinite(decoded.at<cv::Vec2f>(y, x)[0]) ? 1 : 0;
  INSPECT_ASSIGN_OR_RETURN(cv::Matx33d coarse, CoarseHomographyFromGrayCode(decoded));
  const int sp = o.geometry_grid_spacing_px;
  std::vector<DotGridCapture> grids;
  for (int oy = 0; oy < sp; ++oy)
    for (int ox = 0; ox < sp; ++ox) {
      INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s.Capture(MakeDotGridPattern(ps, sp, ox, oy), dt));
      grids.push_back({ox, oy, f});
      s.Item("dot grid " + std::to_string(grids.size()) + "/" + std::to_string(sp * sp));
    }
  GeometricCalibrationOptions go;
  go.grid_spacing_px = sp;
  go.centroid.min_peak = 0.05 * s.max_grey();
  const auto t0 = Clock::now();
  INSPECT_ASSIGN_OR_RETURN(GeometricCalibration g, EstimateGeometricCalibration(grids, black, coarse, ps, go));
  rep.figures["estimate_seconds"] = std::chrono::duration<double>(Clock::now() - t0).count();
  rep.figures["gray_code_decoded_percent"] = 100.0 * decodable / static_cast<double>(decoded.total());
  rep.figures["valid_projector_pixels"] = g.valid_projector_pixels;
  rep.figures["lut_vs_homography_mean_px"] = g.lut_vs_homography_mean_px;
  rep.figures["lut_vs_homography_std_px"] = g.lut_vs_homography_std_px;
  rep.figures["lut_vs_homography_max_px"] = g.lut_vs_homography_max_px;
  rep.figures["camera_px_per_projector_px"] = g.camera_px_per_projector_px;
  rep.figures["projector_rotation_deg"] = g.projector_rotation_deg;
  b.geometry = std::move(g);
  return Status::Ok();
}

Status RunPsf(Session& s, Targeting& t, const CalibrationOptions& o, CalibrationBundle& b, CalibrationStepReport& rep) {
  INSPECT_ASSIGN_OR_RETURN(const double z_focus, t.Use(o.simulated_target));
  const cv::Size ps = s.projector_size();
  const GeometricCalibration& g = *b.geometry;
  const int sp = o.psf_grid_spacing_px;
  const int off = sp / 2;
  const cv::Mat dots = MakeDotGridPattern(ps, sp, off, off);
  std::vector<cv::Point2d> centres;
  for (int v = off; v < ps.height; v += sp)
    for (int u = off; u < ps.width; u += sp) {
      const cv::Vec2f c = g.projector_to_camera.at<cv::Vec2f>(v, u);
      if (std::isfinite(c[0])) centres.emplace_back(c[0], c[1]);
    }
  if (centres.empty()) return Status::FailedPrecondition("psf: no dot of the PSF grid is seen by the camera");
  std::vector<PsfCapture> caps;
  const double white_dt = s.rig().camera().exposure_us();
  for (double dz : o.psf_defocus_um) {
    INSPECT_RETURN_IF_ERROR(s.MoveTo(z_focus + dz));
    // Expose for the dots themselves: their peak falls with defocus.
    INSPECT_ASSIGN_OR_RETURN(double dt, s.AutoExposure(dots, 0.9995, 0.8, white_dt));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat black, s.Capture(cv::Mat::zeros(ps, CV_8UC1), dt));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s.Capture(dots, dt));
    PsfCapture c;
    c.defocus_um = dz;
    c.signal = b.camera_response->Radiance(f, dt) - b.camera_response->Radiance(black, dt);
    c.dot_centres = centres;
    caps.push_back(std::move(c));
    s.Item("defocus " + std::to_string(dz) + " um");
  }
  INSPECT_RETURN_IF_ERROR(s.MoveTo(z_focus));
  PsfOptions po;
  po.patch_radius_px = std::clamp(static_cast<int>(0.5 * sp * g.camera_px_per_projector_px) - 1, 3, 40);
  INSPECT_ASSIGN_OR_RETURN(PsfCalibration psf, EstimatePsf(caps, po));
  for (const auto& st : psf.steps) {
    char name[64];
    std::snprintf(name, sizeof name, "sigma_px_at_%+.1f_um", st.defocus_um);
    rep.figures[name] = st.sigma_px;
  }
  rep.figures["influence_radius_px"] = psf.influence_radius_px;
  rep.figures["two_sigma_p_px"] = 2 * psf.influence_radius_px;
  rep.figures["focus_z_um"] = z_focus;
  b.psf = std::move(psf);
  return Status::Ok();
}

Status RunScatter(Session& s, Targeting& t, const CalibrationOptions& o, CalibrationBundle& b,
                  CalibrationStepReport& rep) {
  INSPECT_RETURN_IF_ERROR(t.Use(o.simulated_target).status());
  const cv::Size ps = s.projector_size();
  const GeometricCalibration& g = *b.geometry;
  const CameraResponseFunction& crf = *b.camera_response;
  const ProjectorResponseFunction& prf = *b.projector_response;
  const int sp = o.scatter_grid_spacing_px;
  int radius = o.scatter_patch_radius_px;
  if (radius <= 0) {
    radius = b.psf ? static_cast<int>(std::ceil(2 * b.psf->influence_radius_px)) + 2
                   : static_cast<int>(std::ceil(1.5 * g.camera_px_per_projector_px)) + 2;
  }
  // One exposure for every capture: the test pattern's brightest areas (uniform 255) at 80 %.
  INSPECT_ASSIGN_OR_RETURN(
      double dt, s.AutoExposure(cv::Mat(ps, CV_8UC1, cv::Scalar(255)), 0.99, 0.8, s.rig().camera().exposure_us()));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat black, s.Capture(cv::Mat::zeros(ps, CV_8UC1), dt));
  const cv::Mat black_radiance = crf.Radiance(black, dt);
  ScatterMatrixOptions so;
  so.grid_spacing_px = sp;
  so.patch_radius_px = radius;
  so.relative_threshold = o.scatter_relative_threshold;
  so.dot_irradiance = prf.relative_irradiance[255];
  so.projector_black_irradiance = prf.relative_irradiance[0];
  INSPECT_ASSIGN_OR_RETURN(ScatterMatrixBuilder builder, ScatterMatrixBuilder::Create(g, black_radiance, so));
  double build_s = 0;
  for (int oy = 0; oy < sp; ++oy)
    for (int ox = 0; ox < sp; ++ox) {
      INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s.Capture(MakeDotGridPattern(ps, sp, ox, oy), dt));
      const auto t0 = Clock::now();
      INSPECT_RETURN_IF_ERROR(builder.Add({ox, oy, crf.Radiance(f, dt) - black_radiance}));
      build_s += std::chrono::duration<double>(Clock::now() - t0).count();
      s.Item("dot grid " + std::to_string(oy * sp + ox + 1) + "/" + std::to_string(sp * sp));
    }
  const auto t0 = Clock::now();
  INSPECT_ASSIGN_OR_RETURN(ScatterMatrix sm, builder.Finish());
  rep.figures["build_seconds"] = build_s + std::chrono::duration<double>(Clock::now() - t0).count();

  // Model error (thesis Fig. 4.21): a random block pattern, captured and predicted.
  std::mt19937 rng(static_cast<uint32_t>(o.scatter_test_seed));
  std::uniform_int_distribution<int> grey(0, 255);
  cv::Mat test(ps, CV_8UC1);
  const int blk = std::max(1, o.scatter_test_block_px);
  for (int y = 0; y < ps.height; y += blk)
    for (int x = 0; x < ps.width; x += blk)
      test(cv::Rect(x, y, std::min(blk, ps.width - x), std::min(blk, ps.height - y))).setTo(grey(rng));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat captured, s.Capture(test, dt));
  s.Item("test pattern");
  // Compared where every contributing projector pixel has a column: inside the LUT's lit area,
  // at least one patch radius from its edge.
  cv::Mat lit(g.camera_size, CV_8UC1);
  for (int y = 0; y < lit.rows; ++y)
    for (int x = 0; x < lit.cols; ++x)
      lit.at<uint8_t>(y, x) = std::isfinite(g.camera_to_projector.at<cv::Vec2f>(y, x)[0]) ? 255 : 0;
  cv::Mat mask;
  cv::erode(lit, mask, cv::getStructuringElement(cv::MORPH_RECT, {2 * radius + 1, 2 * radius + 1}));
  INSPECT_ASSIGN_OR_RETURN(ScatterPrediction pred, PredictAndCompare(sm, prf, crf, test, dt, captured, mask));
  rep.figures["non_zeros"] = static_cast<double>(sm.a.nonZeros());
  rep.figures["density"] = sm.Density();
  rep.figures["density_percent"] = 100.0 * sm.Density();
  rep.figures["patch_radius_px"] = radius;
  rep.figures["prediction_mae_percent"] = pred.mean_abs_error_percent;
  rep.figures["prediction_mae_grey"] = pred.mean_abs_error_grey;
  rep.figures["prediction_pixels"] = static_cast<double>(pred.pixel_count);
  rep.figures["memory_mb"] = (sm.a.nonZeros() * 8.0 + (sm.a.cols() + 1) * 4.0) / 1e6;
  b.scatter = std::move(sm);
  return Status::Ok();
}

Status RunIntegralPsf(Session& s, Targeting& t, const CalibrationOptions& o, CalibrationBundle& b,
                      CalibrationStepReport& rep) {
  INSPECT_ASSIGN_OR_RETURN(const double z_focus, t.Use(o.simulated_target));
  const cv::Size ps = s.projector_size();
  const cv::Mat uniform(ps, CV_8UC1, cv::Scalar(128));
  INSPECT_ASSIGN_OR_RETURN(double dt, s.AutoExposure(uniform, 0.5, 0.5, s.rig().camera().exposure_us()));
  std::vector<cv::Mat> frames;
  cv::Mat focused;
  const int n = static_cast<int>(std::floor(o.ipsf_half_range_um / o.ipsf_step_um + 1e-9));
  for (int k = -n; k <= n; ++k) {
    INSPECT_RETURN_IF_ERROR(s.MoveTo(z_focus + k * o.ipsf_step_um));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s.Capture(uniform, dt));
    if (k == 0) focused = f;
    frames.push_back(f);
    s.Item("stack frame " + std::to_string(k + n + 1) + "/" + std::to_string(2 * n + 1));
  }
  INSPECT_RETURN_IF_ERROR(s.MoveTo(z_focus));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat integral, IntegralImage(frames));
  const cv::Size cs = integral.size();
  const int rw = std::min(cs.width, o.ipsf_region_px), rh = std::min(cs.height, o.ipsf_region_px);
  const cv::Rect region((cs.width - rw) / 2, (cs.height - rh) / 2, rw, rh);
  integral = integral(region).clone();
  focused = focused(region).clone();
  IntegralPsfOptions io;
  io.radius_px = o.ipsf_radius_px;
  io.regularisation = o.ipsf_regularisation;
  io.regularisation_weight = o.ipsf_regularisation_weight;
  INSPECT_ASSIGN_OR_RETURN(IntegralPsf ipsf, EstimateIntegralPsf(integral, focused, io));
  ipsf.stack_frames = static_cast<int>(frames.size());
  rep.figures["integral_rms_error_grey"] = ipsf.integral_rms_error;
  rep.figures["restored_rms_error_grey"] = ipsf.restored_rms_error;
  rep.figures["restored_to_integral_error_ratio"] =
      ipsf.integral_rms_error > 0 ? ipsf.restored_rms_error / ipsf.integral_rms_error : 0.0;
  rep.figures["stack_frames"] = ipsf.stack_frames;
  rep.figures["kernel_radius_px"] = o.ipsf_radius_px;
  rep.figures["region_px"] = std::min(rw, rh);
  b.integral_psf = std::move(ipsf);
  return Status::Ok();
}

// Focus breathing: the textured target scanned through z around its focus; the
// frames' neighbour registrations give the model scans align with (core/registration/stack_alignment.h).
Status RunFocusBreathing(Session& s, Targeting& t, const CalibrationOptions& o, CalibrationBundle& b,
                         CalibrationStepReport& rep) {
  INSPECT_ASSIGN_OR_RETURN(const double z_focus, t.Use(o.simulated_target));
  const cv::Mat uniform(s.projector_size(), CV_8UC1, cv::Scalar(128));
  INSPECT_ASSIGN_OR_RETURN(double dt, s.AutoExposure(uniform, 0.5, 0.5, s.rig().camera().exposure_us()));
  const int n = static_cast<int>(std::floor(o.breathing_half_range_um / o.breathing_step_um + 1e-9));
  const Stage& stage = s.rig().stage();
  std::vector<cv::Mat> frames;
  std::vector<double> z_um;
  for (int k = -n; k <= n; ++k) {
    const double z = z_focus + k * o.breathing_step_um;
    if (z < stage.min_z_um() || z > stage.max_z_um()) continue;  // a target near the end of travel
    INSPECT_RETURN_IF_ERROR(s.MoveTo(z));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s.Capture(uniform, dt));
    frames.push_back(f);
    z_um.push_back(z);
    s.Item("stack frame " + std::to_string(k + n + 1) + "/" + std::to_string(2 * n + 1));
  }
  INSPECT_RETURN_IF_ERROR(s.MoveTo(z_focus));
  INSPECT_ASSIGN_OR_RETURN(
      FocusBreathingModel m,
      EstimateFocusBreathing([&](int i) -> StatusOr<cv::Mat> { return frames[static_cast<size_t>(i)]; }, z_um, {}));
  m.reference_z_um = z_focus;  // any z will do (scans use transforms between frames); focus reads best
  rep.figures["scale_change_percent_per_100um"] = 100.0 * m.scale_change_per_100um;
  rep.figures["rotation_mrad_per_100um"] = 1000.0 * m.rotation_rad_per_100um;
  rep.figures["shift_x_px_per_100um"] = m.shift_x_px_per_100um;
  rep.figures["shift_y_px_per_100um"] = m.shift_y_px_per_100um;
  rep.figures["fit_rms_px"] = m.fit_rms_px;
  rep.figures["stack_frames"] = m.frames;
  rep.figures["z_range_um"] = z_um.back() - z_um.front();
  b.focus_breathing = m;
  return Status::Ok();
}

// z linearity: a tilted flat scanned through the rig's default range at its default
// step under uniform grey, as scans would; the SFF depth's periodic error is tabulated.
Status RunZLinearity(Session& s, Targeting& t, const CalibrationOptions& o, CalibrationBundle& b,
                     CalibrationStepReport& rep) {
  INSPECT_RETURN_IF_ERROR(t.Use(o.simulated_linearity_target).status());
  const cv::Mat uniform(s.projector_size(), CV_8UC1, cv::Scalar(128));
  INSPECT_ASSIGN_OR_RETURN(double dt, s.AutoExposure(uniform, 0.5, 0.5, s.rig().camera().exposure_us()));
  const ScanDefaults d = s.rig().scan_defaults();  // the target's range on the simulated rig
  const Stage& stage = s.rig().stage();
  const double step = o.z_linearity_step_um > 0 ? o.z_linearity_step_um : d.z_step_um;
  const double lo = std::max(std::min(d.z_start_um, d.z_end_um), stage.min_z_um());
  const double hi = std::min(std::max(d.z_start_um, d.z_end_um), stage.max_z_um());
  std::vector<double> z_um;
  for (double z = lo; z <= hi + 1e-9; z += step) z_um.push_back(z);
  const int count = int(z_um.size());
  int done = 0;
  auto capture_at = [&](double z) -> StatusOr<cv::Mat> {
    INSPECT_RETURN_IF_ERROR(s.MoveTo(z));
    INSPECT_ASSIGN_OR_RETURN(cv::Mat f, s.Capture(uniform, dt));
    s.Item("stack frame " + std::to_string(++done) + "/" + std::to_string(count));
    return f;
  };
  const std::string target = s.rig().simulation() ? s.rig().simulation()->specimen() : "tilted flat";
  INSPECT_ASSIGN_OR_RETURN(ZLinearityScan scan, ScanZLinearity(capture_at, z_um, s.rig().pixel_size_um(), SffOptions(),
                                                               "calibration step z_linearity on " + target));
  rep.figures["step_um"] = scan.linearity.characterised_step_um;
  rep.figures["rms_percent_of_step"] = 100.0 * scan.linearity.Rms();
  rep.figures["max_abs_percent_of_step"] = 100.0 * scan.linearity.MaxAbs();
  rep.figures["stack_frames"] = scan.frames;
  rep.figures["fitted_percent_of_field"] = scan.valid_percent;
  b.z_linearity = std::move(scan.linearity);
  return Status::Ok();
}

}  // namespace

Status CalibrationOptions::Validate() const {
  if (crf_exposure_count < 3) return Status::InvalidArgument("crf_exposure_count must be >= 3");
  if (!(crf_exposure_span > 1)) return Status::InvalidArgument("crf_exposure_span must be > 1");
  if (crf_projector_grey < 1 || crf_projector_grey > 255)
    return Status::InvalidArgument("crf_projector_grey must be 1..255");
  if (prf_level_step < 1 || prf_level_step > 128) return Status::InvalidArgument("prf_level_step must be 1..128");
  if (!(prf_exposure_span >= 1)) return Status::InvalidArgument("prf_exposure_span must be >= 1");
  if (gray_code_finest_stripe_px < 2) return Status::InvalidArgument("gray_code_finest_stripe_px must be >= 2");
  if (geometry_grid_spacing_px < 2 || geometry_grid_spacing_px > 64) {
    return Status::InvalidArgument("geometry_grid_spacing_px must be 2..64");
  }
  if (psf_defocus_um.empty()) return Status::InvalidArgument("psf_defocus_um must not be empty");
  if (psf_grid_spacing_px < 4) return Status::InvalidArgument("psf_grid_spacing_px must be >= 4");
  if (scatter_grid_spacing_px < 2 || scatter_grid_spacing_px > 64) {
    return Status::InvalidArgument("scatter_grid_spacing_px must be 2..64");
  }
  if (scatter_patch_radius_px < 0) return Status::InvalidArgument("scatter_patch_radius_px must be >= 0");
  if (!(ipsf_step_um > 0) || !(ipsf_half_range_um >= ipsf_step_um)) {
    return Status::InvalidArgument("ipsf_step_um must be > 0 and ipsf_half_range_um >= ipsf_step_um");
  }
  if (ipsf_radius_px < 1) return Status::InvalidArgument("ipsf_radius_px must be >= 1");
  if (ipsf_region_px < 4 * ipsf_radius_px + 2) {
    return Status::InvalidArgument("ipsf_region_px must be at least 4 * ipsf_radius_px + 2");
  }
  if (!(breathing_step_um > 0) || !(breathing_half_range_um >= breathing_step_um)) {
    return Status::InvalidArgument("breathing_step_um must be > 0 and breathing_half_range_um >= breathing_step_um");
  }
  if (!(z_linearity_step_um >= 0.0) || !std::isfinite(z_linearity_step_um)) {
    return Status::InvalidArgument("z_linearity_step_um must be >= 0 (0 = the rig's default step)");
  }
  return Status::Ok();
}

StatusOr<CalibrationBundle> RunCalibration(Rig& rig, const CalibrationOptions& options,
                                           const CalibrationBundle* previous,
                                           const std::function<void(const CalibrationProgress&)>& on_progress,
                                           const std::atomic<bool>& cancel) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  std::set<CalibrationStep> wanted(options.steps.begin(), options.steps.end());
  const std::vector<CalibrationStep> all = AllCalibrationSteps();
  if (wanted.empty()) {
    const std::vector<CalibrationStep> d = DefaultCalibrationSteps();
    wanted = std::set<CalibrationStep>(d.begin(), d.end());
  }
  std::vector<CalibrationStep> steps;
  for (CalibrationStep s : all)
    if (wanted.count(s)) steps.push_back(s);

  CalibrationBundle b;
  const cv::Size cam = rig.camera().frame_size(), proj = rig.projector().resolution();
  if (previous) {
    if (previous->camera_size != cam || previous->projector_size != proj) {
      return Status::FailedPrecondition("previous calibration is for camera " +
                                        std::to_string(previous->camera_size.width) + "x" +
                                        std::to_string(previous->camera_size.height) + " / projector " +
                                        std::to_string(previous->projector_size.width) + "x" +
                                        std::to_string(previous->projector_size.height) + ", the rig differs");
    }
    b = *previous;
  }
  b.id.clear();
  b.version = kCalibrationBundleVersion;
  b.camera_size = cam;
  b.projector_size = proj;
  b.camera_bit_depth = rig.camera().bit_depth();
  const DeviceInfo ci = rig.camera().info();
  b.rig = ci.driver + " " + ci.model + " " + ci.serial + " / " + rig.projector().info().model;

  // Dependencies: available if run earlier in this request or carried over.
  auto available = [&](CalibrationStep dep, CalibrationStep before) {
    return (wanted.count(dep) && dep < before) || (previous && previous->HasModel(dep));
  };
  const std::vector<std::pair<CalibrationStep, std::vector<CalibrationStep>>> deps = {
      {CalibrationStep::kProjectorResponse, {CalibrationStep::kCameraResponse}},
      {CalibrationStep::kPsf, {CalibrationStep::kCameraResponse, CalibrationStep::kGeometry}},
      {CalibrationStep::kScatterMatrix,
       {CalibrationStep::kCameraResponse, CalibrationStep::kProjectorResponse, CalibrationStep::kGeometry}},
  };
  for (const auto& [step, needs] : deps) {
    if (!wanted.count(step)) continue;
    for (CalibrationStep d : needs) {
      if (!available(d, step)) {
        return Status::FailedPrecondition(std::string(CalibrationStepName(step)) + " needs a " +
                                          CalibrationStepName(d) +
                                          " calibration: run that step too or pass a previous bundle that has it");
      }
    }
  }

  INSPECT_RETURN_IF_ERROR(rig.CheckDevices());
  RigRestorer restore(rig);
  Session session(rig, on_progress, cancel);
  Targeting targeting(session, options);
  const int count = static_cast<int>(steps.size());
  for (int i = 0; i < count; ++i) {
    const CalibrationStep step = steps[i];
    const int sp_geo = options.geometry_grid_spacing_px, sp_sc = options.scatter_grid_spacing_px;
    const int items[] = {
        options.crf_exposure_count,
        (255 + options.prf_level_step - 1) / options.prf_level_step + 1,
        1 + static_cast<int>(MakeGrayCodePatterns(proj, options.gray_code_finest_stripe_px).size()) + sp_geo * sp_geo,
        static_cast<int>(options.psf_defocus_um.size()),
        sp_sc * sp_sc + 1,
        2 * static_cast<int>(std::floor(options.ipsf_half_range_um / options.ipsf_step_um + 1e-9)) + 1,
        0,  // z linearity: the range is known once the target is in place (items counted as they come)
        2 * static_cast<int>(std::floor(options.breathing_half_range_um / options.breathing_step_um + 1e-9)) + 1};
    session.BeginStep(CalibrationStepName(step), i, count, items[static_cast<int>(step)]);
    const int frames_before = session.frames();
    const auto t0 = Clock::now();
    CalibrationStepReport rep;
    rep.step = step;
    Status st;
    switch (step) {
      case CalibrationStep::kCameraResponse:
        st = RunCameraResponse(session, targeting, options, b, rep);
        break;
      case CalibrationStep::kProjectorResponse:
        st = RunProjectorResponse(session, targeting, options, b, rep);
        break;
      case CalibrationStep::kGeometry:
        st = RunGeometry(session, targeting, options, b, rep);
        break;
      case CalibrationStep::kPsf:
        st = RunPsf(session, targeting, options, b, rep);
        break;
      case CalibrationStep::kScatterMatrix:
        st = RunScatter(session, targeting, options, b, rep);
        break;
      case CalibrationStep::kIntegralPsf:
        st = RunIntegralPsf(session, targeting, options, b, rep);
        break;
      case CalibrationStep::kZLinearity:
        st = RunZLinearity(session, targeting, options, b, rep);
        break;
      case CalibrationStep::kFocusBreathing:
        st = RunFocusBreathing(session, targeting, options, b, rep);
        break;
    }
    if (!st.ok()) return st.WithContext(CalibrationStepName(step));
    rep.duration_s = std::chrono::duration<double>(Clock::now() - t0).count();
    rep.frames_captured = session.frames() - frames_before;
    rep.finished_utc = UtcNow();
    if (rig.simulation()) rep.note = "simulated rig, target " + rig.simulation()->specimen();
    b.SetReport(std::move(rep));
    session.Report("done");
  }
  b.created_utc = UtcNow();
  INSPECT_RETURN_IF_ERROR(b.Validate());
  return b;
}

}  // namespace inspection
