// Tilt, flatness (FLTt, least-squares reference) and volume against a reference plane, with
// their uncertainties.
#include "core/plane_measures.h"

#include <cmath>
#include <limits>

namespace inspection {
namespace {

constexpr double kDegPerRad = 180.0 / 3.14159265358979323846;

Status CheckInputs(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um, const char* what) {
  if (depth_um.empty() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("depth map must be a non-empty CV_32FC1 image");
  }
  if (mask.type() != CV_8UC1 || mask.size() != depth_um.size()) {
    return Status::InvalidArgument(std::string(what) + " mask must be CV_8UC1 of the depth map's size");
  }
  if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um)) return Status::InvalidArgument("pixel_size_um must be > 0");
  return Status::Ok();
}

// Standard uncertainty of |slope| from the slope covariance s (2x2), see TiltResult: both
// components' variances (radial and tangential).
double SlopeMagnitudeUncertainty(const Eigen::Matrix2d& s) { return std::sqrt(std::max(0.0, s.trace())); }

}  // namespace

StatusOr<TiltResult> MeasureTilt(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                 const DepthNoiseModel* noise) {
  INSPECT_RETURN_IF_ERROR(CheckInputs(depth_um, mask, pixel_size_um, "region"));
  TiltResult res;
  INSPECT_ASSIGN_OR_RETURN(res.plane, FitForm(depth_um, mask, pixel_size_um, FormOptions{}));
  const double gx = res.plane.parameters[1], gy = res.plane.parameters[2], m = std::hypot(gx, gy);
  res.tilt_deg = std::atan(m) * kDegPerRad;
  res.tilt_x_deg = std::atan(gx) * kDegPerRad;
  res.tilt_y_deg = std::atan(gy) * kDegPerRad;
  res.azimuth_deg = m > 0.0 ? std::atan2(gy, gx) * kDegPerRad : 0.0;
  if (noise != nullptr) {
    INSPECT_ASSIGN_OR_RETURN(FunctionalCovariance cov, FormFitCovariance(res.plane, depth_um, mask, pixel_size_um, *noise));
    const double to_deg = kDegPerRad / (1.0 + m * m);  // d atan(m) / dm
    auto part = [&](const Eigen::MatrixXd& c) {
      return to_deg * SlopeMagnitudeUncertainty(c.block<2, 2>(1, 1));
    };
    res.uncertainty.method = "analytic";
    res.uncertainty.random = part(cov.random);
    res.uncertainty.linearity = part(cov.linearity);
    res.uncertainty.stage = part(cov.stage);
    res.uncertainty.standard_uncertainty = part(cov.Total());
  }
  return res;
}

StatusOr<FlatnessResult> MeasureFlatness(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                         const DepthNoiseModel* noise) {
  INSPECT_RETURN_IF_ERROR(CheckInputs(depth_um, mask, pixel_size_um, "region"));
  FlatnessResult res;
  INSPECT_ASSIGN_OR_RETURN(res.plane, FitForm(depth_um, mask, pixel_size_um, FormOptions{}));
  const double gx = res.plane.parameters[1], gy = res.plane.parameters[2];
  const double cos_tilt = 1.0 / std::sqrt(1.0 + gx * gx + gy * gy);
  const cv::Mat r = FormResidual(depth_um, mask, pixel_size_um, res.plane);
  double lo = 0.0, hi = 0.0;
  cv::minMaxLoc(r, &lo, &hi, nullptr, nullptr, mask & (r == r));
  res.peak_um = hi * cos_tilt;
  res.valley_um = -lo * cos_tilt;
  res.flatness_um = res.peak_um + res.valley_um;
  if (noise != nullptr) {
    res.uncertainty = ExtremeValueBudget(2, LinearityRangeUm(depth_um, mask, *noise), *noise);
  }
  return res;
}

const char* VolumeReferenceName(VolumeReference r) {
  return r == VolumeReference::kRegionPlane ? "region_plane" : "height";
}

