// The inspection report (server/results/inspection_report.h): verdict text, escaping of user
// text, self-containedness, histogram counts against a known map, NaN gaps in profiles, the
// embedded PNGs' sizes after decoding, and bad input.
#include "server/results/inspection_report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <regex>
#include <string>
#include <vector>

#include "core/io/depth_export.h"

namespace inspection {
namespace {

const float kNaN = std::numeric_limits<float>::quiet_NaN();

v1::MeasurementResult Measurement(const std::string& name, double value, double u, v1::Verdict verdict) {
  v1::MeasurementResult m;
  m.set_name(name);
  m.set_parameter("step_height");
  m.set_measured(true);
  m.set_value(value);
  m.set_unit("um");
  m.set_standard_uncertainty(u);
  m.set_expanded_uncertainty(2 * u);
  m.set_coverage_percent(97.5);
  m.set_verdict(verdict);
  m.set_reason("reason of " + name);
  m.mutable_tolerance()->set_nominal(10.0);
  m.mutable_tolerance()->set_lower(-0.5);
  m.mutable_tolerance()->set_upper(0.5);
  m.mutable_tolerance()->set_min_coverage_percent(80);
  return m;
}

// A tilted plane, 40 x 30 px, no holes.
InspectionReportInput SmallInput(v1::Verdict verdict) {
  InspectionReportInput in;
  in.depth_um.create(30, 40, CV_32FC1);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) in.depth_um.at<float>(y, x) = 0.5f * x + 0.25f * y;
  in.inspection.set_part_id("P-0001");
  in.inspection.set_recipe_id("step-gauge");
  in.inspection.set_recipe_version(3);
  in.inspection.set_verdict(verdict);
  *in.inspection.add_measurements() = Measurement("step", 10.1234, 0.0123, verdict);
  return in;
}

std::string Render(const InspectionReportInput& in) {
  StatusOr<std::string> html = RenderInspectionReport(in);
  EXPECT_TRUE(html.ok()) << html.status().ToString();
  return html.ok() ? *html : std::string();
}

std::string VerdictElementText(const std::string& html) {
  std::smatch m;
  static const std::regex re(R"re(<div id="verdict" class="([^"]*)">([^<]*)</div>)re");
  if (!std::regex_search(html, m, re)) return "(no verdict element)";
  return m[1].str() + ":" + m[2].str();
}

std::vector<uchar> DecodeBase64(const std::string& text) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::vector<uchar> out;
  uint32_t acc = 0;
  int bits = 0;
  for (char c : text) {
    if (c == '=') break;
    const int v = value(c);
    EXPECT_GE(v, 0) << "not base64: " << c;
    if (v < 0) return {};
    acc = (acc << 6) | uint32_t(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(uchar((acc >> bits) & 0xFF));
    }
  }
  return out;
}

// The PNG of <figure id="figure_id"> decoded as stored (channels and depth unchanged). Plain
// string search: std::regex recurses per character and overflows the stack on a long data URI.
cv::Mat FigureImage(const std::string& html, const std::string& figure_id) {
  const std::string figure_tag = "<figure id=\"" + figure_id + "\">";
  const size_t figure = html.find(figure_tag + "<img ");
  if (figure == std::string::npos) return {};
  const size_t img = figure + figure_tag.size();
  const std::string prefix = "src=\"data:image/png;base64,";
  const size_t begin = html.find(prefix, img);
  if (begin == std::string::npos || begin > html.find('>', img)) return {};
  const size_t data = begin + prefix.size(), end = html.find('"', data);
  const std::vector<uchar> png = DecodeBase64(html.substr(data, end - data));
  return cv::imdecode(png, cv::IMREAD_UNCHANGED);
}

std::vector<std::string> AllMatches(const std::string& text, const std::regex& re) {
  std::vector<std::string> out;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), re); it != std::sregex_iterator(); ++it)
    out.push_back((*it)[1].str());
  return out;
}

