// Calibration bundle folder: bundle.json (nlohmann-json) + float32 TIFFs + the CSC scatter
// matrix file. Every loaded model passes its Validate() before the bundle is returned.
#include "core/calibration/calibration_bundle.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

namespace inspection {
namespace fs = std::filesystem;
using nlohmann::json;

const char* CalibrationStepName(CalibrationStep step) {
  switch (step) {
    case CalibrationStep::kCameraResponse:
      return "camera_response";
    case CalibrationStep::kProjectorResponse:
      return "projector_response";
    case CalibrationStep::kGeometry:
      return "geometry";
    case CalibrationStep::kPsf:
      return "psf";
    case CalibrationStep::kScatterMatrix:
      return "scatter_matrix";
    case CalibrationStep::kIntegralPsf:
      return "integral_psf";
    case CalibrationStep::kZLinearity:
      return "z_linearity";
    case CalibrationStep::kFocusBreathing:
      return "focus_breathing";
  }
  return "unknown";
}

std::vector<CalibrationStep> AllCalibrationSteps() {
  return {CalibrationStep::kCameraResponse, CalibrationStep::kProjectorResponse,
          CalibrationStep::kGeometry,       CalibrationStep::kPsf,
          CalibrationStep::kScatterMatrix,  CalibrationStep::kIntegralPsf,
          CalibrationStep::kZLinearity,     CalibrationStep::kFocusBreathing};
}

std::vector<CalibrationStep> DefaultCalibrationSteps() {
  std::vector<CalibrationStep> steps = AllCalibrationSteps();
  steps.pop_back();  // kFocusBreathing, the last
  return steps;
}

StatusOr<CalibrationStep> ParseCalibrationStep(const std::string& name) {
  for (CalibrationStep s : AllCalibrationSteps())
    if (name == CalibrationStepName(s)) return s;
  return Status::InvalidArgument(
      "unknown calibration step '" + name +
      "' (camera_response, projector_response, geometry, psf, scatter_matrix, integral_psf, z_linearity, "
      "focus_breathing)");
}

const CalibrationStepReport* CalibrationBundle::Report(CalibrationStep step) const {
  for (const auto& r : reports)
    if (r.step == step) return &r;
  return nullptr;
}

void CalibrationBundle::SetReport(CalibrationStepReport report) {
  for (auto& r : reports)
    if (r.step == report.step) {
      r = std::move(report);
      return;
    }
  reports.push_back(std::move(report));
  std::sort(reports.begin(), reports.end(), [](const auto& a, const auto& b) { return a.step < b.step; });
}

bool CalibrationBundle::HasModel(CalibrationStep step) const {
  switch (step) {
    case CalibrationStep::kCameraResponse:
      return camera_response.has_value();
    case CalibrationStep::kProjectorResponse:
      return projector_response.has_value();
    case CalibrationStep::kGeometry:
      return geometry.has_value();
    case CalibrationStep::kPsf:
      return psf.has_value();
    case CalibrationStep::kScatterMatrix:
      return scatter.has_value();
    case CalibrationStep::kIntegralPsf:
      return integral_psf.has_value();
    case CalibrationStep::kZLinearity:
      return z_linearity.has_value();
    case CalibrationStep::kFocusBreathing:
      return focus_breathing.has_value();
  }
  return false;
}

Status CalibrationBundle::Validate() const {
  if (version < 1 || version > kCalibrationBundleVersion) {
    return Status::FailedPrecondition("bundle version " + std::to_string(version) +
                                      " is not supported (this build reads up to " +
                                      std::to_string(kCalibrationBundleVersion) + ")");
  }
  if (camera_response) INSPECT_RETURN_IF_ERROR(camera_response->Validate());
  if (projector_response) INSPECT_RETURN_IF_ERROR(projector_response->Validate());
  if (geometry) {
    INSPECT_RETURN_IF_ERROR(geometry->Validate());
    if (geometry->camera_size != camera_size || geometry->projector_size != projector_size) {
      return Status::InvalidArgument("geometry: sizes differ from the bundle's camera/projector size");
    }
  }
  if (psf) INSPECT_RETURN_IF_ERROR(psf->Validate());
  if (scatter) {
    INSPECT_RETURN_IF_ERROR(scatter->Validate());
    if (scatter->camera_size != camera_size || scatter->projector_size != projector_size) {
      return Status::InvalidArgument("scatter: sizes differ from the bundle's camera/projector size");
    }
  }
  if (integral_psf) INSPECT_RETURN_IF_ERROR(integral_psf->Validate());
  if (z_linearity && (z_linearity->bias_of_step.size() < 2 || !(z_linearity->characterised_step_um > 0.0))) {
    return Status::InvalidArgument("z_linearity: needs >= 2 table entries and a characterised step > 0");
  }
  if (focus_breathing) {
    INSPECT_RETURN_IF_ERROR(focus_breathing->Validate().WithContext("focus_breathing"));
    if (focus_breathing->frame_size != camera_size) {
      return Status::InvalidArgument("focus_breathing: frame_size differs from camera_size");
    }
  }
  return Status::Ok();
}

namespace {

Status WriteFloatTiff(const fs::path& file, const cv::Mat& m) {
  if (m.type() != CV_32FC1) return Status::Internal(file.filename().string() + ": expected CV_32FC1");
  try {
    if (!cv::imwrite(file.string(), m)) return Status::Unavailable("cannot write " + file.string());
  } catch (const cv::Exception& e) {
    return Status::Unavailable("cannot write " + file.string() + ": " + e.what());
  }
  return Status::Ok();
}

StatusOr<cv::Mat> ReadFloatTiff(const fs::path& file, cv::Size expected) {
  if (!fs::exists(file)) return Status::DataLoss(file.filename().string() + " is missing");
  cv::Mat m;
  try {
    m = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return Status::DataLoss(file.filename().string() + ": " + e.what());
  }
  if (m.empty() || m.type() != CV_32FC1) return Status::DataLoss(file.filename().string() + ": not a float32 TIFF");
  if (expected.area() > 0 && m.size() != expected) {
    return Status::DataLoss(file.filename().string() + ": size " + std::to_string(m.cols) + "x" +
                            std::to_string(m.rows) + " differs from " + std::to_string(expected.width) + "x" +
                            std::to_string(expected.height));
  }
  return m;
}

Status WriteLut(const fs::path& dir, const std::string& stem, const cv::Mat& lut) {
  cv::Mat ch[2];
  cv::split(lut, ch);
  INSPECT_RETURN_IF_ERROR(WriteFloatTiff(dir / (stem + "_x.tiff"), ch[0]));
  return WriteFloatTiff(dir / (stem + "_y.tiff"), ch[1]);
}

StatusOr<cv::Mat> ReadLut(const fs::path& dir, const std::string& stem, cv::Size size) {
  INSPECT_ASSIGN_OR_RETURN(cv::Mat x, ReadFloatTiff(dir / (stem + "_x.tiff"), size));
  INSPECT_ASSIGN_OR_RETURN(cv::Mat y, ReadFloatTiff(dir / (stem + "_y.tiff"), size));
  cv::Mat out;
  cv::merge(std::vector<cv::Mat>{x, y}, out);
  return out;
}

json SizeJson(cv::Size s) { return json{{"width", s.width}, {"height", s.height}}; }
cv::Size SizeFrom(const json& j) { return {j.at("width").get<int>(), j.at("height").get<int>()}; }

// JSON has no NaN/Inf: non-finite figures are written as null and read back as NaN.
json Num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
double NumFrom(const json& j) { return j.is_null() ? std::numeric_limits<double>::quiet_NaN() : j.get<double>(); }

}  // namespace

Status CalibrationBundle::Save(const fs::path& dir) const {
  INSPECT_RETURN_IF_ERROR(Validate());
  std::error_code ec;
  if (fs::exists(dir / kCalibrationBundleManifest, ec)) {
    return Status(StatusCode::kAlreadyExists, dir.string() + " already holds a calibration bundle");
  }
  fs::create_directories(dir, ec);
  if (ec) return Status::Unavailable("cannot create " + dir.string() + ": " + ec.message());

  json j;
  j["format"] = "inspection-calibration";
  j["version"] = version;
  j["id"] = id;
  j["created_utc"] = created_utc;
  j["rig"] = rig;
  j["camera_size"] = SizeJson(camera_size);
  j["projector_size"] = SizeJson(projector_size);
  j["camera_bit_depth"] = camera_bit_depth;
  if (camera_response) {
    const auto& c = *camera_response;
    j["camera_response"] = {{"levels", c.levels},
                            {"log_exposure", c.log_exposure},
                            {"smoothness_lambda", c.smoothness_lambda},
                            {"sample_pixel_count", c.sample_pixel_count},
                            {"image_count", c.image_count},
                            {"fit_rms_residual", Num(c.fit_rms_residual)}};
  }
  if (projector_response) {
    const auto& p = *projector_response;
    j["projector_response"] = {{"relative_irradiance", p.relative_irradiance},
                               {"measured_levels", p.measured_levels},
                               {"exposure_min_us", p.exposure_min_us},
                               {"exposure_max_us", p.exposure_max_us},
                               {"pixel_ratio_cv", Num(p.pixel_ratio_cv)}};
  }
  if (geometry) {
    const auto& g = *geometry;
    INSPECT_RETURN_IF_ERROR(WriteLut(dir, "geometry_projector_to_camera", g.projector_to_camera));
    INSPECT_RETURN_IF_ERROR(WriteLut(dir, "geometry_camera_to_projector", g.camera_to_projector));
    std::vector<double> h;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) h.push_back(g.homography(r, c));
    j["geometry"] = {{"homography", h},
                     {"grid_spacing_px", g.grid_spacing_px},
                     {"valid_projector_pixels", g.valid_projector_pixels},
                     {"camera_px_per_projector_px", Num(g.camera_px_per_projector_px)},
                     {"projector_rotation_deg", Num(g.projector_rotation_deg)},
                     {"lut_vs_homography_mean_px", Num(g.lut_vs_homography_mean_px)},
                     {"lut_vs_homography_std_px", Num(g.lut_vs_homography_std_px)},
                     {"lut_vs_homography_max_px", Num(g.lut_vs_homography_max_px)}};
  }
  if (psf) {
    json steps = json::array();
    for (size_t k = 0; k < psf->steps.size(); ++k) {
      const auto& s = psf->steps[k];
      const std::string file = "psf_" + std::to_string(k) + ".tiff";
      INSPECT_RETURN_IF_ERROR(WriteFloatTiff(dir / file, s.psf));
      steps.push_back(
          {{"defocus_um", s.defocus_um}, {"sigma_px", Num(s.sigma_px)}, {"dot_count", s.dot_count}, {"file", file}});
    }
    j["psf"] = {{"steps", steps}, {"influence_radius_px", psf->influence_radius_px}};
  }
  if (scatter) {
    const auto& s = *scatter;
    INSPECT_RETURN_IF_ERROR(WriteSparseMatrix(dir / "scatter_matrix.bin", s.a));
    INSPECT_RETURN_IF_ERROR(WriteFloatTiff(dir / "scatter_black_radiance.tiff", s.black_radiance));
    j["scatter_matrix"] = {{"file", "scatter_matrix.bin"},
                           {"black_radiance_file", "scatter_black_radiance.tiff"},
                           {"projector_black_irradiance", s.projector_black_irradiance},
                           {"patch_radius_px", s.patch_radius_px},
                           {"grid_spacing_px", s.grid_spacing_px},
                           {"non_zeros", static_cast<int64_t>(s.a.nonZeros())},
                           {"density", s.Density()}};
  }
  if (integral_psf) {
    const auto& p = *integral_psf;
    INSPECT_RETURN_IF_ERROR(WriteFloatTiff(dir / "integral_psf.tiff", p.kernel));
    j["integral_psf"] = {{"file", "integral_psf.tiff"},
                         {"regularisation", IpsfRegularisationName(p.regularisation)},
                         {"regularisation_weight", p.regularisation_weight},
                         {"integral_rms_error", Num(p.integral_rms_error)},
                         {"restored_rms_error", Num(p.restored_rms_error)},
                         {"stack_frames", p.stack_frames},
                         {"integral_noise_sigma", Num(p.integral_noise_sigma)}};
  }
  if (focus_breathing) {
    const auto& m = *focus_breathing;
    j["focus_breathing"] = {{"reference_z_um", m.reference_z_um},
                            {"frame_width", m.frame_size.width},
                            {"frame_height", m.frame_size.height},
                            {"scale_change_per_100um", m.scale_change_per_100um},
                            {"rotation_rad_per_100um", m.rotation_rad_per_100um},
                            {"shift_x_px_per_100um", m.shift_x_px_per_100um},
                            {"shift_y_px_per_100um", m.shift_y_px_per_100um},
                            {"fit_rms_px", Num(m.fit_rms_px)},
                            {"frames", m.frames}};
  }
  if (z_linearity) j["z_linearity"] = json::parse(ZLinearityToJson(*z_linearity));
  json reps = json::array();
  for (const auto& r : reports) {
    json f = json::object();
    for (const auto& [k, v] : r.figures) f[k] = Num(v);
    reps.push_back({{"step", CalibrationStepName(r.step)},
                    {"duration_s", r.duration_s},
                    {"finished_utc", r.finished_utc},
                    {"frames_captured", r.frames_captured},
                    {"figures", f},
                    {"note", r.note}});
  }
  j["reports"] = reps;

