// The inspection report's SVG plots: the height histogram of the depth map (thesis
// 3.1 output) and the line profiles with their +-2u band (k = 2, as the verdicts use it).
// Numbers are written with std::to_chars, so a process locale never turns "1.5" into "1,5".
#include "server/results/report_plots.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <utility>

#include "core/io/depth_export.h"

namespace inspection {
namespace {

// The plots' frame in SVG user units; the page scales the whole SVG (viewBox) to its width.
constexpr double kWidth = 720.0, kHeight = 300.0;
constexpr double kLeft = 72.0, kRight = 18.0, kTop = 30.0, kBottom = 52.0;  // the legend sits in the top margin
constexpr double kPlotX0 = kLeft, kPlotX1 = kWidth - kRight;
constexpr double kPlotY0 = kTop, kPlotY1 = kHeight - kBottom;  // y0 top, y1 bottom

std::string ToChars(double value, std::chars_format format, int precision) {
  if (!std::isfinite(value)) return "n/a";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), value, format, precision);
  if (r.ec != std::errc()) return "n/a";
  std::string s(buf, r.ptr);
  // "-0.00" for a tiny negative reads as a sign error in a table; print it unsigned.
  if (s[0] == '-' && s.find_first_not_of("-0.") == std::string::npos) s.erase(0, 1);
  return s;
}

// A coordinate in SVG user units.
std::string Px(double v) { return FormatFixed(v, 1); }

// Linear map of a data interval onto a pixel interval.
struct Scale {
  double lo, hi, px_lo, px_hi;
  double operator()(double v) const { return px_lo + (v - lo) / (hi - lo) * (px_hi - px_lo); }
};

// 1, 2 or 5 times a power of ten, so that `range` holds about `target` steps.
double NiceStep(double range, int target) {
  if (!(range > 0.0)) return 1.0;
  const double raw = range / std::max(target, 1);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double f : {1.0, 2.0, 5.0}) {
    if (raw <= f * mag) return f * mag;
  }
  return 10.0 * mag;
}

int DecimalsForStep(double step) { return std::clamp(int(std::ceil(-std::log10(step) - 1e-9)), 0, 6); }

std::vector<double> Ticks(double lo, double hi, double step) {
  std::vector<double> ticks;
  const double first = std::ceil(lo / step - 1e-9) * step;
  for (int i = 0;; ++i) {
    const double t = first + i * step;
    if (t > hi + 1e-9 * step || i > 100) break;
    ticks.push_back(std::abs(t) < 1e-9 * step ? 0.0 : t);
  }
  return ticks;
}

// Frame, ticks with labels, grid lines and axis titles for x and y.
void AppendAxes(std::string& svg, const Scale& x, double x_step, const Scale& y, double y_step,
                const std::string& x_title, const std::string& y_title) {
  const int xd = DecimalsForStep(x_step), yd = DecimalsForStep(y_step);
  svg += "<g class=\"axes\">";
  for (double t : Ticks(y.lo, y.hi, y_step)) {
    const std::string py = Px(y(t));
    svg += "<line class=\"grid\" x1=\"" + Px(kPlotX0) + "\" x2=\"" + Px(kPlotX1) + "\" y1=\"" + py + "\" y2=\"" + py +
           "\"/>";
    svg += "<line class=\"tick\" x1=\"" + Px(kPlotX0 - 5) + "\" x2=\"" + Px(kPlotX0) + "\" y1=\"" + py + "\" y2=\"" +
           py + "\"/>";
    svg += "<text class=\"y-tick\" x=\"" + Px(kPlotX0 - 8) + "\" y=\"" + Px(y(t) + 4) + "\" text-anchor=\"end\">" +
           FormatFixed(t, yd) + "</text>";
  }
  for (double t : Ticks(x.lo, x.hi, x_step)) {
    const std::string px = Px(x(t));
    svg += "<line class=\"tick\" x1=\"" + px + "\" x2=\"" + px + "\" y1=\"" + Px(kPlotY1) + "\" y2=\"" +
           Px(kPlotY1 + 5) + "\"/>";
    svg += "<text class=\"x-tick\" x=\"" + px + "\" y=\"" + Px(kPlotY1 + 19) + "\" text-anchor=\"middle\">" +
           FormatFixed(t, xd) + "</text>";
  }
  svg += "<rect class=\"frame\" x=\"" + Px(kPlotX0) + "\" y=\"" + Px(kPlotY0) + "\" width=\"" + Px(kPlotX1 - kPlotX0) +
         "\" height=\"" + Px(kPlotY1 - kPlotY0) + "\"/>";
  svg += "<text class=\"axis-title\" x=\"" + Px((kPlotX0 + kPlotX1) / 2) + "\" y=\"" + Px(kHeight - 10) +
         "\" text-anchor=\"middle\">" + HtmlEscape(x_title) + "</text>";
  const std::string cy = Px((kPlotY0 + kPlotY1) / 2);
  svg += "<text class=\"axis-title\" x=\"16\" y=\"" + cy + "\" text-anchor=\"middle\" transform=\"rotate(-90 16 " + cy +
         ")\">" + HtmlEscape(y_title) + "</text>";
  svg += "</g>";
}