// The <svg ...>...</svg> of the profile named `name`.
std::string ProfileSvg(const std::string& html, const std::string& name) {
  const size_t at = html.find("data-profile=\"" + name + "\"");
  if (at == std::string::npos) return {};
  const size_t begin = html.rfind("<svg", at), end = html.find("</svg>", at);
  return html.substr(begin, end - begin);
}

TEST(InspectionReport, VerdictElementShowsEachVerdictWithItsColour) {
  EXPECT_EQ(VerdictElementText(Render(SmallInput(v1::VERDICT_OK))), "v-ok:OK");
  EXPECT_EQ(VerdictElementText(Render(SmallInput(v1::VERDICT_NOT_OK))), "v-nok:NOT OK");
  EXPECT_EQ(VerdictElementText(Render(SmallInput(v1::VERDICT_NOT_DECIDABLE))), "v-nd:NOT DECIDABLE");
  const std::string html = Render(SmallInput(v1::VERDICT_OK));
  EXPECT_NE(html.find("#verdict.v-ok { background: var(--ok); }"), std::string::npos);
  EXPECT_NE(html.find("--ok: #1b7f3b"), std::string::npos);   // green
  EXPECT_NE(html.find("--nok: #c62828"), std::string::npos);  // red
  EXPECT_NE(html.find("--nd: #f0a202"), std::string::npos);   // amber
}

TEST(InspectionReport, UnsetOverallVerdictFollowsTheMeasurements) {
  InspectionReportInput in = SmallInput(v1::VERDICT_UNSPECIFIED);
  in.inspection.mutable_measurements(0)->set_verdict(v1::VERDICT_OK);
  EXPECT_EQ(VerdictElementText(Render(in)), "v-ok:OK");
  *in.inspection.add_measurements() = Measurement("second", 12.0, 0.01, v1::VERDICT_NOT_DECIDABLE);
  EXPECT_EQ(VerdictElementText(Render(in)), "v-nd:NOT DECIDABLE");
  *in.inspection.add_measurements() = Measurement("third", 12.0, 0.01, v1::VERDICT_NOT_OK);
  EXPECT_EQ(VerdictElementText(Render(in)), "v-nok:NOT OK");
  in.inspection.clear_measurements();
  EXPECT_EQ(VerdictElementText(Render(in)), "v-nd:NOT DECIDABLE");
}

TEST(InspectionReport, UserTextIsEscapedEverywhere) {
  InspectionReportInput in = SmallInput(v1::VERDICT_NOT_OK);
  in.inspection.set_part_id("<script>alert(\"p\")</script>&1");
  in.inspection.set_station("<img src=x onerror='s'>");
  in.recipe_description = "desc <b>bold</b>";
  in.inspection.mutable_measurements(0)->set_name("m\"<x>");
  in.inspection.mutable_measurements(0)->set_reason("</td><script>r</script>");
  v1::ProfileResult* p = in.inspection.add_profiles();
  p->set_name("pr<script>");
  for (int i = 0; i < 5; ++i) {
    p->add_position_um(i);
    p->add_height_um(i);
  }
  const std::string html = Render(in);
  EXPECT_NE(html.find("&lt;script&gt;alert(&quot;p&quot;)&lt;/script&gt;&amp;1"), std::string::npos);
  EXPECT_NE(html.find("&lt;img src=x onerror=&#39;s&#39;&gt;"), std::string::npos);
  EXPECT_NE(html.find("desc &lt;b&gt;bold&lt;/b&gt;"), std::string::npos);
  EXPECT_NE(html.find("data-measurement=\"m&quot;&lt;x&gt;\""), std::string::npos);
  EXPECT_NE(html.find("&lt;/td&gt;&lt;script&gt;r&lt;/script&gt;"), std::string::npos);
  EXPECT_NE(html.find("data-profile=\"pr&lt;script&gt;\""), std::string::npos);
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_EQ(html.find("<img src=x"), std::string::npos);
  EXPECT_EQ(html.find("<b>bold"), std::string::npos);
}

