// The Type-1 study report: one self-contained HTML page per study (an artifact of the study job,
// ARTIFACT_KIND_REPORT_HTML "study_report.html"), like the inspection report: no script, no remote
// resource, plots as inline SVG, a Content-Security-Policy that forbids anything else.
#pragma once

#include <string>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"

namespace inspection {

// Shows: the overall outcome (element id "capability", text "CAPABLE" or "NOT CAPABLE"), the
// study's identity (recipe and version, part, repeats, calibration, re-positioning), and per
// measurement (section class "study-measurement", data-name) a table of n, mean, s, reference
// (and where it came from), T, Cg, Cgk, bias with t, t_crit and p, U/T and the reason; a run chart
// (<svg class="run-chart">: one <circle class="run-point" data-repeat data-value> per repeat, a
// polyline through them, lines for the reference, reference +- 0.1 T and the mean) and a histogram
// (<svg class="value-histogram">: <rect class="hist-bar" data-count> per bin). Text from the recipe
// or the request is HTML-escaped. INVALID_ARGUMENT when a measurement has no values.
StatusOr<std::string> RenderStudyReport(const v1::Study& study, const std::string& recipe_description);

}  // namespace inspection
