// SFF depth error model: local random sigma from lagged second differences, box-correlated noise,
// z-linearity table with unknown phase, per-frame stage error; and Monte Carlo draws of it.
#include "core/metrology/depth_noise_model.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

namespace inspection {
namespace {

uint64_t SplitMix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Lagged second differences z(p - lag) - 2 z(p) + z(p + lag) along one axis where all three
// samples are usable: value and 0/1 count images (CV_64F, 0 elsewhere).
void LaggedSecondDifferences(const cv::Mat& depth, const cv::Mat& usable, int lag, bool along_x, cv::Mat* value,
                             cv::Mat* count) {
  *value = cv::Mat::zeros(depth.size(), CV_64F);
  *count = cv::Mat::zeros(depth.size(), CV_64F);
  const int dx = along_x ? lag : 0, dy = along_x ? 0 : lag;
  for (int row = dy; row < depth.rows - dy; ++row) {
    const float* z0 = depth.ptr<float>(row - dy);
    const float* z1 = depth.ptr<float>(row);
    const float* z2 = depth.ptr<float>(row + dy);
    const uint8_t* u0 = usable.ptr<uint8_t>(row - dy);
    const uint8_t* u1 = usable.ptr<uint8_t>(row);
    const uint8_t* u2 = usable.ptr<uint8_t>(row + dy);
    double* v = value->ptr<double>(row);
    double* c = count->ptr<double>(row);
    for (int col = dx; col < depth.cols - dx; ++col) {
      if (!u0[col - dx] || !u1[col] || !u2[col + dx]) continue;
      v[col] = double(z0[col - dx]) - 2.0 * double(z1[col]) + double(z2[col + dx]);
      c[col] = 1.0;
    }
  }
}

// Squared lagged second differences / 6 along one axis where all three samples are usable:
// value and 0/1 count images (CV_64F).
void SecondDifferences(const cv::Mat& depth, const cv::Mat& usable, int lag, bool along_x, cv::Mat* value,
                       cv::Mat* count) {
  LaggedSecondDifferences(depth, usable, lag, along_x, value, count);
  for (int row = 0; row < value->rows; ++row) {
    double* v = value->ptr<double>(row);
    for (int col = 0; col < value->cols; ++col) v[col] = v[col] * v[col] / 6.0;
  }
}

// Where a lone error can sit and how large it plausibly is, per pixel (CV_32FC1, NaN where no
// second difference reaches): |d2 - local mean of d2| / 2 along the used directions, the larger of
// the two, spread over +-lag (an error at p enters the second differences centred at p and at
// p +- lag, and the band within lag of the region's edge has none of its own). The local mean
// (box of 2 lag + 1) is the surface's own curvature at that scale, which is no error: a 3 um sine
// at a 43 px period has second differences of 3.7 um at lag 8, and made the extremes' bound 3-4x
// their deviations. A lone spike's mean over that box is zero (-2A at p, +A at p +- lag), so the
// spike keeps its full size.
cv::Mat LocalExtremeError(const cv::Mat& depth, const cv::Mat& usable, int lag, bool use_x, bool use_y) {
  cv::Mat best(depth.size(), CV_32FC1, cv::Scalar(-1.0f));
  const int side = 2 * lag + 1;
  for (const bool along_x : {true, false}) {
    if (along_x ? !use_x : !use_y) continue;
    cv::Mat d2, count;
    LaggedSecondDifferences(depth, usable, lag, along_x, &d2, &count);
    cv::Mat sum, n;
    cv::boxFilter(d2, sum, CV_64F, cv::Size(side, side), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(count, n, CV_64F, cv::Size(side, side), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    for (int row = 0; row < depth.rows; ++row) {
      const double* v = d2.ptr<double>(row);
      const double* c = count.ptr<double>(row);
      const double* sm = sum.ptr<double>(row);
      const double* nn = n.ptr<double>(row);
      float* b = best.ptr<float>(row);
      for (int col = 0; col < depth.cols; ++col) {
        if (c[col] > 0.0) b[col] = std::max(b[col], float(0.5 * std::abs(v[col] - sm[col] / nn[col])));
      }
    }
  }
  cv::Mat spread;
  cv::dilate(best, spread, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(side, side)), cv::Point(-1, -1), 1,
             cv::BORDER_CONSTANT, cv::Scalar(-1.0f));
  spread.setTo(std::nanf(""), spread < 0.0f);
  return spread;
}

}  // namespace

Status DepthNoiseOptions::Validate() const {
  if (window_px < 1 || window_px > 63) {
    return Status::InvalidArgument("window_px must be in 1..63, got " + std::to_string(window_px));
  }
  if (z_positions_um.size() < 2) {
    return Status::InvalidArgument("z_positions_um: the stack's z positions are needed (>= 2), got " +
                                   std::to_string(z_positions_um.size()));
  }
  if (!(stage_repeatability_um >= 0.0) || !std::isfinite(stage_repeatability_um)) {
    return Status::InvalidArgument("stage_repeatability_um must be >= 0");
  }
  if (neighbourhood_px < 0 || neighbourhood_px > 4001) {
    return Status::InvalidArgument("neighbourhood_px must be in 0..4001 (0 = 8 windows)");
  }
  if (linearity.bias_of_step.size() < 2) {
    return Status::InvalidArgument("linearity.bias_of_step needs >= 2 entries");
  }
  for (double v : linearity.bias_of_step) {
    if (!std::isfinite(v) || std::abs(v) > 1.0) {
      return Status::InvalidArgument("linearity.bias_of_step: values must be finite fractions of a step (|v| <= 1)");
    }
  }
  if (!(linearity_step_tolerance >= 0.0)) return Status::InvalidArgument("linearity_step_tolerance must be >= 0");
  INSPECT_RETURN_IF_ERROR(verified.Validate());
  return Status::Ok();
}

Status VerifiedCharacteristics::Validate() const {
  auto check = [](const std::optional<double>& v, const char* name) -> Status {
    if (v && !(std::isfinite(*v) && *v >= 0.0)) {
      return Status::InvalidArgument(std::string("verified.") + name + " must be finite and >= 0");
    }
    return Status::Ok();
  };
  INSPECT_RETURN_IF_ERROR(check(noise_um, "noise_um"));
  INSPECT_RETURN_IF_ERROR(check(amplification_u, "amplification_u"));
  INSPECT_RETURN_IF_ERROR(check(linearity_deviation_um, "linearity_deviation_um"));
  INSPECT_RETURN_IF_ERROR(check(flatness_um, "flatness_um"));
  if (linearity_step_um && !(std::isfinite(*linearity_step_um) && *linearity_step_um > 0.0)) {
    return Status::InvalidArgument("verified.linearity_step_um must be finite and > 0");
  }
  if (amplification && !(std::isfinite(*amplification) && *amplification >= 0.5 && *amplification <= 2.0)) {
    return Status::InvalidArgument("verified.amplification must be in 0.5..2");
  }
  if (amplification_u && !amplification) {
    return Status::InvalidArgument("verified.amplification_u needs verified.amplification");
  }
  return Status::Ok();
}

double VerifiedCharacteristics::RelativeAmplificationUncertainty() const {
  if (!amplification) return 0.0;
  return std::hypot(amplification_u.value_or(0.0), *amplification - 1.0);
}

StatusOr<DepthNoiseModel> EstimateDepthNoise(const cv::Mat& depth_um, const cv::Mat& mask,
                                             const DepthNoiseOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.empty() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("depth map must be a non-empty CV_32FC1 image");
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != depth_um.size())) {
    return Status::InvalidArgument("mask must be empty or CV_8UC1 of the depth map's size");
  }
  DepthNoiseModel model;
  INSPECT_ASSIGN_OR_RETURN(model.grid, ZGrid::Create(options.z_positions_um));
  model.correlation_px = options.window_px;
  model.stage_u_um = options.stage_repeatability_um / std::sqrt(3.0);
  model.three_point_peak = options.three_point_peak;
  model.linearity = options.linearity;
  if (model.linearity.characterised_step_um > 0.0) {
    const double step = model.grid.median_step_um();
    const double characterised = model.linearity.characterised_step_um;
    if (step < characterised * (1.0 - options.linearity_step_tolerance)) {
      // Finer than characterised: the table's shape at this step is not known, its size in um
      // is bounded by the characterised one (a denser sampling of the focus curve does not
      // raise the interpolation error in um; simulated rig, SKEW10: max 0.058 um at 5 um steps,
      // 0.036 um at 2 um). The table is kept in um, i.e. rescaled as a fraction of the step,
      // and its phase stays unknown as always. Dropping to the peak-locking sawtooth instead
      // (+-step / 2) made it the dominant component of every two-height measurement.
      const double scale = characterised / step;
      double largest = 0.0;
      for (double v : model.linearity.bias_of_step) largest = std::max(largest, std::abs(v) * scale);
      if (largest <= 0.5) {
        for (double& v : model.linearity.bias_of_step) v *= scale;
        model.linearity.source += "; transferred from " + std::to_string(characterised) + " um to " +
                                  std::to_string(step) + " um steps (bias in um kept)";
        model.linearity.characterised_step_um = step;
      }
    }
    if (std::abs(step - model.linearity.characterised_step_um) >
        options.linearity_step_tolerance * model.linearity.characterised_step_um) {
      // Coarser than characterised: the error grows with the step, and by an unknown amount.
      const std::string was = model.linearity.source;
      model.linearity = ZLinearity::Uncharacterised();
      model.linearity.source +=
          "; the characterisation (" + was + ") does not apply at " + std::to_string(step) + " um steps";
    }
  }

