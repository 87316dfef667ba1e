// Areal Gaussian filter of ISO 16610-61 for the S-filter and L-filter of ISO 25178-2/-3:
// weighting function s(x, y) = 1 / (alpha^2 lc^2) exp(-pi (x^2 + y^2) / (alpha lc)^2) with
// alpha = sqrt(ln 2 / pi), so a sinusoid of wavelength lc keeps 50 % of its amplitude in the
// mean (smoothed) surface. Missing pixels (NaN, or outside the region) are handled by normalised
// convolution: mean = G * (z m) / G * m with m the 0/1 mask of usable pixels, which also gives
// the end-effect correction at the region's border (the weights are renormalised to the data).
#pragma once

#include <opencv2/core.hpp>

#include "core/util/status.h"

namespace inspection {

// alpha of ISO 16610-61 (and 16610-21): sqrt(ln 2 / pi) = 0.4697.
double GaussianFilterAlpha();
// Standard deviation (µm) of the Gaussian weighting function for a cut-off: alpha lc / sqrt(2 pi).
double GaussianFilterSigmaUm(double cutoff_um);
// Amplitude transmission of the Gaussian mean surface for a sinusoid of wavelength_um:
// exp(-pi (alpha lc / wavelength)^2); 0.5 at wavelength = lc.
double GaussianMeanTransmission(double cutoff_um, double wavelength_um);

// The filter for one set of usable pixels, prepared once: the normalisation G * m is computed
// at Create, so each MeanSurface costs one convolution (Monte Carlo runs it per sample).
class GaussianAreaFilter {
 public:
  // usable: CV_8UC1, non-zero = pixels that carry data. Errors as GaussianMeanSurface.
  static StatusOr<GaussianAreaFilter> Create(const cv::Mat& usable, double pixel_size_um, double cutoff_um);
  // surface_um: CV_32FC1 of the mask's size, finite on the usable pixels (others are ignored).
  // The mean surface on the usable pixels, NaN elsewhere.
  cv::Mat MeanSurface(const cv::Mat& surface_um) const;

 private:
  cv::Mat usable_;
  cv::Mat kernel_;      // CV_64F column, normalised
  cv::Rect pad_box_;    // usable pixels' bounding box grown by the kernel radius
  cv::Mat weight_sum_;  // CV_64F: G * m over pad_box_
};

// The Gaussian mean (smoothed) surface with cut-off cutoff_um of surface_um (CV_32FC1, NaN =
// missing) over the pixels where mask (CV_8UC1) is non-zero and the surface is finite. Returns
// CV_32FC1: the mean surface on those pixels, NaN elsewhere. The weighting function is sampled
// on the pixel grid out to +-cutoff (beyond it the weight is < 1e-6 of its peak) and normalised.
// S-filter (cut-off lambda_s): the result itself is the S-filtered surface.
// L-filter (cut-off lambda_c): surface - result is the L-filtered (SL) surface.
// INVALID_ARGUMENT for a non-positive cut-off or pixel size, or mismatched inputs.
StatusOr<cv::Mat> GaussianMeanSurface(const cv::Mat& surface_um, const cv::Mat& mask, double pixel_size_um,
                                      double cutoff_um);

}  // namespace inspection
