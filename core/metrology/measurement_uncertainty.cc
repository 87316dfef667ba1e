// Uncertainty propagation on SFF depth maps: exact covariance of linear functionals under the
// correlated error model, fit-parameter covariance, and Monte Carlo with a noise-bias estimate.
#include "core/metrology/measurement_uncertainty.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/imgproc.hpp>

namespace inspection {
namespace {

// Phases at which the z-linearity table is averaged (midpoint rule; the table is piecewise linear).
constexpr int kLinearityPhases = 64;
// Fractional positions are binned this finely (per distinct local step) before the table is
// evaluated, so a map of 1e6 pixels costs 64 x 512 table look-ups, not 64 x 1e6. The bin centre
// is within 1/1024 of a step of the true position: a bias error of < 0.1 % of the table's range.
constexpr int kFractionBins = 512;

// Accumulates per (local step, fraction bin) cells; steps are told apart to 1e-9 um.
class FractionCells {
 public:
  // Index of the cell of a grid position.
  int Cell(const ZGrid::Position& p) {
    const long long key = std::llround(p.step_um * 1e9);
    auto it = step_index_.find(key);
    if (it == step_index_.end()) {
      it = step_index_.emplace(key, int(steps_.size())).first;
      steps_.push_back(p.step_um);
    }
    const int bin = std::min(kFractionBins - 1, int(p.fraction * kFractionBins));
    return it->second * kFractionBins + bin;
  }
  int cells() const { return int(steps_.size()) * kFractionBins; }
  // The table's bias (um) for cell c at phase offset `phase`.
  double Bias(const ZLinearity& l, int c, double phase) const {
    return l.At((c % kFractionBins + 0.5) / kFractionBins + phase) * steps_[c / kFractionBins];
  }

 private:
  std::map<long long, int> step_index_;
  std::vector<double> steps_;
};

double SqrtQuadratic(const Eigen::MatrixXd& m, const Eigen::VectorXd& c) {
  return std::sqrt(std::max(0.0, c.dot(m * c)));
}

}  // namespace

UncertaintyBudget AnalyticBudget(const FunctionalCovariance& cov, const Eigen::VectorXd& c) {
  UncertaintyBudget b;
  b.method = "analytic";
  b.random = SqrtQuadratic(cov.random, c);
  b.linearity = SqrtQuadratic(cov.linearity, c);
  b.stage = SqrtQuadratic(cov.stage, c);
  b.standard_uncertainty = SqrtQuadratic(cov.Total(), c);
  return b;
}

UncertaintyBudget MonteCarloBudget(const MonteCarloEstimate& e) {
  UncertaintyBudget b;
  b.method = "monte-carlo";
  b.monte_carlo_spread = e.spread;
  b.noise_bias = e.bias;
  b.monte_carlo_samples = e.samples;
  b.standard_uncertainty = e.standard_uncertainty;
  return b;
}

UncertaintyBudget ExtremeValueBudget(int extremes, double linearity_range_um, const DepthNoiseModel& model) {
  UncertaintyBudget b;
  b.method = "bound";
  b.random = 0.5 * extremes * model.extreme_error_um;
  b.linearity = 0.5 * linearity_range_um;
  b.standard_uncertainty = b.random + b.linearity;
  return b;
}

UncertaintyBudget ExtremeValueBudgetUm(double extreme_error_um, double linearity_range_um) {
  UncertaintyBudget b;
  b.method = "bound";
  b.random = 0.5 * extreme_error_um;
  b.linearity = 0.5 * linearity_range_um;
  b.standard_uncertainty = b.random + b.linearity;
  return b;
}

double ExtremeErrorUm(const cv::Mat& surface_um, const DepthNoiseModel& model, bool peak) {
  const cv::Mat& e = model.extreme_error_map_um;
  if (e.empty() || e.size() != surface_um.size() || surface_um.type() != CV_32FC1) return model.extreme_error_um;
  double top = peak ? -1e300 : 1e300;
  for (int row = 0; row < surface_um.rows; ++row) {
    const float* z = surface_um.ptr<float>(row);
    for (int col = 0; col < surface_um.cols; ++col) {
      if (std::isfinite(z[col])) top = peak ? std::max(top, double(z[col])) : std::min(top, double(z[col]));
    }
  }
  double worst = -1.0;
  for (int row = 0; row < surface_um.rows; ++row) {
    const float* z = surface_um.ptr<float>(row);
    const float* er = e.ptr<float>(row);
    for (int col = 0; col < surface_um.cols; ++col) {
      if (!std::isfinite(z[col]) || !std::isfinite(er[col])) continue;
      const double gap = peak ? top - z[col] : z[col] - top;
      worst = std::max(worst, double(er[col]) - gap);
    }
  }
  return worst >= 0.0 ? worst : model.extreme_error_um;
}

double LinearityRangeUm(const cv::Mat& depth_um, const cv::Mat& mask, const DepthNoiseModel& model) {
  FractionCells cells;
  std::vector<char> occupied;
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* z = depth_um.ptr<float>(row);
    const uint8_t* m = mask.ptr<uint8_t>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (!m[col] || !std::isfinite(z[col])) continue;
      const int c = cells.Cell(model.grid.Locate(z[col]));
      if (c >= int(occupied.size())) occupied.resize(cells.cells(), 0);
      occupied[c] = 1;
    }
  }
  double range = 0.0;
  for (int k = 0; k < kLinearityPhases && !occupied.empty(); ++k) {
    double lo = 1e300, hi = -1e300;
    for (int c = 0; c < int(occupied.size()); ++c) {
      if (!occupied[c]) continue;
      const double b = cells.Bias(model.linearity, c, (k + 0.5) / kLinearityPhases);
      lo = std::min(lo, b);
      hi = std::max(hi, b);
    }
    range = std::max(range, hi - lo);
  }
  return range;
}