StatusOr<VolumeReference> ParseVolumeReference(const std::string& name) {
  if (name == "region_plane") return VolumeReference::kRegionPlane;
  if (name == "height") return VolumeReference::kHeight;
  return Status::InvalidArgument("unknown volume reference '" + name + "' (region_plane, height)");
}

StatusOr<VolumeResult> MeasureVolume(const cv::Mat& depth_um, const cv::Mat& region_mask,
                                     const cv::Mat& reference_mask, double pixel_size_um,
                                     const VolumeOptions& options, const DepthNoiseModel* noise,
                                     const MonteCarloOptions& monte_carlo) {
  INSPECT_RETURN_IF_ERROR(CheckInputs(depth_um, region_mask, pixel_size_um, "region"));
  const bool own_plane = reference_mask.empty();
  if (!own_plane && options.reference == VolumeReference::kRegionPlane) {
    INSPECT_RETURN_IF_ERROR(CheckInputs(depth_um, reference_mask, pixel_size_um, "reference region"));
  }
  if (options.reference == VolumeReference::kHeight && !std::isfinite(options.reference_height_um)) {
    return Status::InvalidArgument("reference_height_um must be finite");
  }
  const size_t region_pixels = size_t(cv::countNonZero(region_mask));
  const double area_um2 = pixel_size_um * pixel_size_um;
  // Above and below for one depth map (also run on the Monte Carlo's perturbed maps).
  auto volumes = [&](const cv::Mat& z, size_t* measured) -> StatusOr<std::vector<double>> {
    FormFit plane;
    if (options.reference == VolumeReference::kRegionPlane) {
      StatusOr<FormFit> f = FitForm(z, own_plane ? region_mask : reference_mask, pixel_size_um, FormOptions{});
      if (!f.ok()) return f.status().WithContext(own_plane ? "region" : "reference region");
      plane = std::move(f).value();
    }
    double above = 0.0, below = 0.0;
    size_t n = 0;
    for (int row = 0; row < z.rows; ++row) {
      const float* d = z.ptr<float>(row);
      const uint8_t* m = region_mask.ptr<uint8_t>(row);
      const double y = PixelCentreUm(row, pixel_size_um);
      for (int col = 0; col < z.cols; ++col) {
        if (!m[col] || !std::isfinite(d[col])) continue;
        const double ref = options.reference == VolumeReference::kHeight
                               ? options.reference_height_um
                               : plane.Evaluate(PixelCentreUm(col, pixel_size_um), y);
        const double h = double(d[col]) - ref;
        (h > 0.0 ? above : below) += std::abs(h);
        ++n;
      }
    }
    if (n == 0) return Status::FailedPrecondition("the region has no measured pixel");
    if (measured) *measured = n;
    const double fill = double(region_pixels) / double(n);
    return std::vector<double>{above * area_um2 * fill, below * area_um2 * fill};
  };
  VolumeResult res;
  res.region_pixels = region_pixels;
  INSPECT_ASSIGN_OR_RETURN(std::vector<double> v, volumes(depth_um, &res.measured_pixels));
  res.above_um3 = v[0];
  res.below_um3 = v[1];
  if (noise != nullptr) {
    auto measure = [&](const cv::Mat& z) { return volumes(z, nullptr); };
    INSPECT_ASSIGN_OR_RETURN(std::vector<MonteCarloEstimate> mc,
                             MonteCarloUncertainty(depth_um, v, measure, *noise, monte_carlo));
    const double filled = 1.0 - double(res.measured_pixels) / double(std::max<size_t>(region_pixels, 1));
    UncertaintyBudget* budgets[2] = {&res.above_uncertainty, &res.below_uncertainty};
    for (int i = 0; i < 2; ++i) {
      *budgets[i] = MonteCarloBudget(mc[i]);
      budgets[i]->other = filled * v[i] / std::sqrt(3.0);
      budgets[i]->standard_uncertainty = std::hypot(mc[i].standard_uncertainty, budgets[i]->other);
    }
  }
  return res;
}

}  // namespace inspection
