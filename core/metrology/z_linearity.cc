// z linearity (peak-locking) table of the SFF depth: the z grid, the uncharacterised bound and
// the characterisation from a tilted flat.
#include "core/metrology/z_linearity.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/metrology/form_removal.h"

namespace inspection {

StatusOr<ZGrid> ZGrid::Create(std::vector<double> z, const std::string& field) {
  if (z.size() < 2) return Status::InvalidArgument(field + ": needs >= 2 z positions, got " + std::to_string(z.size()));
  for (size_t i = 0; i < z.size(); ++i) {
    if (!std::isfinite(z[i])) return Status::InvalidArgument(field + "[" + std::to_string(i) + "] is not finite");
  }
  std::sort(z.begin(), z.end());
  for (size_t i = 1; i < z.size(); ++i) {
    if (!(z[i] > z[i - 1])) return Status::InvalidArgument(field + ": z positions must be distinct");
  }
  ZGrid g;
  g.z_ = std::move(z);
  return g;
}

ZGrid::Position ZGrid::Locate(double z_um) const {
  Position p;
  const int n = int(z_.size());
  if (n < 2 || !std::isfinite(z_um)) return p;
  if (z_um < z_[0]) {  // below the grid: continue its first step
    const double step = z_[1] - z_[0];
    const double k = std::floor((z_um - z_[0]) / step);
    p.lower = int(std::max(k, -1e9));  // far outliers: no int overflow
    p.fraction = (z_um - z_[0]) / step - k;
    p.step_um = step;
    p.nearest = 0;
    return p;
  }
  if (z_um >= z_[n - 1]) {  // above: continue its last step
    const double step = z_[n - 1] - z_[n - 2];
    const double k = std::floor((z_um - z_[n - 1]) / step);
    p.lower = n - 1 + int(std::min(k, 1e9));
    p.fraction = (z_um - z_[n - 1]) / step - k;
    p.step_um = step;
    p.nearest = n - 1;
    return p;
  }
  const int k = int(std::upper_bound(z_.begin(), z_.end(), z_um) - z_.begin()) - 1;
  p.lower = k;
  p.step_um = z_[k + 1] - z_[k];
  p.fraction = std::clamp((z_um - z_[k]) / p.step_um, 0.0, std::nextafter(1.0, 0.0));
  p.nearest = p.fraction < 0.5 ? k : k + 1;
  return p;
}

double ZGrid::median_step_um() const {
  if (z_.size() < 2) return 0.0;
  std::vector<double> d;
  for (size_t i = 1; i < z_.size(); ++i) d.push_back(z_[i] - z_[i - 1]);
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2];
}

ZLinearity ZLinearity::Uncharacterised() {
  // The discrete maximum reports the nearest frame: error = -f below half a step, 1 - f above.
  ZLinearity l;
  const int n = 64;
  for (int i = 0; i < n; ++i) {
    const double f = double(i) / n;
    l.bias_of_step.push_back(f < 0.5 ? -f : 1.0 - f);
  }
  // Tabulated at f = i / n the sawtooth has mean -1/(2n) at the jump (f = 0.5 is taken as +0.5):
  // remove it so the table is zero-mean like a characterised one.
  double mean = 0.0;
  for (double v : l.bias_of_step) mean += v;
  mean /= n;
  for (double& v : l.bias_of_step) v -= mean;
  l.source = "uncharacterised: peak-locking bound of the discrete maximum (+-1/2 z step)";
  return l;
}

ZLinearity ZLinearity::UncharacterisedThreePointPeak() {
  // The Gaussian vertex through ln F at u = -1, 0, 1 (in steps) for the focus at x in [-1/2, 1/2],
  // F(u) = (1 + ((u - x) / w)^2)^-2, w = 1/2: mu = (g_-1 - g_1) / (2 (g_-1 - 2 g_0 + g_1)), g = -ln F.
  constexpr double kHalfWidthSteps = 0.5;
  auto g = [](double u) { return 2.0 * std::log1p((u / kHalfWidthSteps) * (u / kHalfWidthSteps)); };
  ZLinearity l;
  const int n = 64;
  for (int i = 0; i < n; ++i) {
    const double f = double(i) / n;
    const double x = f < 0.5 ? f : f - 1.0;  // focus relative to the nearest frame
    const double gm = g(-1.0 - x), g0 = g(-x), gp = g(1.0 - x);
    const double den = 2.0 * (gm - 2.0 * g0 + gp);
    l.bias_of_step.push_back(den > 0.0 ? (gm - gp) / den - x : 0.0);
  }
  l.source =
      "uncharacterised: analytic error bound of the three-point peak interpolation (curve half-width 1/2 z step)";
  return l;
}

double ZLinearity::At(double fraction) const {
  const int n = int(bias_of_step.size());
  if (n == 0) return 0.0;
  double f = fraction - std::floor(fraction);
  const double pos = f * n;
  const int i = std::min(int(pos), n - 1);
  const double w = pos - i;
  return (1.0 - w) * bias_of_step[i] + w * bias_of_step[(i + 1) % n];
}