StatusOr<FunctionalCovariance> LinearFunctionalCovariance(const std::vector<cv::Mat>& weights, const cv::Mat& depth_um,
                                                          const DepthNoiseModel& model) {
  const int n = int(weights.size());
  if (depth_um.empty() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("depth map must be a non-empty CV_32FC1 image");
  }
  if (model.sigma_um.size() != depth_um.size()) {
    return Status::InvalidArgument("noise model was estimated on a map of another size");
  }
  for (int i = 0; i < n; ++i) {
    if (weights[i].type() != CV_64FC1 || weights[i].size() != depth_um.size()) {
      return Status::InvalidArgument("weights[" + std::to_string(i) + "] must be CV_64FC1 of the depth map's size");
    }
  }
  FunctionalCovariance cov;
  cov.random = cov.linearity = cov.stage = Eigen::MatrixXd::Zero(n, n);
  if (n == 0) return cov;

  // Pixels any functional uses, with their grid position.
  struct Used {
    int row, col;
    ZGrid::Position pos;
  };
  std::vector<Used> used;
  cv::Rect box;
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* z = depth_um.ptr<float>(row);
    const float* s = model.sigma_um.ptr<float>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      bool any = false;
      for (int i = 0; i < n && !any; ++i) any = weights[i].at<double>(row, col) != 0.0;
      if (!any) continue;
      if (!std::isfinite(z[col]) || !std::isfinite(s[col])) {
        return Status::InvalidArgument("weights use pixel (" + std::to_string(col) + ", " + std::to_string(row) +
                                       ") that has no depth or no noise estimate");
      }
      used.push_back({row, col, model.grid.Locate(z[col])});
      box |= cv::Rect(col, row, 1, 1);
    }
  }
  if (used.empty()) return cov;

  // Random part: L_i = sum_q w(q) h_i(q), h_i = (1 / w) box * (a_i sigma) over the padded canvas.
  const int w = model.correlation_px, r = w / 2;
  const cv::Rect canvas(box.x - r, box.y - r, box.width + 2 * r, box.height + 2 * r);
  std::vector<cv::Mat> h(n);
  for (int i = 0; i < n; ++i) {
    cv::Mat g = cv::Mat::zeros(canvas.size(), CV_64F);
    for (const Used& u : used) {
      g.at<double>(u.row - canvas.y, u.col - canvas.x) =
          weights[i].at<double>(u.row, u.col) * double(model.sigma_um.at<float>(u.row, u.col));
    }
    cv::boxFilter(g, h[i], CV_64F, cv::Size(w, w), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    h[i] /= double(w);
  }
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j <= i; ++j) cov.random(i, j) = cov.random(j, i) = h[i].dot(h[j]);
  }

  // z linearity: the table at an unknown phase; E over the phase of L_i L_j.
  // The functionals' weights summed per fraction cell, then the table per cell and phase.
  FractionCells cells;
  std::vector<int> cell_of(used.size());
  for (size_t k = 0; k < used.size(); ++k) cell_of[k] = cells.Cell(used[k].pos);
  Eigen::MatrixXd cell_weight = Eigen::MatrixXd::Zero(n, cells.cells());
  for (size_t k = 0; k < used.size(); ++k) {
    for (int i = 0; i < n; ++i) cell_weight(i, cell_of[k]) += weights[i].at<double>(used[k].row, used[k].col);
  }
  Eigen::MatrixXd bias(cells.cells(), kLinearityPhases);
  for (int c = 0; c < cells.cells(); ++c) {
    for (int k = 0; k < kLinearityPhases; ++k)
      bias(c, k) = cells.Bias(model.linearity, c, (k + 0.5) / kLinearityPhases);
  }
  const Eigen::MatrixXd l = cell_weight * bias;  // n x phases
  cov.linearity = l * l.transpose() / double(kLinearityPhases);

  // Stage: one independent error per frame, reaching each depth through its peak
  // interpolation's sensitivity to the frames around it (core/metrology/depth_noise_model.h).
  if (model.stage_u_um > 0.0) {
    const int frames = int(model.grid.positions_um().size());
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n, frames);
    for (const Used& u : used) {
      const DepthNoiseModel::StageSensitivity s = model.StageSensitivityAt(u.pos);
      for (int k = 0; k < s.count; ++k) {
        for (int i = 0; i < n; ++i) a(i, s.frame[k]) += s.weight[k] * weights[i].at<double>(u.row, u.col);
      }
    }
    cov.stage = model.stage_u_um * model.stage_u_um * a * a.transpose();
  }
  return cov;
}

