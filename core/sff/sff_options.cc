// Names, parsing and validation of the SFF engine's options (core/sff/sff_options.h).
#include "core/sff/sff_options.h"

namespace inspection {

const char* FocusMeasureName(FocusMeasure m) {
  switch (m) {
    case FocusMeasure::kModifiedLaplacian:
      return "ml";
    case FocusMeasure::kSumModifiedLaplacian:
      return "sml";
    case FocusMeasure::kTenengrad:
      return "tenengrad";
    case FocusMeasure::kGreyLevelVariance:
      return "variance";
    case FocusMeasure::kHelmliMean:
      return "helmli-mean";
    case FocusMeasure::kChebyshevMoments:
      return "chebyshev";
    case FocusMeasure::kGreyLevelLocalVariance:
      return "glvm";
  }
  return "unknown";
}

StatusOr<FocusMeasure> ParseFocusMeasure(const std::string& name) {
  for (FocusMeasure m : {FocusMeasure::kModifiedLaplacian, FocusMeasure::kSumModifiedLaplacian,
                         FocusMeasure::kTenengrad, FocusMeasure::kGreyLevelVariance, FocusMeasure::kHelmliMean,
                         FocusMeasure::kChebyshevMoments, FocusMeasure::kGreyLevelLocalVariance}) {
    if (name == FocusMeasureName(m)) return m;
  }
  return Status::InvalidArgument("focus_measure '" + name +
                                 "' is unknown (ml, sml, tenengrad, variance, helmli-mean, chebyshev, glvm)");
}

const char* DepthInterpolationName(DepthInterpolation i) {
  switch (i) {
    case DepthInterpolation::kMaximum:
      return "maximum";
    case DepthInterpolation::kLineFit:
      return "linefit";
    case DepthInterpolation::kGaussian:
      return "gaussian";
    case DepthInterpolation::kDefocusParabola:
      return "defocus_parabola";
  }
  return "unknown";
}

StatusOr<DepthInterpolation> ParseDepthInterpolation(const std::string& name) {
  for (DepthInterpolation i : {DepthInterpolation::kMaximum, DepthInterpolation::kLineFit,
                               DepthInterpolation::kGaussian, DepthInterpolation::kDefocusParabola}) {
    if (name == DepthInterpolationName(i)) return i;
  }
  return Status::InvalidArgument("interpolation '" + name +
                                 "' is unknown (maximum, linefit, gaussian, defocus_parabola)");
}

Status SffOptions::Validate() const {
  if (window_px < 3 || window_px > 31 || window_px % 2 == 0) {
    return Status::InvalidArgument("window_px " + std::to_string(window_px) + " must be odd and between 3 and 31");
  }
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) {
    return Status::InvalidArgument("min_confidence must be between 0 and 1");
  }
  if (threads < 0) return Status::InvalidArgument("threads must be >= 0");
  if (linefit_half_width < 1 || linefit_half_width > 4) {
    return Status::InvalidArgument("linefit_half_width " + std::to_string(linefit_half_width) + " must be 1..4");
  }
  switch (focus_measure) {
    case FocusMeasure::kModifiedLaplacian:
    case FocusMeasure::kSumModifiedLaplacian:
    case FocusMeasure::kTenengrad:
    case FocusMeasure::kGreyLevelVariance:
    case FocusMeasure::kHelmliMean:
    case FocusMeasure::kChebyshevMoments:
    case FocusMeasure::kGreyLevelLocalVariance:
      break;
    default:
      return Status::InvalidArgument("focus_measure is unknown");
  }
  switch (interpolation) {
    case DepthInterpolation::kMaximum:
    case DepthInterpolation::kLineFit:
    case DepthInterpolation::kGaussian:
    case DepthInterpolation::kDefocusParabola:
      break;
    default:
      return Status::InvalidArgument("interpolation is unknown");
  }
  return Status::Ok();
}

}  // namespace inspection