std::string SvgOpen(const char* css_class, const std::string& label) {
  return std::string("<svg class=\"") + css_class + "\" viewBox=\"0 0 " + Px(kWidth) + " " + Px(kHeight) +
         "\" role=\"img\" aria-label=\"" + HtmlEscape(label) + "\">";
}

std::string NoDataSvg(const char* css_class, const std::string& label, const std::string& message) {
  return SvgOpen(css_class, label) + "<text class=\"no-data\" x=\"" + Px(kWidth / 2) + "\" y=\"" + Px(kHeight / 2) +
         "\" text-anchor=\"middle\">" + HtmlEscape(message) + "</text></svg>";
}

// Half-open runs [begin, end) of consecutive samples with a finite position and height.
std::vector<std::pair<int, int>> FiniteRuns(const v1::ProfileResult& p, int n) {
  std::vector<std::pair<int, int>> runs;
  int begin = -1;
  for (int i = 0; i <= n; ++i) {
    const bool ok = i < n && std::isfinite(p.position_um(i)) && std::isfinite(p.height_um(i));
    if (ok && begin < 0) begin = i;
    if (!ok && begin >= 0) {
      runs.emplace_back(begin, i);
      begin = -1;
    }
  }
  return runs;
}

}  // namespace

// One escaping for the x3p comment and the report (core/io/depth_export.h).
std::string HtmlEscape(std::string_view text) { return XmlEscape(text); }

std::string FormatFixed(double value, int decimals) {
  return ToChars(value, std::chars_format::fixed, std::clamp(decimals, 0, 12));
}

std::string FormatSignificant(double value, int significant) {
  return ToChars(value, std::chars_format::general, std::clamp(significant, 1, 17));
}

HeightHistogram ComputeHeightHistogram(const cv::Mat& depth_um, int bins) {
  HeightHistogram h;
  h.pixel_count = int64_t(depth_um.total());
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      if (!std::isfinite(d[x])) continue;
      lo = std::min(lo, double(d[x]));
      hi = std::max(hi, double(d[x]));
      ++h.valid_count;
    }
  }
  if (h.valid_count == 0) return h;
  if (hi > lo) {
    h.lo_um = lo;
    h.bin_width_um = (hi - lo) / std::max(bins, 1);
    h.counts.assign(size_t(std::max(bins, 1)), 0);
  } else {
    h.lo_um = lo - 0.5;
    h.bin_width_um = 1.0;
    h.counts.assign(1, 0);
  }
  const int last = int(h.counts.size()) - 1;
  for (int y = 0; y < depth_um.rows; ++y) {
    const float* d = depth_um.ptr<float>(y);
    for (int x = 0; x < depth_um.cols; ++x) {
      if (!std::isfinite(d[x])) continue;
      const int bin = std::clamp(int(std::floor((double(d[x]) - h.lo_um) / h.bin_width_um)), 0, last);
      ++h.counts[size_t(bin)];
    }
  }
  return h;
}

std::string RenderHistogramSvg(const HeightHistogram& histogram) {
  const char* css = "height-histogram";
  if (histogram.counts.empty()) return NoDataSvg(css, "height histogram", "no valid height in the depth map");
  const int n = int(histogram.counts.size());
  const double lo = histogram.lo_um, hi = histogram.lo_um + n * histogram.bin_width_um;
  const int64_t max_count = *std::max_element(histogram.counts.begin(), histogram.counts.end());
  const double x_step = NiceStep(hi - lo, 8);
  const double y_step = std::max(1.0, NiceStep(double(max_count), 5));
  const double y_top = std::max(1.0, std::ceil(double(max_count) / y_step) * y_step);
  const Scale x{lo, hi, kPlotX0, kPlotX1};
  const Scale y{0.0, y_top, kPlotY1, kPlotY0};
  std::string svg = SvgOpen(css, "height histogram");
  AppendAxes(svg, x, x_step, y, y_step, "height z [µm]", "pixels");
  svg += "<g class=\"bars\">";
  const int lo_decimals = DecimalsForStep(histogram.bin_width_um) + 1;
  for (int i = 0; i < n; ++i) {
    const double b_lo = lo + i * histogram.bin_width_um, b_hi = b_lo + histogram.bin_width_um;
    const int64_t c = histogram.counts[size_t(i)];
    const double x0 = x(b_lo), x1 = x(b_hi), y0 = y(double(c));
    svg += "<rect class=\"hist-bar\" data-bin=\"" + std::to_string(i) + "\" data-lo-um=\"" +
           FormatSignificant(b_lo, 9) + "\" data-hi-um=\"" + FormatSignificant(b_hi, 9) + "\" data-count=\"" +
           std::to_string(c) + "\" x=\"" + FormatFixed(x0, 2) + "\" y=\"" + FormatFixed(y0, 2) + "\" width=\"" +
           FormatFixed(x1 - x0, 2) + "\" height=\"" + FormatFixed(kPlotY1 - y0, 2) + "\"><title>" +
           FormatFixed(b_lo, lo_decimals) + " to " + FormatFixed(b_hi, lo_decimals) + " µm: " + std::to_string(c) +
           " px</title></rect>";
  }
  svg += "</g></svg>";
  return svg;
}

