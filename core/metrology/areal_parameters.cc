// ISO 25178-2 height parameters over a masked, scale-limited surface (ISO 25178-3 operator order).
#include "core/metrology/areal_parameters.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace inspection {

StatusOr<ArealHeightParameters> ComputeHeightParameters(const cv::Mat& surface_um, const cv::Mat& mask) {
  if (surface_um.empty() || surface_um.type() != CV_32FC1) {
    return Status::InvalidArgument("surface must be a non-empty CV_32FC1 image");
  }
  if (mask.type() != CV_8UC1 || mask.size() != surface_um.size()) {
    return Status::InvalidArgument("mask must be CV_8UC1 of the surface's size");
  }
  double s1 = 0.0, s2 = 0.0, s3 = 0.0, s4 = 0.0;
  double hi = -std::numeric_limits<double>::infinity(), lo = std::numeric_limits<double>::infinity();
  size_t n = 0;
  for (int row = 0; row < surface_um.rows; ++row) {
    const float* z = surface_um.ptr<float>(row);
    const uint8_t* m = mask.ptr<uint8_t>(row);
    for (int col = 0; col < surface_um.cols; ++col) {
      if (!m[col] || !std::isfinite(z[col])) continue;
      const double v = z[col], v2 = v * v;
      s1 += std::abs(v);
      s2 += v2;
      s3 += v2 * v;
      s4 += v2 * v2;
      hi = std::max(hi, v);
      lo = std::min(lo, v);
      ++n;
    }
  }
  if (n == 0) return Status::FailedPrecondition("the region has no measured pixel");
  ArealHeightParameters p;
  const double dn = double(n);
  p.pixel_count = n;
  p.Sa_um = s1 / dn;
  p.Sq_um = std::sqrt(s2 / dn);
  p.Sp_um = hi;
  p.Sv_um = -lo;
  p.Sz_um = hi - lo;
  const double sq2 = s2 / dn;
  p.Ssk = sq2 > 0.0 ? (s3 / dn) / (sq2 * p.Sq_um) : std::nan("");
  p.Sku = sq2 > 0.0 ? (s4 / dn) / (sq2 * sq2) : std::nan("");
  return p;
}

const char* HeightParameterName(HeightParameter p) {
  switch (p) {
    case HeightParameter::kSa:
      return "Sa";
    case HeightParameter::kSq:
      return "Sq";
    case HeightParameter::kSp:
      return "Sp";
    case HeightParameter::kSv:
      return "Sv";
    case HeightParameter::kSz:
      return "Sz";
    case HeightParameter::kSsk:
      return "Ssk";
    case HeightParameter::kSku:
      return "Sku";
  }
  return "unknown";
}

const char* HeightParameterUnit(HeightParameter p) {
  return p == HeightParameter::kSsk || p == HeightParameter::kSku ? "" : "um";
}

StatusOr<HeightParameter> ParseHeightParameter(const std::string& name) {
  for (HeightParameter p : {HeightParameter::kSa, HeightParameter::kSq, HeightParameter::kSp, HeightParameter::kSv,
                            HeightParameter::kSz, HeightParameter::kSsk, HeightParameter::kSku}) {
    if (name == HeightParameterName(p)) return p;
  }
  return Status::InvalidArgument("unknown areal height parameter '" + name + "' (Sa, Sq, Sp, Sv, Sz, Ssk, Sku)");
}

double HeightParameterValue(const ArealHeightParameters& v, HeightParameter p) {
  switch (p) {
    case HeightParameter::kSa:
      return v.Sa_um;
    case HeightParameter::kSq:
      return v.Sq_um;
    case HeightParameter::kSp:
      return v.Sp_um;
    case HeightParameter::kSv:
      return v.Sv_um;
    case HeightParameter::kSz:
      return v.Sz_um;
    case HeightParameter::kSsk:
      return v.Ssk;
    case HeightParameter::kSku:
      return v.Sku;
  }
  return std::nan("");
}

Status ArealOptions::Validate() const {
  {
    const Status s = form.Validate();
    if (!s.ok()) return s.WithContext("form");
  }
  if (!(s_filter_cutoff_um >= 0.0) || !std::isfinite(s_filter_cutoff_um)) {
    return Status::InvalidArgument("s_filter_cutoff_um must be >= 0 (0 = no S-filter)");
  }
  if (!(l_filter_cutoff_um >= 0.0) || !std::isfinite(l_filter_cutoff_um)) {
    return Status::InvalidArgument("l_filter_cutoff_um must be >= 0 (0 = no L-filter)");
  }
  if (s_filter_cutoff_um > 0.0 && l_filter_cutoff_um > 0.0 && !(l_filter_cutoff_um > s_filter_cutoff_um)) {
    return Status::InvalidArgument("l_filter_cutoff_um must exceed s_filter_cutoff_um");
  }
  return Status::Ok();
}

StatusOr<ArealEvaluator> ArealEvaluator::Create(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                                const ArealOptions& options) {
  INSPECT_RETURN_IF_ERROR(options.Validate());
  if (depth_um.empty() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("depth map must be a non-empty CV_32FC1 image");
  }
  if (mask.type() != CV_8UC1 || mask.size() != depth_um.size()) {
    return Status::InvalidArgument("mask must be CV_8UC1 of the depth map's size");
  }
  ArealEvaluator e;
  e.usable_ = mask & (depth_um == depth_um);
  e.pixel_size_um_ = pixel_size_um;
  e.options_ = options;
  if (options.s_filter_cutoff_um > 0.0) {
    auto f = GaussianAreaFilter::Create(e.usable_, pixel_size_um, options.s_filter_cutoff_um);
    if (!f.ok()) return f.status().WithContext("s_filter_cutoff_um");
    e.s_filter_ = std::move(f).value();
  }
  if (options.l_filter_cutoff_um > 0.0) {
    auto f = GaussianAreaFilter::Create(e.usable_, pixel_size_um, options.l_filter_cutoff_um);
    if (!f.ok()) return f.status().WithContext("l_filter_cutoff_um");
    e.l_filter_ = std::move(f).value();
  }
  return e;
}

StatusOr<ArealEvaluation> ArealEvaluator::Evaluate(const cv::Mat& depth_um) const {
  if (depth_um.size() != usable_.size() || depth_um.type() != CV_32FC1) {
    return Status::InvalidArgument("depth map does not match the evaluator's region");
  }
  const cv::Mat primary = s_filter_ ? s_filter_->MeanSurface(depth_um) : depth_um;
  ArealEvaluation e;
  INSPECT_ASSIGN_OR_RETURN(e.form, FitForm(primary, usable_, pixel_size_um_, options_.form));
  e.surface_um = FormResidual(primary, usable_, pixel_size_um_, e.form);
  if (l_filter_) e.surface_um -= l_filter_->MeanSurface(e.surface_um);  // NaN where either is NaN
  INSPECT_ASSIGN_OR_RETURN(e.parameters, ComputeHeightParameters(e.surface_um, usable_));
  return e;
}

StatusOr<ArealEvaluation> EvaluateArealSurface(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                               const ArealOptions& options) {
  INSPECT_ASSIGN_OR_RETURN(ArealEvaluator evaluator, ArealEvaluator::Create(depth_um, mask, pixel_size_um, options));
  return evaluator.Evaluate(depth_um);
}

}  // namespace inspection
