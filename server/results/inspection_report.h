// The inspection report: one self-contained HTML file per inspection result, written
// beside the depth map as an artifact (ARTIFACT_KIND_REPORT_HTML). Everything is inside the file:
// images as data: URIs (PNG), plots as inline SVG drawn here, no script and no remote resource,
// so it opens the same on a line PC without network as in the MES archive years later.
#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"

namespace inspection {

struct InspectionReportInput {
  // Measurements with tolerances and verdicts, profiles, part, recipe version, station, job,
  // calibration, timings.
  v1::InspectionResult inspection;
  // Scan metadata: size, pixel size, z range and step, frames, valid %, method, illumination.
  v1::DepthSummary depth;
  std::string recipe_description;
  cv::Mat depth_um;      // CV_32FC1, NaN = no depth
  cv::Mat all_in_focus;  // CV_8U or CV_16U, 1 or 3 channels (BGR); empty = not shown
};

// The report's HTML (UTF-8). It shows: the overall verdict (element id "verdict", text "OK",
// "NOT OK" or "NOT DECIDABLE"), the depth preview with its colour bar (um), the all-in-focus
// image, a histogram of heights, one plot per profile (height with its +-2u band against
// position), the measurement table (value, unit, U, coverage, tolerance limits, verdict and
// reason) and the scan metadata. Text from the recipe or the request is HTML-escaped.
// Embedded images are downscaled to at most 1024 px on the long side (the depth map by box means
// of its valid heights, so holes do not grow); the histogram is of the full-size map. An unset
// overall verdict is derived from the measurements as InspectionResult.verdict defines it (none:
// NOT DECIDABLE). About 1.6 MB for a 1024x768 scan with a textured all-in-focus image.
// INVALID_ARGUMENT when depth_um is empty or not CV_32FC1, or all_in_focus is neither empty nor
// CV_8U/CV_16U with 1 or 3 channels.
StatusOr<std::string> RenderInspectionReport(const InspectionReportInput& input);

}  // namespace inspection
