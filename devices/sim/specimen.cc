// Built-in specimens modelled on the thesis's (6.1.1, 6.2.1) and user scenes from scene.json:
// height (ground truth), reflectance (eq. 5.2) and texture on the camera pixel grid.
#include "devices/sim/specimen.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "devices/sim/radiometry.h"

namespace inspection {
namespace {

constexpr double kBaseHeightUm = 200.0;
constexpr double kDeg = CV_PI / 180.0;
// Largest surface tilt (deg, 1/e) at which a specular surface still reflects the coaxial
// illumination into the objective (NA 0.3: asin(0.3) / 2 ~ 8.7 degrees).
constexpr double kSpecularAcceptanceDeg = 8.0;

struct Grid {
  cv::Size size;
  double px_um;
  uint64_t seed;
  double width_um() const { return size.width * px_um; }
  double height_um() const { return size.height * px_um; }
  // Physical position of the pixel centre relative to the image centre.
  double x_um(int col) const { return (col - (size.width - 1) / 2.0) * px_um; }
  double y_um(int row) const { return (row - (size.height - 1) / 2.0) * px_um; }
};

cv::Mat Fill(const Grid& g, const std::function<float(double, double)>& f) {
  cv::Mat m(g.size, CV_32FC1);
  for (int r = 0; r < g.size.height; ++r) {
    float* p = m.ptr<float>(r);
    const double y = g.y_um(r);
    for (int c = 0; c < g.size.width; ++c) p[c] = f(g.x_um(c), y);
  }
  return m;
}

// Zero-mean, unit-variance Gaussian noise smoothed with (sigma_x, sigma_y) camera pixels.
cv::Mat SmoothNoise(const Grid& g, uint64_t stream, double sigma_x, double sigma_y) {
  cv::Mat n(g.size, CV_32FC1);
  cv::RNG rng(MixSeed(g.seed, stream) | 1u);
  rng.fill(n, cv::RNG::NORMAL, 0.0, 1.0);
  cv::GaussianBlur(n, n, cv::Size(0, 0), sigma_x, sigma_y, cv::BORDER_REFLECT);
  cv::Scalar mean, stddev;
  cv::meanStdDev(n, mean, stddev);
  n = (n - mean[0]) / std::max(stddev[0], 1e-12);
  return n;
}

// Log-normal texture with mean 1: fine grain (contrast fine_log) plus a coarse mottling.
cv::Mat Texture(const Grid& g, uint64_t stream, double fine_log, double coarse_log, double fine_sigma_x = 1.0,
                double fine_sigma_y = 1.0) {
  cv::Mat t = fine_log * SmoothNoise(g, stream, fine_sigma_x, fine_sigma_y) +
              coarse_log * SmoothNoise(g, stream + 1000, 8.0, 8.0);
  cv::exp(t, t);
  t /= cv::mean(t)[0];
  return t;
}

// Tilt of the surface normal from the optical axis (radians), from the height map.
cv::Mat TiltRad(const cv::Mat& height_um, double px_um) {
  cv::Mat gx, gy;
  cv::Sobel(height_um, gx, CV_32F, 1, 0, 3, 1.0 / (8.0 * px_um), 0, cv::BORDER_REPLICATE);
  cv::Sobel(height_um, gy, CV_32F, 0, 1, 3, 1.0 / (8.0 * px_um), 0, cv::BORDER_REPLICATE);
  cv::Mat mag, tilt(height_um.size(), CV_32FC1);
  cv::magnitude(gx, gy, mag);
  for (int r = 0; r < mag.rows; ++r) {
    for (int c = 0; c < mag.cols; ++c) tilt.at<float>(r, c) = std::atan(mag.at<float>(r, c));
  }
  return tilt;
}

// Diffuse (Lambertian, cos tilt) and specular (coaxial acceptance) reflectance factors.
cv::Mat Lambert(const cv::Mat& tilt) {
  cv::Mat out(tilt.size(), CV_32FC1);
  tilt.forEach<float>([&](const float& t, const int* pos) { out.at<float>(pos[0], pos[1]) = std::cos(t); });
  return out;
}
cv::Mat SpecularAcceptance(const cv::Mat& tilt) {
  cv::Mat out(tilt.size(), CV_32FC1);
  const double t0 = kSpecularAcceptanceDeg * kDeg;
  tilt.forEach<float>([&](const float& t, const int* pos) {
    out.at<float>(pos[0], pos[1]) = static_cast<float>(std::exp(-(t / t0) * (t / t0)));
  });
  return out;
}

double SmoothStep(double e0, double e1, double v) {
  const double t = std::clamp((v - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

Specimen TexturedPlane(const Grid& g, const std::string& name, double tilt_deg) {
  Specimen s;
  s.name = name;
  const double slope = std::tan(tilt_deg * kDeg), half_w = g.width_um() / 2.0;
  s.height_um = Fill(g, [&](double x, double) { return kBaseHeightUm + (x + half_w) * slope; });
  s.reflectance = 0.5 * Lambert(TiltRad(s.height_um, g.px_um));
  s.texture = Texture(g, 1, 0.35, 0.15);
  return s;
}

Specimen Step1um(const Grid& g) {
  Specimen s;
  s.name = "step1um";
  s.height_um = Fill(g, [&](double x, double) { return kBaseHeightUm + (x >= 0.0 ? 1.0 : 0.0); });
  s.reflectance = cv::Mat(g.size, CV_32FC1, cv::Scalar(0.5));
  s.texture = Texture(g, 2, 0.35, 0.15);
  return s;
}

// Ground tungsten carbide: diffuse grey with grinding marks along the camera y axis.
cv::Mat GroundMetalTexture(const Grid& g, uint64_t stream) {
  cv::Mat iso = Texture(g, stream, 0.25, 0.1);
  cv::Mat streaks = Texture(g, stream + 7, 0.3, 0.0, 0.8, 10.0);
  cv::Mat t = iso.mul(streaks);
  return t / cv::mean(t)[0];
}

Specimen Wedge(const Grid& g) {
  Specimen s;
  s.name = "wedge";
  const double half_w = g.width_um() / 2.0, slope = std::tan(30.0 * kDeg);  // 120 degree ridge
  s.height_um = Fill(g, [&](double x, double) { return kBaseHeightUm + (half_w - std::abs(x)) * slope; });
  s.reflectance = 0.35 * Lambert(TiltRad(s.height_um, g.px_um));
  s.texture = GroundMetalTexture(g, 3);
  return s;
}

Specimen Chamfer(const Grid& g) {
  Specimen s;
  s.name = "chamfer";
  // P1 (top) | P2 at 60 degrees (P1-P2 120 degrees) over a tenth of the field | P3 (bottom).
  const double x1 = -0.05 * g.width_um(), x2 = 0.05 * g.width_um();
  const double drop = (x2 - x1) * std::tan(60.0 * kDeg);
  s.height_um = Fill(g, [&](double x, double) {
    if (x <= x1) return kBaseHeightUm + drop;
    if (x >= x2) return kBaseHeightUm;
    return kBaseHeightUm + drop * (x2 - x) / (x2 - x1);
  });
  s.reflectance = 0.35 * Lambert(TiltRad(s.height_um, g.px_um));
  s.texture = GroundMetalTexture(g, 4);
  return s;
}

Specimen Cutter(const Grid& g) {
  Specimen s;
  s.name = "cutter";
  const double w = g.width_um(), edge_x = 0.2 * w, land_x = edge_x - 0.14 * w;
  const double rake = std::tan(3.0 * kDeg), flank = std::tan(25.0 * kDeg);
  const double edge_h = std::max((edge_x + w / 2.0) * rake, (w / 2.0 - edge_x) * flank);
  s.height_um = Fill(g, [&](double x, double) {
    return kBaseHeightUm + edge_h - (x < edge_x ? (edge_x - x) * rake : (x - edge_x) * flank);
  });
  const cv::Mat tilt = TiltRad(s.height_um, g.px_um);
  const cv::Mat lambert = Lambert(tilt), specular = SpecularAcceptance(tilt);
  // Glints: the top few percent of a smooth random field on the rake face.
  const cv::Mat glint_field = SmoothNoise(g, 5, 3.0, 3.0);
  const cv::Mat ground = GroundMetalTexture(g, 6), polished = Texture(g, 8, 0.05, 0.02);
  s.reflectance.create(g.size, CV_32FC1);
  s.texture.create(g.size, CV_32FC1);
  for (int r = 0; r < g.size.height; ++r) {
    for (int c = 0; c < g.size.width; ++c) {
      const double x = g.x_um(c);
      const bool land = x >= land_x && x < edge_x;
      const bool glint = x < land_x && glint_field.at<float>(r, c) > 1.8f;
      if (land || glint) {  // polished: specular-like, ~20x the ground metal
        s.reflectance.at<float>(r, c) = 5.0f * specular.at<float>(r, c) + 0.05f;
        s.texture.at<float>(r, c) = polished.at<float>(r, c);
      } else {
        s.reflectance.at<float>(r, c) = 0.25f * lambert.at<float>(r, c);
        s.texture.at<float>(r, c) = ground.at<float>(r, c);
      }
    }
  }
  return s;
}

Specimen Lens(const Grid& g) {
  Specimen s;
  s.name = "lens";
  const double half_w = g.width_um() / 2.0, rc = 3.0 * g.width_um();  // cylinder radius
  const double rim = std::sqrt(rc * rc - half_w * half_w);
  s.height_um = Fill(g, [&](double x, double) { return kBaseHeightUm + std::sqrt(rc * rc - x * x) - rim; });
  // Glass: ~4 % Fresnel reflection where the surface faces the objective plus faint scatter.
  s.reflectance = 0.04 * SpecularAcceptance(TiltRad(s.height_um, g.px_um)) + 0.01;
  s.texture = Texture(g, 9, 0.0, 0.01);  // only a faint, very smooth mottling: no focus signal
  return s;
}

Specimen Mirror(const Grid& g) {
  Specimen s;
  s.name = "mirror";
  const double tx = std::tan(0.3 * kDeg), ty = std::tan(0.2 * kDeg);
  const double hw = g.width_um() / 2.0, hh = g.height_um() / 2.0;
  s.height_um = Fill(g, [&](double x, double y) { return kBaseHeightUm + (x + hw) * tx + (y + hh) * ty; });
  s.reflectance = 0.9 * SpecularAcceptance(TiltRad(s.height_um, g.px_um));
  s.texture = Texture(g, 10, 0.0, 0.005);
  return s;
}

Specimen Coin(const Grid& g) {
  Specimen s;
  s.name = "coin";
  // Proof-like coin region: a mirror-polished field (specular, ~17x the relief, only faint
  // scratches) and a frosted raised relief (diffuse, textured, dim) covering a little over half
  // of the view: a large disc, a bar across and a bar down, with sloped (dark) flanks. Relief
  // 20 um high on a field tilted 0.5 degrees. Uniform light either saturates the field or
  // underexposes the relief, and the field has almost no texture.
  const double m = std::min(g.width_um(), g.height_um());
  const double disc_r = 0.42 * m, bar_w = 0.12 * m, flank = 0.02 * m;
  const double relief_um = 20.0, tilt = std::tan(0.5 * kDeg), hw = g.width_um() / 2.0;
  cv::Mat relief = Fill(g, [&](double x, double y) {
    const double d_disc = std::hypot(x + 0.05 * m, y) - disc_r;
    const double d_bar1 = std::max(std::abs(y - 0.1 * m) - bar_w / 2.0, std::abs(x) - 0.45 * g.width_um());
    const double d_bar2 = std::max(std::abs(x - 0.3 * g.width_um()) - bar_w / 2.0, std::abs(y) - 0.45 * g.height_um());
    const double d = std::min({d_disc, d_bar1, d_bar2});
    return static_cast<float>(1.0 - SmoothStep(-flank / 2.0, flank / 2.0, d));
  });
  s.height_um = Fill(g, [&](double x, double) { return kBaseHeightUm + (x + hw) * tilt; }) + relief_um * relief;
  const cv::Mat specular = SpecularAcceptance(TiltRad(s.height_um, g.px_um));
  const cv::Mat frosted = Texture(g, 11, 0.3, 0.1), scratches = Texture(g, 12, 0.03, 0.0, 0.7, 6.0);
  s.reflectance.create(g.size, CV_32FC1);
  s.texture.create(g.size, CV_32FC1);
  for (int r = 0; r < g.size.height; ++r) {
    for (int c = 0; c < g.size.width; ++c) {
      const float top = relief.at<float>(r, c) > 0.98f ? 1.0f : 0.0f;
      s.reflectance.at<float>(r, c) = (1.0f - top) * (2.5f * specular.at<float>(r, c) + 0.003f) + top * 0.15f;
      s.texture.at<float>(r, c) = top > 0 ? frosted.at<float>(r, c) : scratches.at<float>(r, c);
    }
  }
  return s;
}

// ISO 25178-70 material measures (certified values in SimulatedMaterialMeasures). Textured like
// the thesis's planes (shape from focus needs texture; real SFF measures are matt for the same
// reason), reflectance 0.5, each its own texture stream.
Specimen MeasureFlat(const Grid& g) {  // AFL
  Specimen s = TexturedPlane(g, "afl", 0.0);
  s.texture = Texture(g, 11, 0.35, 0.15);
  return s;
}

// PGR (ISO 5436-1 type A1): a groove of depth d across the field, its width a third of the
// field, centred; the lands either side at the base + d.
Specimen MeasureGroove(const Grid& g, const std::string& name, double depth_um) {
  Specimen s;
  s.name = name;
  const double half_groove = g.width_um() / 6.0;
  s.height_um = Fill(g, [&](double x, double) { return kBaseHeightUm + (std::abs(x) < half_groove ? 0.0 : depth_um); });
  s.reflectance = cv::Mat(g.size, CV_32FC1, cv::Scalar(0.5));
  s.texture = Texture(g, 12 + uint64_t(depth_um * 10), 0.35, 0.15);
  return s;
}

// ASG: a sinusoid along x of the given period and amplitude (crests along y).
Specimen MeasureSinusoid(const Grid& g, const std::string& name, double period_um, double amplitude_um) {
  Specimen s;
  s.name = name;
  const double k = 2.0 * CV_PI / period_um;
  s.height_um = Fill(g, [&](double x, double) { return kBaseHeightUm + amplitude_um * (1.0 + std::sin(k * x)); });
  s.reflectance = cv::Mat(g.size, CV_32FC1, cv::Scalar(0.5));
  s.texture = Texture(g, 40 + uint64_t(period_um), 0.35, 0.15);
  return s;
}

// ACG: a cross grating, sinusoids of the same pitch along x and y.
Specimen MeasureCrossGrating(const Grid& g, double pitch_um, double amplitude_um) {
  Specimen s;
  s.name = "acg";
  const double k = 2.0 * CV_PI / pitch_um;
  s.height_um = Fill(g, [&](double x, double y) {
    return kBaseHeightUm + amplitude_um * (2.0 + std::sin(k * x) + std::sin(k * y));
  });
  s.reflectance = cv::Mat(g.size, CV_32FC1, cv::Scalar(0.5));
  s.texture = Texture(g, 90, 0.35, 0.15);
  return s;
}

const std::map<std::string, std::function<Specimen(const Grid&)>>& Builtins() {
  static auto* builtins = new std::map<std::string, std::function<Specimen(const Grid&)>>{
      {"plane", [](const Grid& g) { return TexturedPlane(g, "plane", 0.0); }},
      {"skew5", [](const Grid& g) { return TexturedPlane(g, "skew5", 5.0); }},
      {"skew10", [](const Grid& g) { return TexturedPlane(g, "skew10", 10.0); }},
      {"step1um", Step1um},
      {"wedge", Wedge},
      {"chamfer", Chamfer},
      {"cutter", Cutter},
      {"lens", Lens},
      {"mirror", Mirror},
      {"coin", Coin},
  };
  static bool measures_added = [] {
    for (const MaterialMeasure& m : SimulatedMaterialMeasures()) {
      std::function<Specimen(const Grid&)> make;
      switch (m.type) {
        case MaterialMeasureType::kAfl:
          make = MeasureFlat;
          break;
        case MaterialMeasureType::kPgr:
          make = [m](const Grid& g) { return MeasureGroove(g, m.specimen, m.height_um); };
          break;
        case MaterialMeasureType::kAsg:
          make = [m](const Grid& g) { return MeasureSinusoid(g, m.specimen, m.period_um, m.height_um); };
          break;
        case MaterialMeasureType::kAcg:
          make = [m](const Grid& g) { return MeasureCrossGrating(g, m.period_um, m.height_um); };
          break;
      }
      builtins->emplace(m.specimen, std::move(make));
    }
    return true;
  }();
  (void)measures_added;
  return *builtins;
}

StatusOr<cv::Mat> ReadSceneImage(const std::filesystem::path& dir, const nlohmann::json& j, const std::string& key,
                                 cv::Size size, double* default_scale) {
  if (!j[key].is_string()) return Status::InvalidArgument("scene key '" + key + "' must be a file name string");
  const std::filesystem::path p = dir / j[key].get<std::string>();
  if (!std::filesystem::exists(p)) {
    return Status::NotFound("scene key '" + key + "': file " + p.string() + " does not exist");
  }
  cv::Mat img = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
  if (img.empty()) return Status::InvalidArgument("scene key '" + key + "': cannot decode " + p.string());
  if (img.channels() != 1) {
    return Status::InvalidArgument("scene key '" + key + "': " + p.string() + " must be single-channel, has " +
                                   std::to_string(img.channels()) + " channels");
  }
  switch (img.depth()) {
    case CV_8U:
      *default_scale = 1.0 / 255.0;
      break;
    case CV_16U:
      *default_scale = 1.0 / 65535.0;
      break;
    default:
      *default_scale = 1.0;
      break;
  }
  cv::Mat f;
  img.convertTo(f, CV_32FC1);
  if (f.size() != size) cv::resize(f, f, size, 0, 0, cv::INTER_LINEAR);
  return f;
}

StatusOr<double> NumberOr(const nlohmann::json& j, const std::string& key, double fallback) {
  if (!j.contains(key)) return fallback;
  if (!j[key].is_number()) return Status::InvalidArgument("scene key '" + key + "' must be a number");
  return j[key].get<double>();
}

}  // namespace

std::vector<std::string> BuiltinSpecimenNames() {
  return {"plane", "skew5", "skew10", "step1um", "wedge", "chamfer", "cutter", "lens", "mirror", "coin"};
}

std::vector<std::string> MaterialMeasureSpecimenNames() {
  std::vector<std::string> names;
  for (const MaterialMeasure& m : SimulatedMaterialMeasures()) names.push_back(m.specimen);
  return names;
}

std::vector<MaterialMeasure> SimulatedMaterialMeasures() {
  // Certificates as a calibration laboratory would state them (k = 1): steps 2 nm + 0.05 %,
  // periods and pitches 0.01 %.
  std::vector<MaterialMeasure> out;
  out.push_back({"afl", MaterialMeasureType::kAfl, 0.0, 0.0, 0.0, 0.0});
  for (double d : {2.0, 5.0, 10.0, 20.0}) {
    out.push_back({"pgr" + std::to_string(int(d)), MaterialMeasureType::kPgr, d, 0.002 + 0.0005 * d, 0.0, 0.0});
  }
  for (double p : {4.0, 6.0, 8.0, 10.0, 12.0, 16.0, 24.0, 40.0}) {
    out.push_back({"asg" + std::to_string(int(p)), MaterialMeasureType::kAsg, 1.0, 0.002, p, 1e-4 * p});
  }
  out.push_back({"acg", MaterialMeasureType::kAcg, 1.0, 0.002, 20.0, 0.002});
  return out;
}

StatusOr<Specimen> MakeSpecimen(const std::string& name, const SpecimenGrid& grid) {
  if (grid.camera_size.width < 16 || grid.camera_size.height < 16) {
    return Status::InvalidArgument("camera_size must be at least 16x16");
  }
  if (!(grid.pixel_size_um > 0.0)) return Status::InvalidArgument("pixel_size_um must be > 0");
  if (name.rfind("file:", 0) == 0) {
    INSPECT_ASSIGN_OR_RETURN(Specimen s, LoadSceneFile(name.substr(5), grid));
    s.name = name;
    return s;
  }
  const auto& builtins = Builtins();
  auto it = builtins.find(name);
  if (it == builtins.end()) {
    std::string known;
    for (const auto& n : BuiltinSpecimenNames()) known += (known.empty() ? "" : ", ") + n;
    known += "; material measures: afl, pgr2 .. pgr20, asg4 .. asg40, acg";
    return Status::NotFound("unknown specimen '" + name + "'; built-ins: " + known + "; or file:/path/scene.json");
  }
  return it->second(Grid{grid.camera_size, grid.pixel_size_um, grid.seed});
}

StatusOr<Specimen> LoadSceneFile(const std::string& path, const SpecimenGrid& grid) {
  std::ifstream in(path);
  if (!in) return Status::NotFound("scene file " + path + " cannot be opened");
  nlohmann::json j = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) {
    return Status::InvalidArgument("scene file " + path + " is not a JSON object");
  }
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  Specimen s;
  s.name = "file:" + path;
  if (!j.contains("height")) return Status::InvalidArgument("scene key 'height' is missing in " + path);
  double unused = 1.0;
  INSPECT_ASSIGN_OR_RETURN(cv::Mat height, ReadSceneImage(dir, j, "height", grid.camera_size, &unused));
  INSPECT_ASSIGN_OR_RETURN(double h_scale, NumberOr(j, "height_scale_um", 1.0));
  INSPECT_ASSIGN_OR_RETURN(double h_offset, NumberOr(j, "height_offset_um", 0.0));
  if (!(h_scale > 0.0)) return Status::InvalidArgument("scene key 'height_scale_um' must be > 0");
  s.height_um = height * h_scale + h_offset;
  if (cv::checkRange(s.height_um, true, nullptr, -1e6, 1e6) == false) {
    return Status::InvalidArgument("scene key 'height': values must be finite and within +-1e6 um");
  }
  if (j.contains("reflectance")) {
    double default_scale = 1.0;
    INSPECT_ASSIGN_OR_RETURN(cv::Mat refl, ReadSceneImage(dir, j, "reflectance", grid.camera_size, &default_scale));
    INSPECT_ASSIGN_OR_RETURN(double r_scale, NumberOr(j, "reflectance_scale", default_scale));
    if (!(r_scale > 0.0)) return Status::InvalidArgument("scene key 'reflectance_scale' must be > 0");
    s.reflectance = cv::max(refl * r_scale, 0.0);
  } else {
    s.reflectance = cv::Mat(grid.camera_size, CV_32FC1, cv::Scalar(0.5));
  }
  if (j.contains("texture")) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat tex, ReadSceneImage(dir, j, "texture", grid.camera_size, &unused));
    INSPECT_ASSIGN_OR_RETURN(double contrast, NumberOr(j, "texture_contrast", 1.0));
    if (!(contrast >= 0.0)) return Status::InvalidArgument("scene key 'texture_contrast' must be >= 0");
    const double mean = cv::mean(tex)[0];
    if (!(mean > 0.0)) return Status::InvalidArgument("scene key 'texture': image mean must be > 0");
    tex = tex / mean;
    s.texture = cv::max(1.0 + contrast * (tex - 1.0), 0.0);
  } else {
    s.texture = cv::Mat(grid.camera_size, CV_32FC1, cv::Scalar(1.0));
  }
  return s;
}

}  // namespace inspection