std::string RenderProfileSvg(const v1::ProfileResult& profile) {
  const char* css = "profile-plot";
  const std::string label = "profile " + profile.name();
  const int n = std::min(profile.position_um_size(), profile.height_um_size());
  const bool has_band = profile.standard_uncertainty_um_size() == profile.height_um_size();
  const auto runs = FiniteRuns(profile, n);
  if (runs.empty()) return NoDataSvg(css, label, "no height in the band");

  // Uncertainty of sample i when it can be drawn; 0 otherwise (the band then pinches to the line).
  auto u_of = [&](int i) {
    const double u = has_band ? profile.standard_uncertainty_um(i) : 0.0;
    return std::isfinite(u) && u > 0.0 ? u : 0.0;
  };
  double x_lo = profile.position_um(runs.front().first), x_hi = x_lo;
  double y_lo = std::numeric_limits<double>::infinity(), y_hi = -y_lo;
  for (const auto& [b, e] : runs) {
    for (int i = b; i < e; ++i) {
      x_lo = std::min(x_lo, profile.position_um(i));
      x_hi = std::max(x_hi, profile.position_um(i));
      y_lo = std::min(y_lo, profile.height_um(i) - 2.0 * u_of(i));
      y_hi = std::max(y_hi, profile.height_um(i) + 2.0 * u_of(i));
    }
  }
  // The whole line's extent when the positions say so (a gap at either end still shows as a gap).
  for (int i = 0; i < n; ++i) {
    if (std::isfinite(profile.position_um(i))) {
      x_lo = std::min(x_lo, profile.position_um(i));
      x_hi = std::max(x_hi, profile.position_um(i));
    }
  }
  if (!(x_hi > x_lo)) {
    x_lo -= 0.5;
    x_hi += 0.5;
  }
  if (!(y_hi > y_lo)) {
    y_lo -= 0.5;
    y_hi += 0.5;
  }
  const double y_pad = 0.06 * (y_hi - y_lo);
  y_lo -= y_pad;
  y_hi += y_pad;
  const double x_step = NiceStep(x_hi - x_lo, 8), y_step = NiceStep(y_hi - y_lo, 5);
  const Scale x{x_lo, x_hi, kPlotX0, kPlotX1};
  const Scale y{y_lo, y_hi, kPlotY1, kPlotY0};

  std::string svg = SvgOpen(css, label);
  svg.insert(svg.size() - 1, " data-profile=\"" + HtmlEscape(profile.name()) + "\"");
  AppendAxes(svg, x, x_step, y, y_step, "position along the line [µm]", "height z [µm]");
  if (has_band) {
    svg += "<g class=\"bands\">";
    for (const auto& [b, e] : runs) {
      std::string points;
      for (int i = b; i < e; ++i)
        points += Px(x(profile.position_um(i))) + "," + Px(y(profile.height_um(i) + 2 * u_of(i))) + " ";
      for (int i = e - 1; i >= b; --i)
        points += Px(x(profile.position_um(i))) + "," + Px(y(profile.height_um(i) - 2 * u_of(i))) + " ";
      points.pop_back();
      svg += "<polygon class=\"profile-band\" points=\"" + points + "\"/>";
    }
    svg += "</g>";
  }
  svg += "<g class=\"lines\">";
  for (const auto& [b, e] : runs) {
    if (e - b == 1) {
      svg += "<circle class=\"profile-point\" cx=\"" + Px(x(profile.position_um(b))) + "\" cy=\"" +
             Px(y(profile.height_um(b))) + "\" r=\"2\"/>";
      continue;
    }
    std::string points;
    for (int i = b; i < e; ++i) points += Px(x(profile.position_um(i))) + "," + Px(y(profile.height_um(i))) + " ";
    points.pop_back();
    svg += "<polyline class=\"profile-line\" points=\"" + points + "\"/>";
  }
  svg += "</g>";
  // Legend above the plot's top right corner, where no data can lie under it.
  const double lx = kPlotX1 - 190, ly = kPlotY0 - 10;
  svg += "<g class=\"legend\"><line class=\"legend-line\" x1=\"" + Px(lx) + "\" x2=\"" + Px(lx + 22) + "\" y1=\"" +
         Px(ly - 4) + "\" y2=\"" + Px(ly - 4) + "\"/><text x=\"" + Px(lx + 28) + "\" y=\"" + Px(ly) +
         "\">height</text>";
  if (has_band) {
    svg += "<rect class=\"legend-band\" x=\"" + Px(lx + 80) + "\" y=\"" + Px(ly - 10) +
           "\" width=\"22\" height=\"12\"/>" + "<text x=\"" + Px(lx + 108) + "\" y=\"" + Px(ly) +
           "\">±2u (k = 2)</text>";
  }
  svg += "</g></svg>";
  return svg;
}

}  // namespace inspection
