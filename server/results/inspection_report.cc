// The inspection report: one self-contained HTML page per inspection result, with the
// verdicts (ISO 14253-1, U = 2u), the depth map (thesis 3.1 output) and all-in-focus image as
// data: PNGs, the plots of server/report_plots as inline SVG and the scan metadata.
// A Content-Security-Policy in the page itself forbids scripts and any fetch but data: images,
// so even a mistake in the escaping could not make the page run code or call out.
#include "server/results/inspection_report.h"

#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "core/io/depth_export.h"
#include "server/results/report_plots.h"

// inspectd's version (CMake defines INSPECT_VERSION for the server library).
#ifdef INSPECT_VERSION
#define INSPECT_REPORT_VERSION INSPECT_VERSION
#else
#define INSPECT_REPORT_VERSION "(development build)"
#endif

namespace inspection {
namespace {

// Embedded images stay at most this long on their long side (an archive holds one report per
// part); the depth preview's map part is smaller so that map + colour bar panel stay within it.
constexpr int kMaxImageSidePx = 1024;
constexpr int kMaxPreviewMapSidePx = kMaxImageSidePx - kDepthPreviewPanelWidthPx - 18;

const char* kStyle = R"css(
:root { --ok: #1b7f3b; --nok: #c62828; --nd: #f0a202; --ink: #1d2329; --muted: #5b6670; --line: #d5dae0; }
* { box-sizing: border-box; }
body { margin: 0; font: 14px/1.45 "DejaVu Sans", "Liberation Sans", Arial, sans-serif; color: var(--ink);
       background: #f4f6f8; -webkit-print-color-adjust: exact; print-color-adjust: exact; }
main { max-width: 1180px; margin: 0 auto; padding: 16px 20px 32px; }
header.report-head { display: flex; gap: 24px; align-items: stretch; margin-bottom: 16px; }
#verdict { flex: 0 0 auto; min-width: 280px; display: flex; align-items: center; justify-content: center;
           padding: 18px 28px; border-radius: 10px; font-size: 44px; font-weight: 700; letter-spacing: 1px;
           color: #fff; }
#verdict.v-ok { background: var(--ok); }
#verdict.v-nok { background: var(--nok); }
#verdict.v-nd { background: var(--nd); color: #1d1d1d; }
.ident { flex: 1 1 auto; background: #fff; border: 1px solid var(--line); border-radius: 10px; padding: 12px 16px; }
.ident h1 { margin: 0 0 4px; font-size: 22px; }
.ident p { margin: 2px 0; color: var(--muted); }
section { background: #fff; border: 1px solid var(--line); border-radius: 10px; padding: 12px 16px; margin-bottom: 16px; }
h2 { margin: 0 0 10px; font-size: 17px; }
table { border-collapse: collapse; width: 100%; }
th, td { text-align: left; padding: 5px 8px; border-bottom: 1px solid var(--line); vertical-align: top; }
th { background: #eef1f4; font-weight: 600; white-space: nowrap; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
table.kv th { width: 220px; background: none; font-weight: 600; color: var(--muted); }
.cols { display: grid; grid-template-columns: 1fr 1fr; gap: 16px; }
.v { font-weight: 700; white-space: nowrap; padding: 2px 8px; border-radius: 4px; color: #fff; }
.v.v-ok { background: var(--ok); } .v.v-nok { background: var(--nok); } .v.v-nd { background: var(--nd); color: #1d1d1d; }
.v.v-none { background: #8a949e; }
figure { margin: 0 0 8px; }
figure img { display: block; max-width: 100%; height: auto; border: 1px solid var(--line); background: #000; }
figcaption { color: var(--muted); font-size: 13px; margin-top: 4px; }
.images { display: grid; grid-template-columns: 1fr; gap: 16px; }
svg { display: block; width: 100%; max-width: 900px; height: auto; font-size: 12px; fill: var(--ink); }
svg .grid { stroke: #e6e9ed; stroke-width: 1; }
svg .tick { stroke: var(--ink); stroke-width: 1; }
svg .frame { fill: none; stroke: var(--ink); stroke-width: 1; }
svg .axis-title { font-size: 13px; font-weight: 600; }
svg .hist-bar { fill: #3b6ea5; stroke: #2a5585; stroke-width: 0.3; }
svg .profile-line { fill: none; stroke: #1f4e8c; stroke-width: 1.8; stroke-linejoin: round; }
svg .profile-point { fill: #1f4e8c; }
svg .profile-band, svg .legend-band { fill: #8fb3e0; fill-opacity: 0.45; stroke: none; }
svg .legend-line { stroke: #1f4e8c; stroke-width: 1.8; }
svg .no-data { font-size: 16px; fill: var(--muted); }
footer { color: var(--muted); font-size: 12px; text-align: center; }
@media (max-width: 800px) { header.report-head, .cols { display: block; } #verdict { margin-bottom: 12px; } }
)css";

struct VerdictStyle {
  const char* text;
  const char* css;
};

VerdictStyle StyleOf(v1::Verdict verdict) {
  switch (verdict) {
    case v1::VERDICT_OK:
      return {"OK", "v-ok"};
    case v1::VERDICT_NOT_OK:
      return {"NOT OK", "v-nok"};
    case v1::VERDICT_NOT_DECIDABLE:
      return {"NOT DECIDABLE", "v-nd"};
    default:
      return {"—", "v-none"};
  }
}

// The overall verdict as InspectionResult defines it; used when the result leaves it unset.
// Without any decided measurement nothing was shown to be OK: NOT DECIDABLE.
v1::Verdict OverallVerdict(const v1::InspectionResult& r) {
  if (r.verdict() != v1::VERDICT_UNSPECIFIED) return r.verdict();
  bool any_nd = r.measurements().empty(), any_nok = false;
  for (const auto& m : r.measurements()) {
    any_nok |= m.verdict() == v1::VERDICT_NOT_OK;
    any_nd |= m.verdict() != v1::VERDICT_NOT_OK && m.verdict() != v1::VERDICT_OK;
  }
  return any_nok ? v1::VERDICT_NOT_OK : any_nd ? v1::VERDICT_NOT_DECIDABLE : v1::VERDICT_OK;
}

std::string DisplayUnit(const std::string& unit) {
  if (unit == "um") return "µm";
  if (unit == "um3") return "µm³";
  if (unit == "mm3") return "mm³";
  if (unit == "deg") return "°";
  return HtmlEscape(unit);
}

// Strips an enum's type prefix: RECONSTRUCTION_METHOD_ISFF_FAST -> ISFF_FAST.
std::string EnumShortName(const std::string& full, const std::string& prefix) {
  return full.rfind(prefix, 0) == 0 ? full.substr(prefix.size()) : full;
}

std::string Base64(const std::vector<uchar>& bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = uint32_t(bytes[i]) << 16 | uint32_t(bytes[i + 1]) << 8 | bytes[i + 2];
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (i < bytes.size()) {
    const bool two = i + 1 < bytes.size();
    const uint32_t v = uint32_t(bytes[i]) << 16 | (two ? uint32_t(bytes[i + 1]) << 8 : 0u);
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += two ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

StatusOr<std::string> PngDataUri(const cv::Mat& image) {
  std::vector<uchar> png;
  try {
    if (!cv::imencode(".png", image, png)) return Status::Internal("PNG encoding failed");
  } catch (const cv::Exception& e) {
    return Status::Internal(std::string("PNG encoding failed: ") + e.what());
  }
  return "data:image/png;base64," + Base64(png);
}

cv::Size FitSize(cv::Size size, int max_side) {
  const double f = std::min(1.0, double(max_side) / std::max(size.width, size.height));
  return {std::max(1, int(std::lround(size.width * f))), std::max(1, int(std::lround(size.height * f)))};
}

// Box mean of the finite heights under each output pixel (NaN where the box has none), so a
// hole in the map does not spread into its neighbours the way cv::resize would spread a NaN.
cv::Mat DownscaleDepth(const cv::Mat& depth_um, cv::Size out) {
  if (out == depth_um.size()) return depth_um;
  cv::Mat result(out, CV_32FC1);
  const int rows = depth_um.rows, cols = depth_um.cols;
  for (int oy = 0; oy < out.height; ++oy) {
    const int y0 = int(int64_t(oy) * rows / out.height),
              y1 = std::max(y0 + 1, int(int64_t(oy + 1) * rows / out.height));
    float* dst = result.ptr<float>(oy);
    for (int ox = 0; ox < out.width; ++ox) {
      const int x0 = int(int64_t(ox) * cols / out.width),
                x1 = std::max(x0 + 1, int(int64_t(ox + 1) * cols / out.width));
      double sum = 0.0;
      int n = 0;
      for (int y = y0; y < y1; ++y) {
        const float* src = depth_um.ptr<float>(y);
        for (int x = x0; x < x1; ++x) {
          if (std::isfinite(src[x])) {
            sum += src[x];
            ++n;
          }
        }
      }
      dst[ox] = n ? float(sum / n) : std::numeric_limits<float>::quiet_NaN();
    }
  }
  return result;
}

// 8-bit image for display: 16-bit scaled linearly so that its largest value becomes 255 (a
// 10- or 12-bit camera in a 16-bit container would otherwise show nearly black).
cv::Mat AllInFocusForDisplay(const cv::Mat& image, std::string* scaling_note) {
  cv::Mat img8;
  if (image.depth() == CV_16U) {
    double max_value = 0.0;
    cv::minMaxLoc(image.reshape(1), nullptr, &max_value);
    image.convertTo(img8, CV_8U, max_value > 0 ? 255.0 / max_value : 1.0);
    *scaling_note = "16-bit, shown scaled linearly 0.." + FormatFixed(max_value, 0) + " → 0..255";
  } else {
    img8 = image;
  }
  const cv::Size out = FitSize(img8.size(), kMaxImageSidePx);
  if (out == img8.size()) return img8;
  cv::Mat small;
  cv::resize(img8, small, out, 0, 0, cv::INTER_AREA);
  return small;
}

std::string Row(const std::string& key, const std::string& value_html) {
  return "<tr><th>" + key + "</th><td>" + value_html + "</td></tr>";
}

// The frame alignment that ran: none (with the default's fallback reason), or how the transforms
// were found, still or warped, and each frame's transform in a nested table.
std::string AlignmentRow(const v1::DepthSummary& d) {
  if (d.alignment() == v1::FRAME_ALIGNMENT_UNSPECIFIED) return "";
  const v1::AlignmentDetail& a = d.alignment_detail();
  std::string text = HtmlEscape(EnumShortName(v1::FrameAlignment_Name(d.alignment()), "FRAME_ALIGNMENT_"));
  if (d.alignment() == v1::FRAME_ALIGNMENT_NONE) {
    if (!a.fallback_reason().empty()) text += " (the default fell back to none: " + HtmlEscape(a.fallback_reason()) + ")";
    return Row("Frame alignment", text);
  }
  if (!a.method().empty()) text += " (" + HtmlEscape(a.method()) + ")";
  text += a.still() ? ": still, frames used as captured; measured max scale change "
                    : ": max scale change ";
  text += FormatFixed(d.alignment_max_scale_change_percent(), 3) + " %, max shift " +
          FormatFixed(d.alignment_max_shift_px(), 2) + " px, seen by all " + FormatFixed(d.alignment_seen_percent(), 1) +
          " %";
  if (!a.decision().empty()) text += "; " + HtmlEscape(a.decision());
  if (a.frames_size() > 0) {
    text += "<table class=\"alignment-frames\"><tr><th>frame</th><th>scale</th><th>rotation (°)</th>"
            "<th>shift x (px)</th><th>shift y (px)</th></tr>";
    for (const v1::FrameTransform& f : a.frames()) {
      text += "<tr><td>" + std::to_string(f.frame()) + (f.frame() == a.reference_frame() ? " (reference)" : "") +
              "</td><td class=\"num\">" + FormatFixed(f.scale(), 5) + "</td><td class=\"num\">" +
              FormatFixed(f.rotation_deg(), 4) + "</td><td class=\"num\">" + FormatFixed(f.shift_x_px(), 2) +
              "</td><td class=\"num\">" + FormatFixed(f.shift_y_px(), 2) + "</td></tr>";
    }
    text += "</table>";
  }
  return Row("Frame alignment", text);
}

std::string OrDash(const std::string& text) { return text.empty() ? "—" : HtmlEscape(text); }

std::string Seconds(double s) { return FormatFixed(s, s < 10 ? 2 : 1) + " s"; }

// Value and U with the same decimals: two significant digits of U (GUM 7.2.6); without U, six
// significant digits.
void FormatValueAndU(const v1::MeasurementResult& m, std::string* value, std::string* u) {
  const double U = m.expanded_uncertainty();
  if (std::isfinite(U) && U > 0.0) {
    const int decimals = std::clamp(1 - int(std::floor(std::log10(U))), 0, 9);
    *value = FormatFixed(m.value(), decimals);
    *u = FormatFixed(U, decimals);
  } else {
    *value = FormatSignificant(m.value(), 6);
    *u = U == 0.0 ? "0" : "n/a";
  }
}

std::string MeasurementTable(const v1::InspectionResult& r) {
  if (r.measurements().empty()) return "<p>The recipe has no measurements.</p>";
  std::string html =
      "<table id=\"measurement-table\"><thead><tr><th>Name</th><th>Parameter</th><th>Value</th><th>Unit</th>"
      "<th>U (k = 2)</th><th>Coverage %</th><th>Nominal</th><th>LSL</th><th>USL</th><th>Verdict</th>"
      "<th>Reason</th></tr></thead><tbody>";
  for (const auto& m : r.measurements()) {
    const v1::RecipeTolerance& t = m.tolerance();
    std::string value = "—", u = "—";
    if (m.measured()) FormatValueAndU(m, &value, &u);
    std::string coverage = FormatFixed(m.coverage_percent(), 1);
    if (t.min_coverage_percent() > 0) coverage += " (min " + FormatSignificant(t.min_coverage_percent(), 4) + ")";
    const VerdictStyle vs = StyleOf(m.verdict());
    html += "<tr data-measurement=\"" + HtmlEscape(m.name()) + "\"><td>" + HtmlEscape(m.name()) + "</td><td>" +
            HtmlEscape(m.parameter()) + "</td><td class=\"num\">" + value + "</td><td>" + DisplayUnit(m.unit()) +
            "</td><td class=\"num\">" + u + "</td><td class=\"num\">" + coverage + "</td><td class=\"num\">" +
            FormatSignificant(t.nominal(), 6) + "</td><td class=\"num\">" +
            (t.has_lower() ? FormatSignificant(t.nominal() + t.lower(), 6) : "—") + "</td><td class=\"num\">" +
            (t.has_upper() ? FormatSignificant(t.nominal() + t.upper(), 6) : "—") + "</td><td><span class=\"v " +
            vs.css + "\">" + vs.text + "</span></td><td>" + HtmlEscape(m.reason()) + "</td></tr>";
  }
  return html + "</tbody></table>";
}

std::string ScanMetadataTable(const v1::DepthSummary& d, const cv::Mat& depth_um) {
  const int width = d.width() > 0 ? d.width() : depth_um.cols, height = d.height() > 0 ? d.height() : depth_um.rows;
  std::string size = std::to_string(width) + " × " + std::to_string(height) + " px";
  std::string html = "<table class=\"kv\" id=\"scan-metadata\">" + Row("Depth map size", size);
  if (d.pixel_size_um() > 0) {
    html += Row("Pixel size", FormatSignificant(d.pixel_size_um(), 6) + " µm");
    html += Row("Field of view", FormatFixed(width * d.pixel_size_um() / 1000.0, 3) + " × " +
                                     FormatFixed(height * d.pixel_size_um() / 1000.0, 3) + " mm");
  } else {
    html += Row("Pixel size", "not calibrated");
  }
  html +=
      Row("Height range (valid pixels)", FormatFixed(d.z_min_um(), 3) + " … " + FormatFixed(d.z_max_um(), 3) + " µm");
  html += Row("Frames", std::to_string(d.frame_count()));
  html += Row("Valid pixels", FormatFixed(d.valid_percent(), 2) + " %");
  std::string illumination = OrDash(d.illumination());
  if (!d.illumination_decision().empty()) illumination += " (" + HtmlEscape(d.illumination_decision()) + ")";
  html += Row("Illumination", illumination);
  const std::string method = EnumShortName(v1::ReconstructionMethod_Name(d.method()), "RECONSTRUCTION_METHOD_");
  html += Row("Reconstruction", HtmlEscape(method == "UNSPECIFIED" ? "SFF" : method) + ", engine " +
                                    Seconds(d.engine_seconds()) + " after the last frame");
  if (d.method() == v1::RECONSTRUCTION_METHOD_ISFF_FAST && d.isff_fast_threshold() > 0)
    html += Row("ISFF fast threshold", FormatSignificant(d.isff_fast_threshold(), 4));
  if (d.frame_noise_sigma() > 0)
    html += Row("Frame noise σ", FormatSignificant(d.frame_noise_sigma(), 4) + " grey levels");
  if (d.frames_searched_fraction() > 0)
    html += Row("Frames searched per pixel", FormatFixed(100.0 * d.frames_searched_fraction(), 1) + " %");
  html += AlignmentRow(d);
  if (d.has_z_range_search()) {
    const v1::ZRangeSearchResult& z = d.z_range_search();
    html += Row("Automatic z range",
                "searched " + FormatFixed(z.window_start_um(), 1) + " … " + FormatFixed(z.window_end_um(), 1) +
                    " µm (" + std::to_string(z.coarse_frame_count()) + " coarse frames at " +
                    FormatFixed(z.coarse_step_um(), 1) + " µm" +
                    (z.stopped_early() ? ", stopped early: " + FormatFixed(z.settled_percent(), 1) + " % past focus"
                                       : std::string()) +
                    (z.refine_frame_count() > 0
                         ? ", " + std::to_string(z.refine_frame_count()) + " refining the ends"
                         : std::string()) +
                    "), focus " + FormatFixed(z.focus_low_um(), 1) + " … " + FormatFixed(z.focus_high_um(), 1) +
                    " µm, scanned " + FormatFixed(z.z_start_um(), 1) + " … " + FormatFixed(z.z_end_um(), 1) + " µm");
  }
  if (d.has_ground_truth()) {
    html += Row("Against ground truth (simulated rig)", "RMSE " + FormatFixed(d.rmse_um(), 3) + " µm, mean |error| " +
                                                            FormatFixed(d.mean_abs_error_um(), 3) + " µm");
  }
  return html + "</table>";
}

std::string FinishTime(const v1::InspectionResult& r) {
  if (!r.has_finish_time()) return "—";
  return HtmlEscape(google::protobuf::util::TimeUtil::ToString(r.finish_time()));
}

std::string ProfilesSection(const v1::InspectionResult& r) {
  std::string html = "<section id=\"profiles\"><h2>Line profiles</h2>";
  if (r.profiles().empty()) return html + "<p>The recipe has no line profiles.</p></section>";
  for (const auto& p : r.profiles()) {
    html += "<figure class=\"profile\">" + RenderProfileSvg(p) + "<figcaption>Profile <b>" + HtmlEscape(p.name()) +
            "</b>: " + std::to_string(p.height_um_size()) + " samples, averaged over a band " +
            FormatSignificant(p.width_um(), 4) + " µm wide, " + FormatFixed(p.coverage_percent(), 1) +
            " % with a height; shaded: height ± 2u.</figcaption></figure>";
  }
  return html + "</section>";
}

Status CheckInput(const InspectionReportInput& in) {
  if (in.depth_um.empty()) return Status::InvalidArgument("depth_um is empty");
  if (in.depth_um.type() != CV_32FC1) return Status::InvalidArgument("depth_um must be CV_32FC1 (float um)");
  const cv::Mat& a = in.all_in_focus;
  if (!a.empty() && ((a.depth() != CV_8U && a.depth() != CV_16U) || (a.channels() != 1 && a.channels() != 3)))
    return Status::InvalidArgument("all_in_focus must be CV_8U or CV_16U with 1 or 3 channels");
  return Status::Ok();
}

}  // namespace

StatusOr<std::string> RenderInspectionReport(const InspectionReportInput& input) {
  INSPECT_RETURN_IF_ERROR(CheckInput(input));
  const v1::InspectionResult& r = input.inspection;
  const VerdictStyle verdict = StyleOf(OverallVerdict(r));

  // Images first: the only steps that can fail after the input check.
  const cv::Size map_out = FitSize(input.depth_um.size(), kMaxPreviewMapSidePx);
  StatusOr<cv::Mat> preview = RenderDepthPreview(DownscaleDepth(input.depth_um, map_out));
  if (!preview.ok()) return preview.status();
  StatusOr<std::string> preview_uri = PngDataUri(*preview);
  if (!preview_uri.ok()) return preview_uri.status();
  std::string aif_uri, aif_note;
  cv::Size aif_shown;
  if (!input.all_in_focus.empty()) {
    const cv::Mat shown = AllInFocusForDisplay(input.all_in_focus, &aif_note);
    aif_shown = shown.size();
    StatusOr<std::string> uri = PngDataUri(shown);
    if (!uri.ok()) return uri.status();
    aif_uri = std::move(*uri);
  }

  const std::string part = OrDash(r.part_id());
  std::string html;
  html.reserve(preview_uri->size() + aif_uri.size() + 64 * 1024);
  html +=
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
      "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; img-src data:; "
      "style-src 'unsafe-inline'\">"
      "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
      "<meta name=\"generator\" content=\"inspectd " INSPECT_REPORT_VERSION "\">";
  html +=
      "<title>Inspection " + part + " – " + verdict.text + "</title><style>" + kStyle + "</style></head><body><main>";

  // Head: the verdict and what was inspected.
  html += std::string("<header class=\"report-head\"><div id=\"verdict\" class=\"") + verdict.css + "\">" +
          verdict.text + "</div><div class=\"ident\"><h1>Part <span id=\"part-id\">" + part + "</span></h1>";
  html +=
      "<p>Recipe <b id=\"recipe-id\">" + OrDash(r.recipe_id()) + "</b> version " + std::to_string(r.recipe_version());
  if (!input.recipe_description.empty())
    html += " — <span id=\"recipe-description\">" + HtmlEscape(input.recipe_description) + "</span>";
  html += "</p><p>Station " + OrDash(r.station()) + " · finished " + FinishTime(r) + "</p></div></header>";

  html += "<section id=\"summary\"><div class=\"cols\"><table class=\"kv\">" + Row("Part id", part) +
          Row("Recipe", OrDash(r.recipe_id()) + " v" + std::to_string(r.recipe_version())) +
          Row("Station", OrDash(r.station())) + Row("Job id", OrDash(r.job_id())) +
          Row("Calibration", r.calibration_id().empty() ? "uncalibrated" : HtmlEscape(r.calibration_id())) +
          // The rig's instrument verification as the scan ran (docs/verification.md).
          Row("Instrument verification",
              "<span id=\"verification\">" +
                  (r.verification_warning().empty() ? std::string("verified") : HtmlEscape(r.verification_warning())) +
                  "</span>") +
          Row("Finished", FinishTime(r)) +
          // The server renders the report before the result is stored and numbered, and before
          // its own time is known: rows without a value yet are left out rather than shown as 0.
          (r.sequence() > 0 ? Row("Result sequence", std::to_string(r.sequence())) : std::string()) +
          "</table><table class=\"kv\" id=\"timings\">" + Row("Queued", Seconds(r.timings().queue_seconds())) +
          Row("Scan (acquisition and reconstruction)", Seconds(r.timings().scan_seconds())) +
          Row("of which engine after the last frame", Seconds(r.timings().engine_seconds())) +
          (r.timings().measure_seconds() > 0 ? Row("Measurements and report", Seconds(r.timings().measure_seconds()))
                                             : std::string()) +
          "</table></div></section>";

  html += "<section id=\"measurements\"><h2>Measurements</h2>" + MeasurementTable(r) +
          "<p class=\"note\">Verdicts follow ISO 14253-1 with U = 2u: OK when value ± U lies within [LSL, USL], "
          "NOT OK when it lies wholly outside, NOT DECIDABLE otherwise (U straddles a limit, 2U is not below "
          "the tolerance band, or the region's coverage is below the recipe's minimum). "
          "LSL = nominal + lower, USL = nominal + upper.</p></section>";

  html += "<section id=\"images\"><h2>Depth map and all-in-focus image</h2><div class=\"images\">";
  html +=
      "<figure id=\"depth-preview\"><img alt=\"depth map preview\" src=\"" + *preview_uri + "\" width=\"" +
      std::to_string(preview->cols) + "\" height=\"" + std::to_string(preview->rows) + "\"><figcaption>Depth map (" +
      std::to_string(input.depth_um.cols) + " × " + std::to_string(input.depth_um.rows) + " px" +
      (map_out != input.depth_um.size()
           ? ", shown at " + std::to_string(map_out.width) + " × " + std::to_string(map_out.height) + " px as box means"
           : std::string()) +
      "); colour scale z [µm] on the right; black: no depth.</figcaption></figure>";
  if (!aif_uri.empty()) {
    html += "<figure id=\"all-in-focus\"><img alt=\"all-in-focus image\" src=\"" + aif_uri + "\" width=\"" +
            std::to_string(aif_shown.width) + "\" height=\"" + std::to_string(aif_shown.height) +
            "\"><figcaption>All-in-focus image (" + std::to_string(input.all_in_focus.cols) + " × " +
            std::to_string(input.all_in_focus.rows) + " px" +
            (aif_shown != input.all_in_focus.size()
                 ? ", shown at " + std::to_string(aif_shown.width) + " × " + std::to_string(aif_shown.height) + " px"
                 : std::string()) +
            (aif_note.empty() ? std::string() : "; " + aif_note) + ").</figcaption></figure>";
  }
  html += "</div></section>";

  const HeightHistogram histogram = ComputeHeightHistogram(input.depth_um);
  html += "<section id=\"histogram\"><h2>Height histogram</h2>" + RenderHistogramSvg(histogram) + "<p>" +
          std::to_string(histogram.valid_count) + " of " + std::to_string(histogram.pixel_count) +
          " pixels with a height, in " + std::to_string(histogram.counts.size()) + " bins of " +
          FormatSignificant(histogram.bin_width_um, 4) + " µm.</p></section>";

  html += ProfilesSection(r);
  html += "<section id=\"scan\"><h2>Scan</h2>" + ScanMetadataTable(input.depth, input.depth_um) + "</section>";
  html += "<footer>Inspection report written by inspectd " INSPECT_REPORT_VERSION
          ". Self-contained: no script, no remote resource.</footer></main></body></html>\n";
  return html;
}

}  // namespace inspection
