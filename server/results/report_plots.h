// The inspection report's plots: a histogram of the depth map's valid heights and the
// line profiles (height with its +-2u band against position), drawn as inline SVG with axes in
// um; plus the HTML escaping and number formatting the report and its plots share.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "inspection/v1/inspection.pb.h"

namespace inspection {

// Escapes & < > " ' so user text (part ids, names, reasons) can only ever be text, in element
// content and in attribute values alike.
std::string HtmlEscape(std::string_view text);

// "%.*f" with a '.' decimal point whatever the process locale; NaN/inf as "n/a".
std::string FormatFixed(double value, int decimals);
// Up to `significant` significant digits, trailing zeros dropped ("%.*g"); NaN/inf as "n/a".
std::string FormatSignificant(double value, int significant);

// Equal-width bins over the finite heights, from the smallest to the largest (the largest falls
// into the last bin). A map whose valid heights are all equal gets one bin 1 um wide centred on
// them; a map without any gets no bins.
struct HeightHistogram {
  double lo_um = 0.0;         // lower edge of bin 0
  double bin_width_um = 0.0;  // bin i covers [lo_um + i w, lo_um + (i + 1) w)
  std::vector<int64_t> counts;
  int64_t valid_count = 0;  // finite pixels (the sum of counts)
  int64_t pixel_count = 0;  // all pixels
};
inline constexpr int kHeightHistogramBins = 64;
// depth_um: CV_32FC1 (the caller checks), NaN = no depth.
HeightHistogram ComputeHeightHistogram(const cv::Mat& depth_um, int bins = kHeightHistogramBins);

// <svg class="height-histogram"> with one <rect class="hist-bar"> per bin carrying data-bin,
// data-lo-um, data-hi-um and data-count (what a reader or a test can check against the map),
// x axis "height z [µm]" and y axis "pixels" with ticks.
std::string RenderHistogramSvg(const HeightHistogram& histogram);

// <svg class="profile-plot"> of one profile: one <polyline class="profile-line"> per run of
// samples with a height (a NaN breaks the line; a run of one sample is a <circle
// class="profile-point">), under it one <polygon class="profile-band"> per run for height +-2u
// when standard_uncertainty_um has one value per sample; axes "position along the line [µm]"
// and "height z [µm]" with ticks. A profile without any height shows "no height in the band".
std::string RenderProfileSvg(const v1::ProfileResult& profile);

}  // namespace inspection
