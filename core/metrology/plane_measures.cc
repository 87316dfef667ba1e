// Tilt, flatness (FLTt, least-squares reference) and volume against a reference plane, with
// their uncertainties.
#include "core/metrology/plane_measures.h"

#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

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
  if (!(pixel_size_um > 0.0) || !std::isfinite(pixel_size_um))
    return Status::InvalidArgument("pixel_size_um must be > 0");
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
    INSPECT_ASSIGN_OR_RETURN(FunctionalCovariance cov,
                             FormFitCovariance(res.plane, depth_um, mask, pixel_size_um, *noise));
    const double to_deg = kDegPerRad / (1.0 + m * m);  // d atan(m) / dm
    auto part = [&](const Eigen::MatrixXd& c) { return to_deg * SlopeMagnitudeUncertainty(c.block<2, 2>(1, 1)); };
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

StatusOr<VolumeReference> ParseVolumeReference(const std::string& name) {
  if (name == "region_plane") return VolumeReference::kRegionPlane;
  if (name == "height") return VolumeReference::kHeight;
  return Status::InvalidArgument("unknown volume reference '" + name + "' (region_plane, height)");
}

StatusOr<VolumeResult> MeasureVolume(const cv::Mat& depth_um, const cv::Mat& region_mask, const cv::Mat& reference_mask,
                                     double pixel_size_um, const VolumeOptions& options, const DepthNoiseModel* noise,
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
  const cv::Rect box = cv::boundingRect(region_mask);
  // Region pixels without depth take the Gaussian-weighted mean height (above the reference) of
  // the measured pixels around them (normalised convolution, sigma kFillSigmaPx); those with no
  // measured pixel nearby are covered by scaling the sums to the whole region.
  constexpr double kFillSigmaPx = 4.0, kFillMinWeight = 0.05;
  const int pad = int(std::ceil(3.0 * kFillSigmaPx));
  const cv::Rect work =
      (box + cv::Size(2 * pad, 2 * pad) - cv::Point(pad, pad)) & cv::Rect(0, 0, depth_um.cols, depth_um.rows);
  // Above, below, and the parts of each that come from filled pixels (outputs 2 and 3).
  auto volumes = [&](const cv::Mat& z, size_t* measured) -> StatusOr<std::vector<double>> {
    FormFit plane;
    if (options.reference == VolumeReference::kRegionPlane) {
      StatusOr<FormFit> f = FitForm(z, own_plane ? region_mask : reference_mask, pixel_size_um, FormOptions{});
      if (!f.ok()) return f.status().WithContext(own_plane ? "region" : "reference region");
      plane = std::move(f).value();
    }
    auto reference = [&](int row, int col) {
      return options.reference == VolumeReference::kHeight
                 ? options.reference_height_um
                 : plane.Evaluate(PixelCentreUm(col, pixel_size_um), PixelCentreUm(row, pixel_size_um));
    };
    cv::Mat h = cv::Mat::zeros(work.size(), CV_64F), m = cv::Mat::zeros(work.size(), CV_64F);
    size_t n = 0;
    for (int r = 0; r < work.height; ++r) {
      const float* d = z.ptr<float>(r + work.y) + work.x;
      const uint8_t* inside = region_mask.ptr<uint8_t>(r + work.y) + work.x;
      for (int c = 0; c < work.width; ++c) {
        if (!inside[c] || !std::isfinite(d[c])) continue;
        h.at<double>(r, c) = double(d[c]) - reference(r + work.y, c + work.x);
        m.at<double>(r, c) = 1.0;
        ++n;
      }
    }
    if (n == 0) return Status::FailedPrecondition("the region has no measured pixel");
    cv::Mat hs, ms;
    cv::GaussianBlur(h, hs, cv::Size(2 * pad + 1, 2 * pad + 1), kFillSigmaPx, kFillSigmaPx, cv::BORDER_CONSTANT);
    cv::GaussianBlur(m, ms, cv::Size(2 * pad + 1, 2 * pad + 1), kFillSigmaPx, kFillSigmaPx, cv::BORDER_CONSTANT);
    double above = 0.0, below = 0.0, above_filled = 0.0, below_filled = 0.0;
    size_t filled = 0;
    for (int r = 0; r < work.height; ++r) {
      const uint8_t* inside = region_mask.ptr<uint8_t>(r + work.y) + work.x;
      for (int c = 0; c < work.width; ++c) {
        if (!inside[c]) continue;
        double v;
        const bool is_measured = m.at<double>(r, c) > 0.0;
        if (is_measured) {
          v = h.at<double>(r, c);
        } else if (ms.at<double>(r, c) > kFillMinWeight) {
          v = hs.at<double>(r, c) / ms.at<double>(r, c);
          ++filled;
          (v > 0.0 ? above_filled : below_filled) += std::abs(v);
        } else {
          continue;
        }
        (v > 0.0 ? above : below) += std::abs(v);
      }
    }
    if (measured) *measured = n;
    const double scale = area_um2 * double(region_pixels) / double(n + filled);
    return std::vector<double>{above * scale, below * scale, above_filled * scale, below_filled * scale,
                               double(n + filled)};
  };
  VolumeResult res;
  res.region_pixels = region_pixels;
  INSPECT_ASSIGN_OR_RETURN(std::vector<double> v, volumes(depth_um, &res.measured_pixels));
  res.above_um3 = v[0];
  res.below_um3 = v[1];
  if (noise != nullptr) {
    auto measure = [&](const cv::Mat& z) -> StatusOr<std::vector<double>> {
      INSPECT_ASSIGN_OR_RETURN(std::vector<double> w, volumes(z, nullptr));
      return std::vector<double>{w[0], w[1]};
    };
    INSPECT_ASSIGN_OR_RETURN(std::vector<MonteCarloEstimate> mc,
                             MonteCarloUncertainty(depth_um, {v[0], v[1]}, measure, *noise, monte_carlo));
    // Filled pixels: their contribution is uncertain by +-100 % (rectangular); pixels too far from
    // any measurement to be filled: the region's mean stands in for them, with the same bound.
    const double unfilled = 1.0 - v[4] / double(std::max<size_t>(region_pixels, 1));
    UncertaintyBudget* budgets[2] = {&res.above_uncertainty, &res.below_uncertainty};
    for (int i = 0; i < 2; ++i) {
      *budgets[i] = MonteCarloBudget(mc[i]);
      budgets[i]->other = (v[2 + i] + unfilled * v[i]) / std::sqrt(3.0);
      budgets[i]->standard_uncertainty = std::hypot(mc[i].standard_uncertainty, budgets[i]->other);
    }
  }
  return res;
}

}  // namespace inspection
