// ISO 25178-600 metrological characteristics of an areal topography instrument, determined from
// measurements of ISO 25178-70 material measures as ISO 25178-700 describes (the evaluation only;
// acquiring the measures is the rig's). Each characteristic comes with its standard uncertainty
// (k = 1) from the evidence it was computed from:
//   N_M     measurement noise: two repeated maps of a flat (AFL), Sq of their difference / sqrt 2
//   z_FLT   flatness deviation: peak-to-valley of the levelled flat, noise averaged out
//   alpha_z amplification coefficient and l_z linearity deviation: step heights (PGR) measured
//           against their certified values, slope of the response line and its largest residual
//   alpha_x, alpha_y lateral amplification: a grating's (ACG) measured pitch / its certified pitch
//   W_R     topographic spatial resolution: the period at which a sinusoid's (ASG) measured
//           amplitude has fallen to 50 % of its certified one
// Maps are CV_32FC1 in um, NaN = no depth; correlation_px is the lateral correlation length of
// the depth noise (the focus window), which sets how many independent samples a map holds.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/util/status.h"

namespace inspection {

struct CharacteristicEstimate {
  double value = 0.0;
  double standard_uncertainty = 0.0;  // k = 1
};

// INVALID_ARGUMENT naming `a`/`b` for empty, differently sized or non-float maps, or fewer than
// 100 pixels finite in both; correlation_px >= 1.
StatusOr<CharacteristicEstimate> MeasurementNoise(const cv::Mat& a, const cv::Mat& b, int correlation_px);

// z_FLT from the same two maps of a flat: their mean, levelled by a least-squares plane, averaged
// over blocks of 4 x 4 correlation lengths (so the noise N_M does not read as form), max - min.
// u: the residual noise of the two extremes (N_M / sqrt 2 / 4 per block mean, times the expected
// extreme of that many blocks, sqrt(2 ln blocks)).
StatusOr<CharacteristicEstimate> FlatnessDeviation(const cv::Mat& a, const cv::Mat& b, int correlation_px);

struct ResponsePoint {
  double certified_um = 0.0;
  double certified_u_um = 0.0;  // the certificate's standard uncertainty
  double measured_um = 0.0;
  double measured_u_um = 0.0;   // the measurement's standard uncertainty
};
struct AmplificationLinearity {
  CharacteristicEstimate alpha_z;  // slope of measured against certified (1 = perfect)
  CharacteristicEstimate offset_um;
  CharacteristicEstimate l_z_um;   // largest |residual| from the response line
};
// Weighted least squares (weights 1 / (u_meas^2 + alpha^2 u_cert^2), two passes). INVALID_ARGUMENT
// for fewer than 2 points, non-positive uncertainties or certified values all equal.
StatusOr<AmplificationLinearity> AmplificationAndLinearity(const std::vector<ResponsePoint>& points);

// alpha for one axis from a grating's depth map: the mean profile along the axis (rows averaged
// for x, columns for y), its period from the zero crossings of the detrended profile (linear
// interpolation), divided by certified_pitch_um. axis 0 = x, 1 = y. INVALID_ARGUMENT when fewer
// than 3 periods are in the field.
StatusOr<CharacteristicEstimate> LateralAmplification(const cv::Mat& grating_um, double pixel_size_um,
                                                      double certified_pitch_um, int axis);

struct TransferPoint {
  double period_um = 0.0;
  double certified_amplitude_um = 0.0;
  double measured_amplitude_um = 0.0;
  double measured_amplitude_u_um = 0.0;
};
// W_R: the period where measured / certified amplitude crosses 0.5, linearly interpolated
// between the two sinusoids bracketing it. FAILED_PRECONDITION when no pair brackets 0.5 (all
// resolved, or none: measure finer or coarser patterns).
StatusOr<CharacteristicEstimate> TopographicSpatialResolution(std::vector<TransferPoint> points);

// Amplitude of a sinusoid along x in a map: sqrt(2) x Sq of the mean row profile after removing
// its linear trend, with its uncertainty from the profile's noise (for TransferPoint).
StatusOr<CharacteristicEstimate> SinusoidAmplitudeAlongX(const cv::Mat& map_um, int correlation_px);

// Amplitude of the fundamental of a sinusoid along x of nominal period period_um: the mean row
// profile (linear trend removed) projected onto sin and cos at the period that maximises the
// projection within +-15 % of the nominal (so a lateral scale error does not leak amplitude),
// with its uncertainty from the profile's residual noise. Content at other periods (texture
// artefacts, harmonics) does not count, unlike SinusoidAmplitudeAlongX. INVALID_ARGUMENT for
// fewer than 2 periods in the field.
StatusOr<CharacteristicEstimate> SinusoidFundamentalAlongX(const cv::Mat& map_um, double pixel_size_um,
                                                           double period_um, int correlation_px);

// Depth of a groove (ISO 5436-1 type A1, a PGR measure) running along y through the middle third
// of the map along x: a least-squares plane through the two lands (the outer thirds, without a
// sixth of their width next to the groove's edges and the map's border) evaluated under the
// central third of the groove, minus the groove's depth there, averaged. u: the lands' and the
// bottom's residual scatter over their independent samples (pixels / correlation_px^2).
// INVALID_ARGUMENT for a map narrower than 18 px or with fewer than 100 finite pixels in a region.
StatusOr<CharacteristicEstimate> GrooveDepth(const cv::Mat& map_um, int correlation_px);

}  // namespace inspection