  if (model.linearity.characterised_step_um <= 0.0 && options.three_point_peak) {
    // Not characterised at this step, but the depth is interpolated through three frames: the
    // discrete maximum's +-step / 2 sawtooth bounds which frame is the maximum, not the
    // interpolated depth (its jump at half a step moved straddling pixels a whole step apart in
    // every Monte Carlo draw, and made every uncertainty 5-50x wider than the deviations on the
    // simulated rig). The three-point fit's own analytic error is the prior instead
    // (ZLinearity::UncharacterisedThreePointPeak, +-0.11 step); a verified l_z still scales it.
    const std::string why = model.linearity.source;
    model.linearity = ZLinearity::UncharacterisedThreePointPeak();
    if (why.rfind("uncharacterised:", 0) != 0 || why.find(';') != std::string::npos) {
      model.linearity.source += " (" + why + ")";
    }
  }

  model.linearity_shape_known = model.linearity.characterised_step_um > 0.0 &&
                                model.linearity.source.find("transferred from") == std::string::npos;
  model.relative_amplification_u = options.verified.RelativeAmplificationUncertainty();
  if (options.verified.linearity_deviation_um && model.linearity.characterised_step_um <= 0.0) {
    // Not characterised at this step: the verified l_z bounds the deviation instead of +-step / 2.
    const double step = model.grid.median_step_um(), largest = model.linearity.MaxAbs() * step;
    const double lz = *options.verified.linearity_deviation_um;
    const std::optional<double>& verified_at = options.verified.linearity_step_um;
    if (verified_at && step > *verified_at * (1.0 + options.linearity_step_tolerance)) {
      model.linearity.source += "; the verified l_z (at " + std::to_string(*verified_at) +
                                " um steps) does not apply at " + std::to_string(step) + " um steps";
    } else if (largest > 0.0 && lz < largest) {
      for (double& v : model.linearity.bias_of_step) v *= lz / largest;
      model.linearity.source += "; scaled to the verified l_z " + std::to_string(lz) + " um";
    }
  }