TEST(InspectionReport, IsSelfContained) {
  InspectionReportInput in = SmallInput(v1::VERDICT_OK);
  in.all_in_focus = cv::Mat(30, 40, CV_8UC1, cv::Scalar(128));
  const std::string html = Render(in);
  std::string lower = html;
  for (char& c : lower) c = char(std::tolower(static_cast<unsigned char>(c)));
  EXPECT_EQ(lower.find("http://"), std::string::npos);
  EXPECT_EQ(lower.find("https://"), std::string::npos);
  EXPECT_EQ(lower.find("<script"), std::string::npos);
  EXPECT_EQ(lower.find("<link"), std::string::npos);
  EXPECT_EQ(lower.find("url("), std::string::npos);
  // Every image source is a data: URI; the page forbids anything else itself.
  const auto srcs = AllMatches(html, std::regex(R"re(src="([^"]{0,16}))re"));
  ASSERT_EQ(srcs.size(), 2u);
  for (const auto& s : srcs) EXPECT_EQ(s.rfind("data:image/png", 0), 0u) << s;
  EXPECT_NE(html.find("default-src 'none'; img-src data:;"), std::string::npos);
}

TEST(InspectionReport, HistogramCountsMatchAKnownMap) {
  // 100 px at 0 um, 25 at 5 um, 50 at 10 um, 25 without depth: 64 bins over 0..10 um put 5 um
  // into bin 32 (5 / (10 / 64)) and 10 um into the last bin.
  InspectionReportInput in = SmallInput(v1::VERDICT_OK);
  in.depth_um.create(10, 20, CV_32FC1);
  float* d = in.depth_um.ptr<float>(0);
  for (int i = 0; i < 200; ++i) d[i] = i < 100 ? 0.0f : i < 125 ? 5.0f : i < 175 ? 10.0f : kNaN;
  const std::string html = Render(in);
  const auto counts = AllMatches(
      html,
      std::regex(R"re(class="hist-bar" data-bin="\d+" data-lo-um="[^"]*" data-hi-um="[^"]*" data-count="(\d+)")re"));
  ASSERT_EQ(counts.size(), 64u);
  std::vector<int> expected(64, 0);
  expected[0] = 100;
  expected[32] = 25;
  expected[63] = 50;
  for (int i = 0; i < 64; ++i) EXPECT_EQ(std::stoi(counts[size_t(i)]), expected[size_t(i)]) << "bin " << i;
  EXPECT_NE(html.find("data-bin=\"32\" data-lo-um=\"5\" data-hi-um=\"5.15625\" data-count=\"25\""), std::string::npos);
  EXPECT_NE(html.find("175 of 200 pixels with a height, in 64 bins of "), std::string::npos);
  EXPECT_NE(html.find(">height z [µm]</text>"), std::string::npos);

  // All heights equal: one bin holding every valid pixel.
  in.depth_um.setTo(cv::Scalar(3.0));
  in.depth_um.at<float>(0, 0) = kNaN;
  const auto one = AllMatches(Render(in), std::regex(R"re(data-count="(\d+)")re"));
  ASSERT_EQ(one.size(), 1u);
  EXPECT_EQ(one[0], "199");
}

TEST(InspectionReport, ProfileNaNGapSplitsTheLine) {
  InspectionReportInput in = SmallInput(v1::VERDICT_OK);
  v1::ProfileResult* gap = in.inspection.add_profiles();
  gap->set_name("gap");
  for (int i = 0; i < 10; ++i) {
    gap->add_position_um(2.0 * i);
    gap->add_height_um(i == 4 || i == 5 ? std::nan("") : 1.0 + 0.1 * i);
    gap->add_standard_uncertainty_um(0.05);
  }
  v1::ProfileResult* whole = in.inspection.add_profiles();
  whole->set_name("whole");
  for (int i = 0; i < 10; ++i) {
    whole->add_position_um(i);
    whole->add_height_um(i);
  }
  const std::string html = Render(in);
  const std::string gap_svg = ProfileSvg(html, "gap");
  ASSERT_FALSE(gap_svg.empty());
  const auto lines = AllMatches(gap_svg, std::regex(R"re(<polyline class="profile-line" points="([^"]*)")re"));
  ASSERT_EQ(lines.size(), 2u);
  // Samples 0-3 and 6-9: four points each.
  for (const auto& pts : lines) EXPECT_EQ(std::count(pts.begin(), pts.end(), ','), 4) << pts;
  const auto bands = AllMatches(gap_svg, std::regex(R"re(<polygon class="profile-band" points="([^"]*)")re"));
  ASSERT_EQ(bands.size(), 2u);
  for (const auto& pts : bands) EXPECT_EQ(std::count(pts.begin(), pts.end(), ','), 8) << pts;
  EXPECT_NE(gap_svg.find(">position along the line [µm]</text>"), std::string::npos);

  const std::string whole_svg = ProfileSvg(html, "whole");
  EXPECT_EQ(AllMatches(whole_svg, std::regex(R"re(<polyline class="profile-line" points="([^"]*)")re")).size(), 1u);
  // No uncertainties given: no band.
  EXPECT_EQ(whole_svg.find("profile-band"), std::string::npos);
}

TEST(InspectionReport, MeasurementTableShowsLimitsAndRoundedValues) {
  InspectionReportInput in = SmallInput(v1::VERDICT_OK);
  v1::MeasurementResult one_sided = Measurement("flat", 0.8, 0.05, v1::VERDICT_NOT_OK);
  one_sided.set_unit("um");
  one_sided.mutable_tolerance()->set_nominal(0.0);
  one_sided.mutable_tolerance()->clear_lower();
  one_sided.mutable_tolerance()->set_upper(0.5);
  *in.inspection.add_measurements() = one_sided;
  v1::MeasurementResult unmeasured = Measurement("hole", 0, 0, v1::VERDICT_NOT_DECIDABLE);
  unmeasured.set_measured(false);
  unmeasured.set_coverage_percent(12.0);
  *in.inspection.add_measurements() = unmeasured;
  const std::string html = Render(in);
  // U = 0.0246 -> two significant digits (3 decimals), the value to the same decimals.
  EXPECT_NE(html.find("<td class=\"num\">10.123</td><td>µm</td><td class=\"num\">0.025</td>"
                      "<td class=\"num\">97.5 (min 80)</td><td class=\"num\">10</td><td class=\"num\">9.5</td>"
                      "<td class=\"num\">10.5</td><td><span class=\"v v-ok\">OK</span></td><td>reason of step</td>"),
            std::string::npos);
  EXPECT_NE(html.find("<td class=\"num\">0.80</td><td>µm</td><td class=\"num\">0.10</td>"
                      "<td class=\"num\">97.5 (min 80)</td><td class=\"num\">0</td><td class=\"num\">—</td>"
                      "<td class=\"num\">0.5</td><td><span class=\"v v-nok\">NOT OK</span></td>"),
            std::string::npos);
  EXPECT_NE(
      html.find("<td class=\"num\">—</td><td>µm</td><td class=\"num\">—</td><td class=\"num\">12.0 (min 80)</td>"),
      std::string::npos);
}

TEST(InspectionReport, EmbeddedPngsDecodeToTheDownscaledSizes) {
  // 1200 x 600: the preview's map fits 896 px on its long side (448 rows), plus the 110 px
  // colour bar panel; the 16-bit all-in-focus image fits 1024 px and is scaled to 8 bits by its
  // maximum.
  InspectionReportInput in = SmallInput(v1::VERDICT_OK);
  in.depth_um.create(600, 1200, CV_32FC1);
  for (int y = 0; y < 600; ++y)
    for (int x = 0; x < 1200; ++x) in.depth_um.at<float>(y, x) = x < 600 ? 0.01f * y : kNaN;
  in.all_in_focus.create(600, 1200, CV_16UC1);
  for (int y = 0; y < 600; ++y)
    for (int x = 0; x < 1200; ++x) in.all_in_focus.at<uint16_t>(y, x) = uint16_t(x % 2 ? 4000 : 1000);
  const std::string html = Render(in);
  const cv::Mat preview = FigureImage(html, "depth-preview");
  ASSERT_FALSE(preview.empty());
  EXPECT_EQ(preview.type(), CV_8UC3);
  EXPECT_EQ(preview.cols, 896 + kDepthPreviewPanelWidthPx);
  EXPECT_EQ(preview.rows, 448);
  // The right half of the map had no depth: black; the left half is coloured.
  EXPECT_EQ(preview.at<cv::Vec3b>(200, 800), cv::Vec3b(0, 0, 0));
  EXPECT_NE(preview.at<cv::Vec3b>(200, 100), cv::Vec3b(0, 0, 0));
  const cv::Mat aif = FigureImage(html, "all-in-focus");
  ASSERT_FALSE(aif.empty());
  EXPECT_EQ(aif.type(), CV_8UC1);
  EXPECT_EQ(aif.size(), cv::Size(1024, 512));
  double lo = 0, hi = 0;
  cv::minMaxLoc(aif, &lo, &hi);
  EXPECT_GT(hi, 150);  // 1000 and 4000 averaged by INTER_AREA: about 2500 / 4000 * 255 = 159
  EXPECT_LE(hi, 255);
  EXPECT_NE(html.find("16-bit, shown scaled linearly 0..4000 → 0..255"), std::string::npos);

  // Small images stay as they are; the preview keeps its minimum height.
  InspectionReportInput small = SmallInput(v1::VERDICT_OK);
  small.all_in_focus = cv::Mat(30, 40, CV_8UC3, cv::Scalar(10, 200, 30));
  const std::string small_html = Render(small);
  const cv::Mat small_preview = FigureImage(small_html, "depth-preview");
  EXPECT_EQ(small_preview.size(), cv::Size(40 + kDepthPreviewPanelWidthPx, kDepthPreviewMinHeightPx));
  const cv::Mat colour = FigureImage(small_html, "all-in-focus");
  ASSERT_EQ(colour.type(), CV_8UC3);
  EXPECT_EQ(colour.size(), cv::Size(40, 30));
  EXPECT_EQ(colour.at<cv::Vec3b>(5, 5), cv::Vec3b(10, 200, 30));
  // Without an all-in-focus image there is no figure for it.
  EXPECT_EQ(Render(SmallInput(v1::VERDICT_OK)).find("id=\"all-in-focus\""), std::string::npos);
}

// The automatic z range's row: window, the coarse frames it took (and why it stopped), where it
// found focus and what was scanned.
TEST(InspectionReport, AutomaticZRangeRowSaysHowTheSearchEnded) {
  InspectionReportInput in = SmallInput(v1::VERDICT_OK);
  v1::ZRangeSearchResult* z = in.depth.mutable_z_range_search();
  z->set_window_start_um(100);
  z->set_window_end_um(600);
  z->set_coarse_step_um(20);
  z->set_coarse_frame_count(9);
  z->set_focus_low_um(200.27);
  z->set_focus_high_um(265.02);
  z->set_z_start_um(192.66);
  z->set_z_end_um(272.64);
  z->set_settled_percent(99.21);
  z->set_stopped_early(true);
  std::string html = Render(in);
  EXPECT_NE(html.find("searched 100.0 … 600.0 µm (9 coarse frames at 20.0 µm, stopped early: 99.2 % past focus), "
                      "focus 200.3 … 265.0 µm, scanned 192.7 … 272.6 µm"),
            std::string::npos)
      << html;
  z->set_stopped_early(false);
  z->set_coarse_frame_count(26);
  html = Render(in);
  EXPECT_NE(html.find("searched 100.0 … 600.0 µm (26 coarse frames at 20.0 µm), focus"), std::string::npos);
  z->set_refine_frame_count(3);
  html = Render(in);
  EXPECT_NE(html.find("searched 100.0 … 600.0 µm (26 coarse frames at 20.0 µm, 3 refining the ends), focus"),
            std::string::npos)
      << html;
}

TEST(InspectionReport, BadMapsAreInvalidArgument) {
  InspectionReportInput in = SmallInput(v1::VERDICT_OK);
  in.depth_um = cv::Mat();
  StatusOr<std::string> r = RenderInspectionReport(in);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("depth_um"), std::string::npos);
  for (int type : {CV_64FC1, CV_32FC3, CV_16UC1}) {
    in.depth_um = cv::Mat(10, 10, type, cv::Scalar::all(1));
    r = RenderInspectionReport(in);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(r.status().message().find("depth_um"), std::string::npos);
  }
  in = SmallInput(v1::VERDICT_OK);
  in.all_in_focus = cv::Mat(10, 10, CV_32FC1, cv::Scalar(0.5));
  r = RenderInspectionReport(in);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("all_in_focus"), std::string::npos);
}

TEST(InspectionReport, MapWithoutDepthStillRenders) {
  InspectionReportInput in = SmallInput(v1::VERDICT_NOT_DECIDABLE);
  in.depth_um.setTo(cv::Scalar(kNaN));
  const std::string html = Render(in);
  EXPECT_NE(html.find("no valid height in the depth map"), std::string::npos);
  EXPECT_EQ(html.find("class=\"hist-bar\""), std::string::npos);
  EXPECT_FALSE(FigureImage(html, "depth-preview").empty());
}

// The frame alignment row: the chain's transforms per frame, a still stack, and the default's
// fallback to none with its reason.
TEST(InspectionReport, AlignmentRowNamesTheMethodEachFramesTransformAndAnyFallback) {
  InspectionReportInput in = SmallInput(v1::VERDICT_OK);
  v1::DepthSummary& d = in.depth;
  d.set_alignment(v1::FRAME_ALIGNMENT_ESTIMATE);
  d.set_alignment_max_scale_change_percent(2.5);
  d.set_alignment_max_shift_px(12.25);
  d.set_alignment_seen_percent(91.5);
  v1::AlignmentDetail* a = d.mutable_alignment_detail();
  a->set_method("chain");
  a->set_reference_frame(1);
  for (int i = 0; i < 3; ++i) {
    v1::FrameTransform* f = a->add_frames();
    f->set_frame(i);
    f->set_scale(1.0 + 0.0125 * (i - 1));
    f->set_rotation_deg(0.5 * (i - 1));
    f->set_shift_x_px(6.25 * (i - 1));
    f->set_shift_y_px(-3.0 * (i - 1));
  }
  std::string html = Render(in);
  EXPECT_NE(html.find("<tr><th>Frame alignment</th><td>ESTIMATE (chain): max scale change 2.500 %, max shift 12.25 px, "
                      "seen by all 91.5 %"),
            std::string::npos);
  EXPECT_NE(html.find("<tr><td>0</td><td class=\"num\">0.98750</td><td class=\"num\">-0.5000</td><td "
                      "class=\"num\">-6.25</td><td class=\"num\">3.00</td></tr>"),
            std::string::npos)
      << html.substr(html.find("Frame alignment"), 800);
  EXPECT_NE(html.find("<tr><td>1 (reference)</td><td class=\"num\">1.00000</td>"), std::string::npos);

  a->set_decision("the linear-in-z focus-breathing model did not fit (<implausible>); registered as a chain");
  html = Render(in);
  EXPECT_NE(html.find("seen by all 91.5 %; the linear-in-z focus-breathing model did not fit (&lt;implausible&gt;); "
                      "registered as a chain<table"),
            std::string::npos)
      << html.substr(html.find("Frame alignment"), 400);
  a->clear_decision();

  a->set_still(true);
  html = Render(in);
  EXPECT_NE(html.find("ESTIMATE (chain): still, frames used as captured; measured max scale change 2.500 %"),
            std::string::npos);

  d.set_alignment(v1::FRAME_ALIGNMENT_NONE);
  d.clear_alignment_detail();
  d.mutable_alignment_detail()->set_fallback_reason("no frame pair could be registered: <featureless>");
  html = Render(in);
  EXPECT_NE(html.find("<tr><th>Frame alignment</th><td>NONE (the default fell back to none: no frame pair could be "
                      "registered: &lt;featureless&gt;)</td></tr>"),
            std::string::npos);
}

}  // namespace
}  // namespace inspection