std::vector<cv::Mat> FormFitWeights(const FormFit& fit, const cv::Mat& depth_um, const cv::Mat& mask,
                                    double pixel_size_um) {
  const int np = int(fit.parameters.size());
  std::vector<cv::Mat> out(np);
  for (cv::Mat& m : out) m = cv::Mat::zeros(depth_um.size(), CV_64F);
  std::vector<double> g(np);
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* z = depth_um.ptr<float>(row);
    const uint8_t* m = mask.ptr<uint8_t>(row);
    const double y = PixelCentreUm(row, pixel_size_um);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (!m[col] || !std::isfinite(z[col])) continue;
      fit.ParameterGradient(PixelCentreUm(col, pixel_size_um), y, g.data());
      const Eigen::VectorXd a = fit.normal_inverse * Eigen::Map<const Eigen::VectorXd>(g.data(), np);
      for (int j = 0; j < np; ++j) out[j].at<double>(row, col) = a[j];
    }
  }
  return out;
}

StatusOr<FunctionalCovariance> FormFitCovariance(const FormFit& fit, const cv::Mat& depth_um, const cv::Mat& mask,
                                                 double pixel_size_um, const DepthNoiseModel& model) {
  return LinearFunctionalCovariance(FormFitWeights(fit, depth_um, mask, pixel_size_um), depth_um, model);
}

Status MonteCarloOptions::Validate() const {
  if (samples < 8 || samples > 10000) {
    return Status::InvalidArgument("monte_carlo.samples must be in 8..10000, got " + std::to_string(samples));
  }
  return Status::Ok();
}

