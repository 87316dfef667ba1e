// The Type-1 study report: figures, run chart and histogram per measurement, as inline SVG.
#include "server/results/study_report.h"

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "server/results/report_plots.h"

#ifdef INSPECT_VERSION
#define INSPECT_STUDY_REPORT_VERSION INSPECT_VERSION
#else
#define INSPECT_STUDY_REPORT_VERSION "(development build)"
#endif

namespace inspection {
namespace {

const char* kStyle = R"css(
:root { --ok: #1b7f3b; --nok: #c62828; --ink: #1d2329; --muted: #5b6670; --line: #d5dae0; --ref: #1f5fa8; }
* { box-sizing: border-box; }
body { margin: 0; font: 14px/1.45 "DejaVu Sans", "Liberation Sans", Arial, sans-serif; color: var(--ink);
       background: #f4f6f8; -webkit-print-color-adjust: exact; print-color-adjust: exact; }
main { max-width: 1180px; margin: 0 auto; padding: 16px 20px 32px; }
header.report-head { display: flex; gap: 24px; align-items: stretch; margin-bottom: 16px; }
#capability { flex: 0 0 auto; min-width: 300px; display: flex; align-items: center; justify-content: center;
              padding: 18px 28px; border-radius: 10px; font-size: 36px; font-weight: 700; color: #fff; }
#capability.c-ok { background: var(--ok); }
#capability.c-nok { background: var(--nok); }
.ident { flex: 1 1 auto; background: #fff; border: 1px solid var(--line); border-radius: 10px; padding: 12px 16px; }
.ident h1 { margin: 0 0 4px; font-size: 22px; }
.ident p { margin: 2px 0; color: var(--muted); }
section { background: #fff; border: 1px solid var(--line); border-radius: 10px; padding: 12px 16px; margin-bottom: 16px; }
h2 { margin: 0 0 10px; font-size: 17px; }
table.kv { border-collapse: collapse; width: 100%; }
table.kv th, table.kv td { text-align: left; padding: 4px 8px; border-bottom: 1px solid var(--line); }
table.kv th { width: 260px; color: var(--muted); font-weight: 600; }
.cols { display: grid; grid-template-columns: 1fr 1fr; gap: 16px; align-items: start; }
.tag { font-weight: 700; padding: 2px 8px; border-radius: 4px; color: #fff; }
.tag.c-ok { background: var(--ok); } .tag.c-nok { background: var(--nok); }
svg text { font: 11px "DejaVu Sans", Arial, sans-serif; fill: var(--ink); }
.axis { stroke: var(--ink); stroke-width: 1; }
.grid { stroke: var(--line); stroke-width: 1; }
.run-line { fill: none; stroke: var(--ink); stroke-width: 1.2; }
.run-point { fill: var(--ink); }
.run-reference { stroke: var(--ref); stroke-width: 1.5; }
.run-limit { stroke: var(--nok); stroke-width: 1.2; stroke-dasharray: 5 3; }
.run-mean { stroke: var(--ok); stroke-width: 1.2; stroke-dasharray: 2 2; }
.hist-bar { fill: #6b8fb8; stroke: #fff; stroke-width: 0.5; }
footer { color: var(--muted); font-size: 12px; }
)css";

constexpr int kW = 540, kH = 260, kLeft = 64, kRight = 14, kTop = 14, kBottom = 40;

struct Axis {
  double lo, hi;
  double Map(double v, double px_lo, double px_hi) const { return px_lo + (v - lo) / (hi - lo) * (px_hi - px_lo); }
};

Axis PaddedAxis(double lo, double hi) {
  if (!(hi > lo)) {
    const double half = std::max(std::abs(lo) * 1e-3, 1e-6);
    return {lo - half, hi + half};
  }
  const double pad = 0.08 * (hi - lo);
  return {lo - pad, hi + pad};
}

std::string F(double v) { return FormatFixed(v, 2); }

std::string YTicks(const Axis& y, int x0, int x1) {
  std::string s;
  for (int i = 0; i <= 4; ++i) {
    const double v = y.lo + (y.hi - y.lo) * i / 4.0;
    const double py = y.Map(v, kH - kBottom, kTop);
    s += "<line class=\"grid\" x1=\"" + std::to_string(x0) + "\" x2=\"" + std::to_string(x1) + "\" y1=\"" + F(py) +
         "\" y2=\"" + F(py) + "\"/>";
    s += "<text x=\"" + std::to_string(x0 - 4) + "\" y=\"" + F(py + 4) + "\" text-anchor=\"end\">" +
         FormatSignificant(v, 6) + "</text>";
  }
  return s;
}

std::string HLine(const char* cls, double v, const Axis& y, const std::string& label) {
  const double py = y.Map(v, kH - kBottom, kTop);
  return "<line class=\"" + std::string(cls) + "\" data-value=\"" + FormatSignificant(v, 10) + "\" x1=\"" +
         std::to_string(kLeft) + "\" x2=\"" + std::to_string(kW - kRight) + "\" y1=\"" + F(py) + "\" y2=\"" + F(py) +
         "\"><title>" + HtmlEscape(label) + "</title></line>";
}

std::string RunChart(const v1::MeasurementCapability& c) {
  const int n = c.values_size();
  const double half_band = 0.1 * c.tolerance();
  double lo = c.reference() - half_band, hi = c.reference() + half_band;
  for (double v : c.values()) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  const Axis y = PaddedAxis(lo, hi);
  const Axis x{0.5, n + 0.5};
  std::string s = "<svg class=\"run-chart\" viewBox=\"0 0 " + std::to_string(kW) + " " + std::to_string(kH) +
                  "\" width=\"" + std::to_string(kW) + "\" height=\"" + std::to_string(kH) +
                  "\" role=\"img\" aria-label=\"run chart\">";
  s += YTicks(y, kLeft, kW - kRight);
  s += "<line class=\"axis\" x1=\"" + std::to_string(kLeft) + "\" y1=\"" + std::to_string(kTop) + "\" x2=\"" +
       std::to_string(kLeft) + "\" y2=\"" + std::to_string(kH - kBottom) + "\"/>";
  s += "<line class=\"axis\" x1=\"" + std::to_string(kLeft) + "\" y1=\"" + std::to_string(kH - kBottom) + "\" x2=\"" +
       std::to_string(kW - kRight) + "\" y2=\"" + std::to_string(kH - kBottom) + "\"/>";
  s += HLine("run-limit", c.reference() - half_band, y, "reference - 0.1 T");
  s += HLine("run-limit", c.reference() + half_band, y, "reference + 0.1 T");
  s += HLine("run-reference", c.reference(), y, "reference");
  s += HLine("run-mean", c.mean(), y, "mean");
  std::string points, circles;
  const int label_every = std::max(1, n / 10);
  for (int i = 0; i < n; ++i) {
    const double px = x.Map(i + 1, kLeft, kW - kRight), py = y.Map(c.values(i), kH - kBottom, kTop);
    points += F(px) + "," + F(py) + " ";
    circles += "<circle class=\"run-point\" cx=\"" + F(px) + "\" cy=\"" + F(py) + "\" r=\"2.8\" data-repeat=\"" +
               std::to_string(i + 1) + "\" data-value=\"" + FormatSignificant(c.values(i), 10) + "\"/>";
    if ((i + 1) % label_every == 0 || i == 0) {
      s += "<text x=\"" + F(px) + "\" y=\"" + std::to_string(kH - kBottom + 14) + "\" text-anchor=\"middle\">" +
           std::to_string(i + 1) + "</text>";
    }
  }
  s += "<polyline class=\"run-line\" points=\"" + points + "\"/>" + circles;
  s += "<text x=\"" + std::to_string((kLeft + kW - kRight) / 2) + "\" y=\"" + std::to_string(kH - 6) +
       "\" text-anchor=\"middle\">repeat</text>";
  s += "<text transform=\"translate(12," + std::to_string((kTop + kH - kBottom) / 2) +
       ") rotate(-90)\" text-anchor=\"middle\">" + HtmlEscape(c.parameter()) + " [" + HtmlEscape(c.unit()) +
       "]</text></svg>";
  return s;
}

std::string Histogram(const v1::MeasurementCapability& c) {
  const int n = c.values_size();
  const int bins = std::clamp(int(std::ceil(std::sqrt(double(n)))), 5, 20);
  double lo = c.values(0), hi = c.values(0);
  for (double v : c.values()) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  if (!(hi > lo)) {
    lo -= 0.5 * std::max(std::abs(lo) * 1e-3, 1e-6);
    hi = lo + 2 * (c.values(0) - lo);
  }
  const double w = (hi - lo) / bins;
  std::vector<int> counts(bins, 0);
  for (double v : c.values()) counts[std::min(bins - 1, int((v - lo) / w))]++;
  const int top = *std::max_element(counts.begin(), counts.end());
  const Axis x{lo, hi};
  const Axis y{0.0, double(top)};
  std::string s = "<svg class=\"value-histogram\" viewBox=\"0 0 " + std::to_string(kW) + " " + std::to_string(kH) +
                  "\" width=\"" + std::to_string(kW) + "\" height=\"" + std::to_string(kH) +
                  "\" role=\"img\" aria-label=\"histogram\">";
  s += "<line class=\"axis\" x1=\"" + std::to_string(kLeft) + "\" y1=\"" + std::to_string(kH - kBottom) + "\" x2=\"" +
       std::to_string(kW - kRight) + "\" y2=\"" + std::to_string(kH - kBottom) + "\"/>";
  for (int i = 0; i < bins; ++i) {
    const double x0 = x.Map(lo + i * w, kLeft, kW - kRight), x1 = x.Map(lo + (i + 1) * w, kLeft, kW - kRight);
    const double y0 = y.Map(counts[i], kH - kBottom, kTop);
    s += "<rect class=\"hist-bar\" x=\"" + F(x0) + "\" y=\"" + F(y0) + "\" width=\"" + F(x1 - x0) + "\" height=\"" +
         F(kH - kBottom - y0) + "\" data-bin=\"" + std::to_string(i) + "\" data-lo=\"" +
         FormatSignificant(lo + i * w, 10) + "\" data-count=\"" + std::to_string(counts[i]) + "\"/>";
  }
  for (int i = 0; i <= 4; ++i) {
    const double v = lo + (hi - lo) * i / 4.0;
    s += "<text x=\"" + F(x.Map(v, kLeft, kW - kRight)) + "\" y=\"" + std::to_string(kH - kBottom + 14) +
         "\" text-anchor=\"middle\">" + FormatSignificant(v, 6) + "</text>";
  }
  s += "<text x=\"" + std::to_string(kLeft - 6) + "\" y=\"" + F(kTop + 8.0) + "\" text-anchor=\"end\">" +
       std::to_string(top) + "</text>";
  s += "<text x=\"" + std::to_string((kLeft + kW - kRight) / 2) + "\" y=\"" + std::to_string(kH - 6) +
       "\" text-anchor=\"middle\">" + HtmlEscape(c.parameter()) + " [" + HtmlEscape(c.unit()) + "]</text>";
  s += "<text transform=\"translate(12," + std::to_string((kTop + kH - kBottom) / 2) +
       ") rotate(-90)\" text-anchor=\"middle\">repeats</text></svg>";
  return s;
}

std::string Row(const std::string& key, const std::string& value_html) {
  return "<tr><th>" + HtmlEscape(key) + "</th><td>" + value_html + "</td></tr>";
}

std::string Num(double v, const std::string& unit = "") {
  return HtmlEscape(FormatSignificant(v, 6) + (unit.empty() ? "" : " " + unit));
}

}  // namespace

StatusOr<std::string> RenderStudyReport(const v1::Study& study, const std::string& recipe_description) {
  for (int i = 0; i < study.measurements_size(); ++i) {
    if (study.measurements(i).values_size() == 0) {
      return Status::InvalidArgument("measurements[" + std::to_string(i) + "] has no values");
    }
  }
  const char* outcome = study.capable() ? "CAPABLE" : "NOT CAPABLE";
  const char* cls = study.capable() ? "c-ok" : "c-nok";
  std::string html =
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
      "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; img-src data:; "
      "style-src 'unsafe-inline'\">"
      "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
      "<meta name=\"generator\" content=\"inspectd " INSPECT_STUDY_REPORT_VERSION "\">";
  html += "<title>Type-1 study " + HtmlEscape(study.recipe_id()) + " – " + outcome + "</title><style>" + kStyle +
          "</style></head><body><main>";
  html += "<header class=\"report-head\"><div id=\"capability\" class=\"" + std::string(cls) + "\">" + outcome +
          "</div><div class=\"ident\"><h1>Type-1 gauge study: recipe " + HtmlEscape(study.recipe_id()) + " v" +
          std::to_string(study.recipe_version()) + "</h1>";
  if (!recipe_description.empty()) html += "<p class=\"description\">" + HtmlEscape(recipe_description) + "</p>";
  html += "<p>reference part " + HtmlEscape(study.part_id().empty() ? "-" : study.part_id()) + " · " +
          std::to_string(study.repeats()) + " repeats · study " + HtmlEscape(study.study_id()) + "</p>";
  html += "<p>calibration " + HtmlEscape(study.calibration_id().empty() ? "none (uncalibrated)" : study.calibration_id()) +
          " · re-positioning: " + HtmlEscape(study.repositioning()) + "</p>";
  html += "<p id=\"verification\">instrument verification: " +
          (study.verification_warning().empty() ? std::string("verified")
                                                : "<strong class=\"c-nok\">" + HtmlEscape(study.verification_warning()) +
                                                      "</strong>") +
          "</p>";
  if (study.has_finish_time()) {
    html += "<p>finished " + HtmlEscape(google::protobuf::util::TimeUtil::ToString(study.finish_time())) + "</p>";
  }
  html += "<p>VDA 5 / Bosch booklet 10: Cg = 0.2 T / (6 s), Cgk = (0.1 T − |mean − reference|) / (3 s); capable when "
          "both are ≥ 1.33. Bias: two-sided Student t-test, α = 5 %.</p></div></header>";
  for (const v1::MeasurementCapability& c : study.measurements()) {
    const std::string unit = c.unit();
    const char* mc = c.capable() ? "c-ok" : "c-nok";
    html += "<section class=\"study-measurement\" data-name=\"" + HtmlEscape(c.name()) + "\"><h2>" +
            HtmlEscape(c.name()) + " (" + HtmlEscape(c.parameter()) + ") <span class=\"tag " + mc + "\">" +
            (c.capable() ? "capable" : "not capable") + "</span></h2><div class=\"cols\"><table class=\"kv\">";
    html += Row("n", std::to_string(c.n()));
    html += Row("mean", Num(c.mean(), unit));
    html += Row("standard deviation s", Num(c.stddev(), unit));
    html += Row("reference", Num(c.reference(), unit) + " <small>(" + HtmlEscape(c.reference_source()) + ")</small>");
    html += Row("tolerance T = USL − LSL", Num(c.tolerance(), unit));
    html += Row("Cg", "<span class=\"cg\">" + HtmlEscape(FormatFixed(c.cg(), 3)) + "</span>");
    html += Row("Cgk", "<span class=\"cgk\">" + HtmlEscape(FormatFixed(c.cgk(), 3)) + "</span>");
    html += Row("bias (mean − reference)", Num(c.bias(), unit));
    html += Row("t (t_crit, p)", HtmlEscape(FormatFixed(c.t_statistic(), 3) + " (" + FormatFixed(c.t_critical(), 3) +
                                            ", p = " + FormatSignificant(c.p_value(), 3) + ")") +
                                     (c.bias_significant() ? " <b>significant</b>" : " not significant"));
    html += Row("mean U (k = 2)", Num(c.mean_expanded_uncertainty(), unit));
    html += Row("U / T", HtmlEscape(FormatFixed(c.u_over_t_percent(), 1) + " %"));
    html += Row("outcome", HtmlEscape(c.reason()));
    html += "</table><div>" + RunChart(c) + Histogram(c) + "</div></div></section>";
  }
  html += "<footer>inspectd " INSPECT_STUDY_REPORT_VERSION "</footer></main></body></html>\n";
  return html;
}

}  // namespace inspection