double ZLinearity::Rms() const {
  if (bias_of_step.empty()) return 0.0;
  double s = 0.0;
  for (double v : bias_of_step) s += v * v;
  return std::sqrt(s / bias_of_step.size());
}

double ZLinearity::MaxAbs() const {
  double m = 0.0;
  for (double v : bias_of_step) m = std::max(m, std::abs(v));
  return m;
}

std::string ZLinearityToJson(const ZLinearity& l) {
  nlohmann::json j;
  j["bias_of_step"] = l.bias_of_step;
  j["characterised_step_um"] = l.characterised_step_um;
  j["source"] = l.source;
  return j.dump();
}

StatusOr<ZLinearity> ZLinearityFromJson(const std::string& text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) return Status::InvalidArgument("z linearity: not a JSON object");
  ZLinearity l;
  if (!j.contains("bias_of_step") || !j["bias_of_step"].is_array()) {
    return Status::InvalidArgument("z linearity: 'bias_of_step' must be an array of numbers");
  }
  for (const auto& v : j["bias_of_step"]) {
    if (!v.is_number() || !std::isfinite(v.get<double>()) || std::abs(v.get<double>()) > 1.0) {
      return Status::InvalidArgument(
          "z linearity: 'bias_of_step' entries must be numbers in [-1, 1] (fractions of a step)");
    }
    l.bias_of_step.push_back(v.get<double>());
  }
  if (l.bias_of_step.size() < 2) return Status::InvalidArgument("z linearity: 'bias_of_step' needs >= 2 entries");
  if (j.contains("characterised_step_um")) {
    if (!j["characterised_step_um"].is_number() || !(j["characterised_step_um"].get<double>() >= 0.0)) {
      return Status::InvalidArgument("z linearity: 'characterised_step_um' must be a number >= 0");
    }
    l.characterised_step_um = j["characterised_step_um"].get<double>();
  }
  if (j.contains("source")) {
    if (!j["source"].is_string()) return Status::InvalidArgument("z linearity: 'source' must be a string");
    l.source = j["source"].get<std::string>();
  }
  return l;
}

Status ZLinearityOptions::Validate() const {
  if (bins < 4 || bins > 200) return Status::InvalidArgument("bins must be in 4..200, got " + std::to_string(bins));
  if (min_pixels_per_bin < 1) return Status::InvalidArgument("min_pixels_per_bin must be >= 1");
  return Status::Ok();
}

StatusOr<ZLinearity> CharacteriseZLinearity(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                            const ZGrid& grid, const ZLinearityOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (grid.positions_um().size() < 2) return Status::InvalidArgument("z grid: needs >= 2 positions");
  FormOptions plane;
  INSPECT_ASSIGN_OR_RETURN(FormFit fit, FitForm(depth_um, mask, pixel_size_um, plane));
  const int n = options.bins;
  std::vector<double> sum(n, 0.0);
  std::vector<size_t> count(n, 0);
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* d = depth_um.ptr<float>(row);
    const uint8_t* m = mask.ptr<uint8_t>(row);
    const double y = PixelCentreUm(row, pixel_size_um);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (!m[col] || !std::isfinite(d[col])) continue;
      const double model = fit.Evaluate(PixelCentreUm(col, pixel_size_um), y);
      const ZGrid::Position p = grid.Locate(model);
      // Bin i collects f in [(i - 1/2) / n, (i + 1/2) / n): centred on the table's nodes i / n.
      const int bin = int(std::floor(p.fraction * n + 0.5)) % n;
      sum[bin] += (double(d[col]) - model) / p.step_um;
      ++count[bin];
    }
  }
  int emptiest = 0;
  for (int i = 1; i < n; ++i) {
    if (count[i] < count[emptiest]) emptiest = i;
  }
  if (count[emptiest] < size_t(options.min_pixels_per_bin)) {
    return Status::FailedPrecondition("z linearity: fractional position " + std::to_string(double(emptiest) / n) +
                                      " of the z step has only " + std::to_string(count[emptiest]) + " pixels (needs " +
                                      std::to_string(options.min_pixels_per_bin) +
                                      "): tilt the flat so that its heights span at least one z step over the region");
  }
  ZLinearity l;
  double mean = 0.0;
  for (int i = 0; i < n; ++i) {
    l.bias_of_step.push_back(sum[i] / double(count[i]));
    mean += l.bias_of_step.back();
  }
  mean /= n;
  for (double& v : l.bias_of_step) v -= mean;
  l.characterised_step_um = grid.median_step_um();
  l.source = "characterised on a tilted flat (" + std::to_string(fit.pixel_count) + " pixels, " +
             std::to_string(l.characterised_step_um) + " um steps)";
  return l;
}

}  // namespace inspection