  const cv::Mat finite = depth_um == depth_um;
  const int lag = options.window_px + 1;
  const double min_independent = 8.0;  // window areas needed for a usable estimate
  const double min_count = min_independent * options.window_px * options.window_px;

  // Estimate over `usable`; fills `var_x/var_y` (local, CV_64F, NaN where too few samples) and
  // returns the global per-direction variances (NaN when none).
  const int nb = options.neighbourhood_px > 0 ? (options.neighbourhood_px | 1) : (8 * options.window_px + 1);
  auto estimate = [&](const cv::Mat& usable, cv::Mat* local_var, double* global_var, double* extreme,
                      cv::Mat* extreme_map) {
    cv::Mat vx, cx, vy, cy;
    SecondDifferences(depth_um, usable, lag, true, &vx, &cx);
    SecondDifferences(depth_um, usable, lag, false, &vy, &cy);
    const double nx = cv::sum(cx)[0], ny = cv::sum(cy)[0];
    const double gx = nx >= min_count ? cv::sum(vx)[0] / nx : std::nan("");
    const double gy = ny >= min_count ? cv::sum(vy)[0] / ny : std::nan("");
    // A lay (structure along one axis) raises one direction's second differences: then use the
    // other only. Otherwise pool both (the minimum of two noisy estimates would be biased low).
    bool use_x = std::isfinite(gx), use_y = std::isfinite(gy);
    if (use_x && use_y) {
      if (gx > 1.5 * gy)
        use_x = false;
      else if (gy > 1.5 * gx)
        use_y = false;
    }
    if (!use_x && !use_y) {
      *global_var = std::nan("");
      return;
    }
    cv::Mat v = cv::Mat::zeros(depth_um.size(), CV_64F), c = cv::Mat::zeros(depth_um.size(), CV_64F);
    if (use_x) {
      v += vx;
      c += cx;
    }
    if (use_y) {
      v += vy;
      c += cy;
    }
    *global_var = cv::sum(v)[0] / cv::sum(c)[0];
    double max_x = 0.0, max_y = 0.0;  // of d2^2 / 6 (0 where no sample)
    if (use_x) cv::minMaxLoc(vx, nullptr, &max_x);
    if (use_y) cv::minMaxLoc(vy, nullptr, &max_y);
    *extreme = std::sqrt(6.0 * std::max(max_x, max_y)) / 2.0;
    *extreme_map = LocalExtremeError(depth_um, usable, lag, use_x, use_y);
    cv::Mat sv, sc;
    cv::boxFilter(v, sv, CV_64F, cv::Size(nb, nb), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    cv::boxFilter(c, sc, CV_64F, cv::Size(nb, nb), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    *local_var = cv::Mat(depth_um.size(), CV_64F, cv::Scalar(std::nan("")));
    for (int row = 0; row < depth_um.rows; ++row) {
      const double* a = sv.ptr<double>(row);
      const double* b = sc.ptr<double>(row);
      double* o = local_var->ptr<double>(row);
      for (int col = 0; col < depth_um.cols; ++col) {
        if (b[col] >= min_count) o[col] = a[col] / b[col];
      }
    }
  };

  const cv::Mat region = mask.empty() ? finite : (finite & mask);
  cv::Mat local_var, extreme_map;
  double global_var = std::nan(""), extreme = 0.0;
  estimate(region, &local_var, &global_var, &extreme, &extreme_map);
  if (!std::isfinite(global_var) && !mask.empty()) {
    // Too small a region for its own estimate: the whole map's noise level stands in.
    estimate(finite, &local_var, &global_var, &extreme, &extreme_map);
    local_var.setTo(std::nan(""));
    extreme_map = cv::Mat();
  }
  if (!std::isfinite(global_var)) {
    return Status::FailedPrecondition("depth noise: too few measured pixels to estimate the noise (needs runs of " +
                                      std::to_string(2 * lag + 1) + " measured pixels in x or y)");
  }
  model.global_sigma_um = std::sqrt(global_var);
  model.extreme_error_um = extreme;
  model.extreme_error_map_um = cv::Mat(depth_um.size(), CV_32FC1, cv::Scalar(std::nanf("")));
  for (int row = 0; row < depth_um.rows; ++row) {
    const uint8_t* r = region.ptr<uint8_t>(row);
    const float* e = extreme_map.empty() ? nullptr : extreme_map.ptr<float>(row);
    float* o = model.extreme_error_map_um.ptr<float>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (r[col]) o[col] = e && std::isfinite(e[col]) ? std::min(e[col], float(extreme)) : float(extreme);
    }
  }
  model.sigma_um = cv::Mat(depth_um.size(), CV_32FC1, cv::Scalar(std::nanf("")));
  for (int row = 0; row < depth_um.rows; ++row) {
    const uint8_t* r = region.ptr<uint8_t>(row);
    const double* lv = local_var.ptr<double>(row);
    float* s = model.sigma_um.ptr<float>(row);
    for (int col = 0; col < depth_um.cols; ++col) {
      if (r[col]) s[col] = float(std::sqrt(std::isfinite(lv[col]) ? lv[col] : global_var));
    }
  }
  return model;
}

DepthNoiseModel::StageSensitivity DepthNoiseModel::StageSensitivityAt(const ZGrid::Position& p) const {
  StageSensitivity a;
  const int frames = int(grid.positions_um().size());
  const int n = p.fraction < 0.5 ? p.lower : p.lower + 1;  // nearest frame, unclamped
  if (!three_point_peak || n < 1 || n > frames - 2) {
    // Maximum / line fit, or a depth at or beyond the grid's end frames (no frame on one side):
    // the nearest frame's error in full.
    a.frame[0] = p.nearest;
    a.weight[0] = -1.0;
    a.count = 1;
    return a;
  }
  const double x = p.fraction < 0.5 ? p.fraction : p.fraction - 1.0;
  a.frame[0] = n - 1;
  a.frame[1] = n;
  a.frame[2] = n + 1;
  a.weight[0] = 0.5 * (2.0 * x - 1.0) * (1.0 + x);
  a.weight[1] = -2.0 * x * x;
  a.weight[2] = 0.5 * (1.0 + 2.0 * x) * (x - 1.0);
  a.count = 3;
  return a;
}

cv::Mat DepthNoiseModel::SamplePerturbation(const cv::Mat& depth_um, uint64_t seed, int k, int count) const {
  const uint64_t stream = SplitMix(seed ^ SplitMix(uint64_t(k) + 0x1234567ull));
  const int r = correlation_px / 2;
  cv::Mat out(depth_um.size(), CV_32FC1, cv::Scalar(0.f));
  // Only the pixels with a sigma are perturbed: noise is drawn over their bounding box, on a
  // canvas padded by the box radius so every pixel's box is full.
  const cv::Rect box = cv::boundingRect(sigma_um == sigma_um);
  if (box.empty()) return out;
  cv::Mat white(box.height + 2 * r, box.width + 2 * r, CV_32FC1);
  cv::RNG rng(stream | 1u);
  rng.fill(white, cv::RNG::NORMAL, 0.0, 1.0);
  cv::Mat boxed;
  cv::boxFilter(white, boxed, CV_32F, cv::Size(correlation_px, correlation_px), cv::Point(-1, -1), false,
                cv::BORDER_CONSTANT);
  const cv::Mat correlated = boxed(cv::Rect(r, r, box.width, box.height));
  const float unit = 1.0f / float(correlation_px);  // box of w^2 unit variances: sum has variance w^2

  std::mt19937_64 gen(stream ^ 0xA5A5A5A5u);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  // One random phase offset per set (from the seed alone), then evenly spaced phases.
  std::mt19937_64 set_gen(SplitMix(seed));
  const double offset = uniform(set_gen);
  const double phase = offset + (k + 0.5) / double(std::max(count, 1));
  const int frames = int(grid.positions_um().size());
  std::vector<double> frame_error(frames, 0.0);
  const double half_width = stage_u_um * std::sqrt(3.0);
  for (double& e : frame_error) e = (2.0 * uniform(gen) - 1.0) * half_width;

  for (int row = box.y; row < box.y + box.height; ++row) {
    const float* z = depth_um.ptr<float>(row);
    const float* s = sigma_um.ptr<float>(row);
    const float* n = correlated.ptr<float>(row - box.y);
    float* o = out.ptr<float>(row);
    for (int col = box.x; col < box.x + box.width; ++col) {
      if (!std::isfinite(z[col]) || !std::isfinite(s[col])) continue;
      const ZGrid::Position p = grid.Locate(z[col]);
      double stage = 0.0;
      if (half_width > 0.0) {
        const StageSensitivity a = StageSensitivityAt(p);
        for (int j = 0; j < a.count; ++j) stage += a.weight[j] * frame_error[a.frame[j]];
      }
      o[col] = float(double(s[col]) * n[col - box.x] * unit + linearity.At(p.fraction + phase) * p.step_um + stage);
    }
  }
  return out;
}

}  // namespace inspection
