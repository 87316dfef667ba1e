// ISO 25178-2 areal height parameters (Sa, Sq, Sp, Sv, Sz, Ssk, Sku) of a region's
// scale-limited surface: S-filter (ISO 16610-61 Gaussian, optional) -> F-operator (form removal,
// core/metrology/form_removal.h) -> L-filter (Gaussian, optional), as ISO 25178-3 orders them.
// Heights are taken from the reference surface (the fitted form, and with an L-filter also its
// Gaussian mean surface), as ISO 25178-2 defines them; they are not re-centred on their mean.
#pragma once

#include <opencv2/core.hpp>
#include <optional>
#include <string>

#include "core/metrology/areal_filter.h"
#include "core/metrology/form_removal.h"
#include "core/util/status.h"

namespace inspection {

// The seven height parameters of ISO 25178-2 4.1 (µm; Ssk and Sku dimensionless), discrete
// sums over the N measured pixels of the region standing in for the integrals over the
// definition area:
//   Sa = mean |z|, Sq = sqrt(mean z^2), Sp = max z, Sv = -min z (a positive depth when the
//   lowest point lies below the reference), Sz = Sp + Sv, Ssk = mean z^3 / Sq^3,
//   Sku = mean z^4 / Sq^4.
// For z = A sin(2 pi x / lambda) over whole periods: Sa = 2A/pi, Sq = A/sqrt 2, Sp = Sv = A,
// Sz = 2A, Ssk = 0, Sku = 1.5 (tests/core/metrology/areal_parameters_test.cc).
struct ArealHeightParameters {
  double Sa_um = 0.0;
  double Sq_um = 0.0;
  double Sp_um = 0.0;
  double Sv_um = 0.0;
  double Sz_um = 0.0;
  double Ssk = 0.0;  // NaN when Sq = 0
  double Sku = 0.0;  // NaN when Sq = 0
  size_t pixel_count = 0;
};

// Parameters of surface_um (CV_32FC1, heights from the reference) over the pixels where mask is
// non-zero and the surface is finite. FAILED_PRECONDITION when no pixel is usable.
StatusOr<ArealHeightParameters> ComputeHeightParameters(const cv::Mat& surface_um, const cv::Mat& mask);

// The height parameters by their ISO 25178-2 names: "Sa", "Sq", "Sp", "Sv", "Sz", "Ssk", "Sku".
// INVALID_ARGUMENT for other names (the message lists them).
enum class HeightParameter { kSa, kSq, kSp, kSv, kSz, kSsk, kSku };
const char* HeightParameterName(HeightParameter p);
const char* HeightParameterUnit(HeightParameter p);  // "um" or "" (Ssk, Sku)
StatusOr<HeightParameter> ParseHeightParameter(const std::string& name);
double HeightParameterValue(const ArealHeightParameters& values, HeightParameter p);

struct ArealOptions {
  FormOptions form;               // F-operator; the ISO 25178 default is the least-squares plane
  double s_filter_cutoff_um = 0;  // lambda_s of the S-filter; 0 = none
  double l_filter_cutoff_um = 0;  // lambda_c of the L-filter; 0 = none (must exceed lambda_s)
  // INVALID_ARGUMENT naming the field (negative or non-finite cut-offs, lambda_c <= lambda_s).
  Status Validate() const;
};

// The scale-limited surface of one region and its parameters.
struct ArealEvaluation {
  cv::Mat surface_um;  // CV_32FC1: heights from the reference on the region's measured pixels, NaN elsewhere
  FormFit form;
  ArealHeightParameters parameters;
};

// depth_um: CV_32FC1 (NaN = no depth); mask: CV_8UC1 region (e.g. RoiMask::measured).
// Errors as FitForm / GaussianMeanSurface, with the option's field named.
StatusOr<ArealEvaluation> EvaluateArealSurface(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                               const ArealOptions& options);

// The same pipeline prepared for one region and one set of measured pixels, for repeated
// evaluation (the Monte Carlo of core/metrology/measurement_uncertainty.h): the filters' normalisation is
// computed once. Evaluate takes maps with depth on the same pixels as the one given to Create
// (e.g. that map plus a perturbation); other pixels are ignored.
class ArealEvaluator {
 public:
  static StatusOr<ArealEvaluator> Create(const cv::Mat& depth_um, const cv::Mat& mask, double pixel_size_um,
                                         const ArealOptions& options);
  StatusOr<ArealEvaluation> Evaluate(const cv::Mat& depth_um) const;

 private:
  cv::Mat usable_;  // mask and finite depth
  double pixel_size_um_ = 0.0;
  ArealOptions options_;
  std::optional<GaussianAreaFilter> s_filter_;
  std::optional<GaussianAreaFilter> l_filter_;
};

}  // namespace inspection