  const fs::path tmp = dir / (std::string(kCalibrationBundleManifest) + ".tmp");
  {
    std::ofstream out(tmp, std::ios::trunc);
    if (!out) return Status::Unavailable("cannot write " + tmp.string());
    out << j.dump(1) << "\n";
    if (!out) return Status::Unavailable("write failed: " + tmp.string());
  }
  fs::rename(tmp, dir / kCalibrationBundleManifest, ec);
  if (ec) return Status::Unavailable("cannot rename " + tmp.string() + ": " + ec.message());
  return Status::Ok();
}

StatusOr<CalibrationBundle> CalibrationBundle::Load(const fs::path& dir) {
  const fs::path manifest = dir / kCalibrationBundleManifest;
  std::ifstream in(manifest);
  if (!in) return Status::NotFound("no calibration bundle in " + dir.string() + " (bundle.json missing)");
  CalibrationBundle b;
  try {
    const json j = json::parse(in);
    if (j.value("format", "") != "inspection-calibration") {
      return Status::InvalidArgument("bundle.json: format must be \"inspection-calibration\"");
    }
    b.version = j.at("version").get<int>();
    if (b.version > kCalibrationBundleVersion || b.version < 1) {
      return Status::FailedPrecondition("bundle.json: version " + std::to_string(b.version) +
                                        " is not supported (this build reads up to " +
                                        std::to_string(kCalibrationBundleVersion) + ")");
    }
    b.id = j.value("id", "");
    b.created_utc = j.value("created_utc", "");
    b.rig = j.value("rig", "");
    b.camera_size = SizeFrom(j.at("camera_size"));
    b.projector_size = SizeFrom(j.at("projector_size"));
    b.camera_bit_depth = j.value("camera_bit_depth", 8);
    if (j.contains("camera_response")) {
      const json& c = j.at("camera_response");
      CameraResponseFunction r;
      r.levels = c.at("levels").get<int>();
      r.log_exposure = c.at("log_exposure").get<std::vector<double>>();
      r.smoothness_lambda = c.value("smoothness_lambda", 0.0);
      r.sample_pixel_count = c.value("sample_pixel_count", 0);
      r.image_count = c.value("image_count", 0);
      r.fit_rms_residual = NumFrom(c.at("fit_rms_residual"));
      b.camera_response = std::move(r);
    }
    if (j.contains("projector_response")) {
      const json& p = j.at("projector_response");
      ProjectorResponseFunction r;
      r.relative_irradiance = p.at("relative_irradiance").get<std::vector<double>>();
      r.measured_levels = p.value("measured_levels", std::vector<int>{});
      r.exposure_min_us = p.value("exposure_min_us", 0.0);
      r.exposure_max_us = p.value("exposure_max_us", 0.0);
      r.pixel_ratio_cv = NumFrom(p.at("pixel_ratio_cv"));
      b.projector_response = std::move(r);
    }
    if (j.contains("geometry")) {
      const json& g = j.at("geometry");
      GeometricCalibration r;
      r.projector_size = b.projector_size;
      r.camera_size = b.camera_size;
      const auto h = g.at("homography").get<std::vector<double>>();
      if (h.size() != 9) return Status::InvalidArgument("bundle.json: geometry.homography must have 9 entries");
      for (int k = 0; k < 9; ++k) r.homography(k / 3, k % 3) = h[k];
      r.grid_spacing_px = g.value("grid_spacing_px", 0);
      r.valid_projector_pixels = g.value("valid_projector_pixels", 0);
      r.camera_px_per_projector_px = NumFrom(g.at("camera_px_per_projector_px"));
      r.projector_rotation_deg = NumFrom(g.at("projector_rotation_deg"));
      r.lut_vs_homography_mean_px = NumFrom(g.at("lut_vs_homography_mean_px"));
      r.lut_vs_homography_std_px = NumFrom(g.at("lut_vs_homography_std_px"));
      r.lut_vs_homography_max_px = NumFrom(g.at("lut_vs_homography_max_px"));
      INSPECT_ASSIGN_OR_RETURN(r.projector_to_camera, ReadLut(dir, "geometry_projector_to_camera", b.projector_size));
      INSPECT_ASSIGN_OR_RETURN(r.camera_to_projector, ReadLut(dir, "geometry_camera_to_projector", b.camera_size));
      b.geometry = std::move(r);
    }
    if (j.contains("psf")) {
      const json& p = j.at("psf");
      PsfCalibration r;
      r.influence_radius_px = p.at("influence_radius_px").get<double>();
      for (const json& s : p.at("steps")) {
        PsfAtDefocus d;
        d.defocus_um = s.at("defocus_um").get<double>();
        d.sigma_px = NumFrom(s.at("sigma_px"));
        d.dot_count = s.value("dot_count", 0);
        const std::string file = s.at("file").get<std::string>();
        if (file.find('/') != std::string::npos || file.find("..") != std::string::npos) {
          return Status::InvalidArgument("bundle.json: psf file '" + file + "' must be a plain file name");
        }
        INSPECT_ASSIGN_OR_RETURN(d.psf, ReadFloatTiff(dir / file, {}));
        r.steps.push_back(std::move(d));
      }
      b.psf = std::move(r);
    }
    if (j.contains("scatter_matrix")) {
      const json& s = j.at("scatter_matrix");
      ScatterMatrix r;
      r.camera_size = b.camera_size;
      r.projector_size = b.projector_size;
      r.projector_black_irradiance = s.value("projector_black_irradiance", 0.0);
      r.patch_radius_px = s.value("patch_radius_px", 0);
      r.grid_spacing_px = s.value("grid_spacing_px", 0);
      INSPECT_ASSIGN_OR_RETURN(r.a, ReadSparseMatrix(dir / "scatter_matrix.bin"));
      INSPECT_ASSIGN_OR_RETURN(r.black_radiance, ReadFloatTiff(dir / "scatter_black_radiance.tiff", b.camera_size));
      b.scatter = std::move(r);
    }
    if (j.contains("integral_psf")) {
      const json& p = j.at("integral_psf");
      IntegralPsf r;
      const auto regularisation = ParseIpsfRegularisation(p.value("regularisation", "gradient_l2"));
      r.regularisation = regularisation.ok() ? *regularisation : IpsfRegularisation::kGradientL2;
      r.regularisation_weight = p.value("regularisation_weight", 0.0);
      r.integral_rms_error = NumFrom(p.at("integral_rms_error"));
      r.restored_rms_error = NumFrom(p.at("restored_rms_error"));
      r.stack_frames = p.value("stack_frames", 0);
      r.integral_noise_sigma = p.contains("integral_noise_sigma") ? NumFrom(p.at("integral_noise_sigma")) : 0.0;
      INSPECT_ASSIGN_OR_RETURN(r.kernel, ReadFloatTiff(dir / "integral_psf.tiff", {}));
      b.integral_psf = std::move(r);
    }
    if (j.contains("focus_breathing")) {
      const json& p = j.at("focus_breathing");
      FocusBreathingModel m;
      m.reference_z_um = p.at("reference_z_um").get<double>();
      m.frame_size = cv::Size(p.at("frame_width").get<int>(), p.at("frame_height").get<int>());
      m.scale_change_per_100um = p.at("scale_change_per_100um").get<double>();
      m.rotation_rad_per_100um = p.at("rotation_rad_per_100um").get<double>();
      m.shift_x_px_per_100um = p.at("shift_x_px_per_100um").get<double>();
      m.shift_y_px_per_100um = p.at("shift_y_px_per_100um").get<double>();
      m.fit_rms_px = NumFrom(p.at("fit_rms_px"));
      m.frames = p.value("frames", 0);
      b.focus_breathing = m;
    }
    if (j.contains("z_linearity")) {
      INSPECT_ASSIGN_OR_RETURN(ZLinearity z, ZLinearityFromJson(j.at("z_linearity").dump()));
      b.z_linearity = std::move(z);
    }
    const json reports_json = j.value("reports", json::array());
    for (const json& r : reports_json) {
      CalibrationStepReport rep;
      INSPECT_ASSIGN_OR_RETURN(rep.step, ParseCalibrationStep(r.at("step").get<std::string>()));
      rep.duration_s = r.value("duration_s", 0.0);
      rep.finished_utc = r.value("finished_utc", "");
      rep.frames_captured = r.value("frames_captured", 0);
      rep.note = r.value("note", "");
      const json figures = r.value("figures", json::object());
      for (const auto& [k, v] : figures.items()) rep.figures[k] = NumFrom(v);
      b.SetReport(std::move(rep));
    }
  } catch (const json::exception& e) {
    return Status::InvalidArgument(std::string("bundle.json: ") + e.what());
  }
  INSPECT_RETURN_IF_ERROR(b.Validate().WithContext(manifest.string()));
  return b;
}

std::string CalibrationBundle::Summary() const {
  std::ostringstream o;
  o << "calibration " << (id.empty() ? "(no id)" : id) << "  version " << version << "  created " << created_utc
    << "\n  rig: " << rig << "  camera " << camera_size.width << "x" << camera_size.height << " (" << camera_bit_depth
    << " bit)  projector " << projector_size.width << "x" << projector_size.height << "\n";
  for (CalibrationStep s : AllCalibrationSteps()) {
    o << "  " << CalibrationStepName(s) << ": " << (HasModel(s) ? "calibrated" : "missing");
    if (const auto* r = Report(s)) {
      o << "  (" << r->duration_s << " s, " << r->frames_captured << " frames, " << r->finished_utc << ")\n";
      for (const auto& [k, v] : r->figures) o << "      " << k << " = " << v << "\n";
      if (!r->note.empty()) o << "      note: " << r->note << "\n";
    } else {
      o << "\n";
    }
  }
  return o.str();
}

}  // namespace inspection