StatusOr<std::vector<MonteCarloEstimate>> MonteCarloUncertainty(const cv::Mat& depth_um,
                                                                const std::vector<double>& values,
                                                                const DepthMeasureFunction& measure,
                                                                const DepthNoiseModel& model,
                                                                const MonteCarloOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.empty() || depth_um.type() != CV_32FC1 || model.sigma_um.size() != depth_um.size()) {
    return Status::InvalidArgument("depth map and noise model must be CV_32FC1 maps of one size");
  }
  const size_t n = values.size();
  std::vector<double> sum(n, 0.0), sum2(n, 0.0), sum3(n, 0.0);
  std::vector<int> count(n, 0), count3(n, 0);
  std::vector<cv::Mat> draws(options.samples);
  for (int k = 0; k < options.samples; ++k) draws[k] = model.SamplePerturbation(depth_um, options.seed, k, options.samples);
  for (int k = 0; k < options.samples; ++k) {
    StatusOr<std::vector<double>> v = measure(depth_um + draws[k]);
    if (!v.ok() || v->size() != n) continue;
    // The third noise level: a second, independent draw on top (paired with this sample).
    StatusOr<std::vector<double>> v3 = measure(depth_um + draws[k] + draws[(k + options.samples / 2) % options.samples]);
    const bool third = v3.ok() && v3->size() == n;
    for (size_t i = 0; i < n; ++i) {
      const double d = (*v)[i] - values[i];  // about the measured value: keeps the sums small
      if (!std::isfinite(d)) continue;
      sum[i] += d;
      sum2[i] += d * d;
      ++count[i];
      if (third && std::isfinite((*v3)[i])) {
        sum3[i] += (*v3)[i] - (*v)[i];
        ++count3[i];
      }
    }
  }
  std::vector<MonteCarloEstimate> out(n);
  for (size_t i = 0; i < n; ++i) {
    if (!std::isfinite(values[i])) {
      out[i].spread = out[i].bias = out[i].standard_uncertainty = std::nan("");
      continue;
    }
    if (count[i] < std::max(2, options.samples / 2)) {
      return Status::FailedPrecondition(
          "Monte Carlo uncertainty: only " + std::to_string(count[i]) + " of " + std::to_string(options.samples) +
          " perturbed measurements succeeded (the measurement is unstable under its noise)");
    }
    const double c = count[i], mean = sum[i] / c;
    out[i].samples = count[i];
    out[i].spread = std::sqrt(std::max(0.0, (sum2[i] - c * mean * mean) / (c - 1.0)));
    const double d2 = count3[i] > 0 ? sum3[i] / count3[i] : std::nan("");
    out[i].noise_exponent = NoiseBiasExponent(mean, d2, out[i].spread / std::sqrt(c));
    out[i].bias = mean / (std::pow(2.0, out[i].noise_exponent) - 1.0);
    out[i].standard_uncertainty = std::hypot(out[i].spread, out[i].bias);
  }
  return out;
}

double NoiseBiasExponent(double d1, double d2, double d1_standard_error) {
  if (!std::isfinite(d1) || !std::isfinite(d2) || !(std::abs(d1) > 3.0 * d1_standard_error) || d1 == 0.0) return 0.5;
  // r(p) = (3^p - 2^p) / (2^p - 1) rises from 0.768 at p = 1/2 to 1 at p = 1.
  const double r = d2 / d1;
  auto ratio = [](double p) { return (std::pow(3.0, p) - std::pow(2.0, p)) / (std::pow(2.0, p) - 1.0); };
  if (!(r > ratio(0.5))) return 0.5;
  if (r >= 1.0) return 1.0;
  double lo = 0.5, hi = 1.0;
  for (int it = 0; it < 40; ++it) {
    const double mid = 0.5 * (lo + hi);
    (ratio(mid) < r ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

cv::Mat WindowAveragingError(const cv::Mat& depth_um, int window_px) {
  CV_Assert(depth_um.type() == CV_32FC1 && window_px >= 1);
  cv::Mat valid = (depth_um == depth_um);  // NaN != NaN
  cv::Mat z = depth_um.clone(), weight;
  z.setTo(0.0f, ~valid);
  valid.convertTo(weight, CV_32F, 1.0 / 255.0);
  // Normalised convolution: holes neither pull the smoothed surface to 0 nor leave gaps.
  const double sigma = std::max(1.0, 0.5 * window_px);
  cv::Mat zs, ws;
  cv::GaussianBlur(z, zs, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
  cv::GaussianBlur(weight, ws, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
  cv::Mat smooth;
  cv::divide(zs, cv::max(ws, 1e-6), smooth);
  cv::Mat lap;
  cv::Laplacian(smooth, lap, CV_32F, 1, 1.0, 0.0, cv::BORDER_REFLECT);  // 4-neighbour, um / px^2
  const double s2 = (double(window_px) * window_px - 1.0) / 12.0 + 0.5;
  cv::Mat e = lap * (0.5 * s2);
  // Where the smoothing had too little support (isolated pixels) the estimate is meaningless.
  e.setTo(0.0f, ~valid | (ws < 0.25f));
  return e;
}

double HeightDependentErrorBoundUm(const cv::Mat& depth_um, const cv::Mat& mask, const DepthNoiseModel& model,
                                   double linearity_range_um) {
  const cv::Mat e = WindowAveragingError(depth_um, model.correlation_px);
  std::vector<float> flattening;
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* z = depth_um.ptr<float>(row);
    const float* er = e.ptr<float>(row);
    const uint8_t* m = mask.ptr<uint8_t>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (m[col] && std::isfinite(z[col])) flattening.push_back(std::abs(er[col]));
    }
  }
  double p99 = 0.0;
  if (!flattening.empty()) {
    const size_t k = std::min(flattening.size() - 1, size_t(0.99 * double(flattening.size())));
    std::nth_element(flattening.begin(), flattening.begin() + long(k), flattening.end());
    p99 = flattening[k];
  }
  return 0.5 * linearity_range_um + p99;
}

namespace {

// n d(parameter) / d z_p for the levelled surface, up to a positive factor (CV_64FC1, 0 where
// surface_um is NaN; all 0 for fewer than 2 finite pixels or no variance).
cv::Mat ShapeParameterGradient(const cv::Mat& surface_um, HeightParameter parameter) {
  cv::Mat grad(surface_um.size(), CV_64FC1, cv::Scalar(0));
  double n = 0, s1 = 0;
  for (int row = 0; row < surface_um.rows; ++row) {
    const float* z = surface_um.ptr<float>(row);
    for (int col = 0; col < surface_um.cols; ++col) {
      if (std::isfinite(z[col])) {
        n += 1;
        s1 += z[col];
      }
    }
  }
  if (n < 2) return grad;
  const double mean = s1 / n;
  double m2 = 0, m3 = 0, m4 = 0;
  for (int row = 0; row < surface_um.rows; ++row) {
    const float* z = surface_um.ptr<float>(row);
    for (int col = 0; col < surface_um.cols; ++col) {
      if (!std::isfinite(z[col])) continue;
      const double d = z[col] - mean;
      m2 += d * d / n;
      m3 += d * d * d / n;
      m4 += d * d * d * d / n;
    }
  }
  if (!(m2 > 0)) return grad;
  // n d(m3 / m2^1.5) / dz_p = (3 (d^2 - m2) m2 - 3 m3 d) / m2^2.5
  // n d(m4 / m2^2) / dz_p   = (4 (d^3 - m3) m2 - 4 m4 d) / m2^3
  // (the common positive factors 1 / m2^2.5 and 1 / m2^3 are left out: only signs and relative
  // sizes are used).
  for (int row = 0; row < surface_um.rows; ++row) {
    const float* z = surface_um.ptr<float>(row);
    double* g = grad.ptr<double>(row);
    for (int col = 0; col < surface_um.cols; ++col) {
      if (!std::isfinite(z[col])) continue;
      const double d = z[col] - mean;
      g[col] = parameter == HeightParameter::kSsk ? 3.0 * (d * d - m2) * m2 - 3.0 * m3 * d
                                                  : 4.0 * (d * d * d - m3) * m2 - 4.0 * m4 * d;
    }
  }
  return grad;
}

}  // namespace

StatusOr<cv::Mat> ShapeParameterSensitivitySign(const cv::Mat& surface_um, HeightParameter parameter) {
  if (parameter != HeightParameter::kSsk && parameter != HeightParameter::kSku) {
    return Status::InvalidArgument("ShapeParameterSensitivitySign: parameter must be Ssk or Sku");
  }
  const cv::Mat grad = ShapeParameterGradient(surface_um, parameter);
  cv::Mat sign(surface_um.size(), CV_32FC1, cv::Scalar(0));
  bool any = false;
  for (int row = 0; row < grad.rows && !any; ++row) {
    const double* g = grad.ptr<double>(row);
    for (int col = 0; col < grad.cols && !any; ++col) any = g[col] != 0.0;
  }
  if (!any) return sign;
  for (int row = 0; row < surface_um.rows; ++row) {
    const float* z = surface_um.ptr<float>(row);
    const double* g = grad.ptr<double>(row);
    float* s = sign.ptr<float>(row);
    for (int col = 0; col < surface_um.cols; ++col) {
      if (std::isfinite(z[col])) s[col] = g[col] >= 0.0 ? 1.0f : -1.0f;
    }
  }
  return sign;
}

StatusOr<cv::Mat> PeriodicWorstCaseSign(const cv::Mat& depth_um, const cv::Mat& surface_um, HeightParameter parameter,
                                        const DepthNoiseModel& model, int bins) {
  if (parameter != HeightParameter::kSsk && parameter != HeightParameter::kSku) {
    return Status::InvalidArgument("PeriodicWorstCaseSign: parameter must be Ssk or Sku");
  }
  if (bins < 2 || bins > 1000) return Status::InvalidArgument("PeriodicWorstCaseSign: bins must be in 2..1000");
  if (depth_um.type() != CV_32FC1 || surface_um.type() != CV_32FC1 || depth_um.size() != surface_um.size()) {
    return Status::InvalidArgument("PeriodicWorstCaseSign: depth and surface must be CV_32FC1 maps of one size");
  }
  const cv::Mat grad = ShapeParameterGradient(surface_um, parameter);
  cv::Mat bin_of(depth_um.size(), CV_32SC1, cv::Scalar(-1));
  std::vector<double> sum(bins, 0.0);
  for (int row = 0; row < depth_um.rows; ++row) {
    const float* z = depth_um.ptr<float>(row);
    const float* s = surface_um.ptr<float>(row);
    const double* g = grad.ptr<double>(row);
    int* b = bin_of.ptr<int>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (!std::isfinite(z[col]) || !std::isfinite(s[col])) continue;
      b[col] = std::min(bins - 1, int(model.grid.Locate(z[col]).fraction * bins));
      sum[b[col]] += g[col];
    }
  }
  cv::Mat sign(depth_um.size(), CV_32FC1, cv::Scalar(0));
  for (int row = 0; row < depth_um.rows; ++row) {
    const int* b = bin_of.ptr<int>(row);
    float* o = sign.ptr<float>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (b[col] >= 0 && sum[b[col]] != 0.0) o[col] = sum[b[col]] > 0.0 ? 1.0f : -1.0f;
    }
  }
  return sign;
}

void AddHeightDependentBound(UncertaintyBudget& budget, double bound) {
  const double u = std::abs(bound) / std::sqrt(3.0);
  budget.height_dependent = u;
  const double before = std::isfinite(budget.standard_uncertainty) ? budget.standard_uncertainty : 0.0;
  budget.standard_uncertainty = std::hypot(before, u);
}

void AddEstimatedSystematic(UncertaintyBudget& budget, double bias) {
  budget.estimated_systematic = bias;
  const double before = std::isfinite(budget.standard_uncertainty) ? budget.standard_uncertainty : 0.0;
  budget.standard_uncertainty = std::hypot(before, std::isfinite(bias) ? bias : 0.0);
}

}  // namespace inspection
