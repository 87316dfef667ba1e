// Writes a sample inspection report (server/results/inspection_report.h) for the browser test: a
// synthetic step gauge (tilted plane, 25 um step, a rough patch, a hole without depth), measured
// by core/ as a scan's result would be (step height and Sa with their uncertainties, ISO 14253-1
// verdicts, a line profile across the step and the hole), so the page shows real figures.
//
// Usage: report_sample OUT.html [WIDTHxHEIGHT]   (default 1024x768)
// Prints "<path> <bytes> bytes, verdict <text>, rendered in <s> s" and one line per measurement.
// Exit 1 with a message on failure.
#include <google/protobuf/util/time_util.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <opencv2/core.hpp>
#include <string>

#include "core/metrology/line_profile.h"
#include "core/metrology/measurement.h"
#include "core/metrology/verdict.h"
#include "server/results/inspection_report.h"
#include "server/results/inspection_result.h"

namespace inspection {
namespace {

constexpr double kPixelSizeUm = 1.5;
constexpr double kStepUm = 25.0;

struct Specimen {
  cv::Mat truth_um, depth_um;  // CV_32FC1
  cv::Mat all_in_focus;        // CV_8UC1
};

// Ground truth: a tilted plane, the right half 25 um higher, a rough patch (sinusoid, amplitude
// 1 um: Sa = 2/pi um) in the lower left. Measured: truth + SFF-like noise (sigma 0.12 um), no
// depth in a textureless disc on the upper step and at 0.3 % scattered pixels.
Specimen MakeSpecimen(cv::Size size) {
  Specimen s;
  const int w = size.width, h = size.height;
  s.truth_um.create(size, CV_32FC1);
  s.depth_um.create(size, CV_32FC1);
  s.all_in_focus.create(size, CV_8UC1);
  cv::RNG rng(20261126);
  const double hole_x = 0.75 * w, hole_y = 0.5 * h, hole_r = 0.05 * std::min(w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double x_um = x * kPixelSizeUm, y_um = y * kPixelSizeUm;
      const bool upper = x >= w / 2;
      const bool rough = !upper && y >= 0.55 * h;
      double z = 8.0 + 0.012 * x_um + 0.006 * y_um + (upper ? kStepUm : 0.0);
      if (rough) z += 1.0 * std::sin(2 * M_PI * x_um / 60.0);
      s.truth_um.at<float>(y, x) = float(z);
      const bool hole = std::hypot(x - hole_x, y - hole_y) < hole_r || rng.uniform(0.0, 1.0) < 0.003;
      s.depth_um.at<float>(y, x) = hole ? std::numeric_limits<float>::quiet_NaN() : float(z + rng.gaussian(0.12));
      // The camera's view: a speckled texture (what SFF needs), darker on the lower level,
      // featureless and bright in the disc.
      double grey = (upper ? 150 : 110) + 45 * std::sin(x / 5.3) * std::cos(y / 7.1) + rng.gaussian(12);
      if (std::hypot(x - hole_x, y - hole_y) < hole_r) grey = 215;
      s.all_in_focus.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(grey);
    }
  }
  return s;
}

v1::MeasurementResult MeasureOne(const std::string& name, const MeasurementSpec& spec, const Tolerance& tol,
                                 const MeasurementContext& ctx) {
  v1::MeasurementResult m;
  m.set_name(name);
  m.set_parameter(MeasurementKindName(spec.kind));
  m.set_unit(spec.unit());
  StatusOr<MeasuredValue> v = Measure(spec, ctx, name);
  const VerdictResult verdict = v.ok() ? Judge(v->value, v->uncertainty.standard_uncertainty, v->coverage_percent, tol)
                                       : NotMeasured(v.status().message());
  if (v.ok()) {
    m.set_measured(true);
    m.set_value(v->value);
    m.set_standard_uncertainty(v->uncertainty.standard_uncertainty);
    m.set_expanded_uncertainty(verdict.expanded_uncertainty);
    m.set_coverage_percent(v->coverage_percent);
  }
  m.set_verdict(ToProtoVerdict(verdict.verdict));
  m.set_reason(verdict.reason);
  v1::RecipeTolerance* t = m.mutable_tolerance();
  t->set_nominal(tol.nominal);
  if (tol.lower) t->set_lower(*tol.lower);
  if (tol.upper) t->set_upper(*tol.upper);
  t->set_min_coverage_percent(tol.min_coverage_percent);
  return m;
}

int Run(int argc, char** argv) {
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: report_sample OUT.html [WIDTHxHEIGHT]\n");
    return 2;
  }
  cv::Size size(1024, 768);
  if (argc == 3 && (std::sscanf(argv[2], "%dx%d", &size.width, &size.height) != 2 || size.width < 64 ||
                    size.height < 64 || size.width > 8192 || size.height > 8192)) {
    std::fprintf(stderr, "report_sample: size must be WIDTHxHEIGHT, 64..8192 each, got %s\n", argv[2]);
    return 2;
  }
  const Specimen s = MakeSpecimen(size);
  const double w = size.width, h = size.height;

  MeasurementContext ctx;
  ctx.depth_um = s.depth_um;
  ctx.pixel_size_um = kPixelSizeUm;
  for (double z = 0.0; z <= 90.0; z += 1.0) ctx.noise.z_positions_um.push_back(z);
  ctx.noise.stage_repeatability_um = 0.1;

  InspectionReportInput in;
  v1::InspectionResult& r = in.inspection;
  r.set_part_id("GAUGE-2026-0412");
  r.set_recipe_id("step-gauge");
  r.set_recipe_version(2);
  r.set_station("line 3 / cell B");
  r.set_job_id("job-20261126-000042");
  r.set_calibration_id("cal-20261120-rig1");
  r.set_sequence(42);
  *r.mutable_finish_time() = google::protobuf::util::TimeUtil::SecondsToTimestamp(1795669200);  // 2026-11-26T05:00Z
  r.mutable_timings()->set_queue_seconds(0.4);
  r.mutable_timings()->set_scan_seconds(9.8);
  r.mutable_timings()->set_engine_seconds(0.35);
  r.mutable_timings()->set_measure_seconds(0.6);
  in.recipe_description = "Step gauge 25 µm <type A> & roughness patch (Sa ≤ 0.4 µm)";

  MeasurementSpec step;
  step.kind = MeasurementKind::kStepHeight;
  step.roi = RegionOfInterest::Rectangle(0.55 * w, 0.08 * h, 0.38 * w, 0.3 * h);
  step.reference_roi = RegionOfInterest::Rectangle(0.07 * w, 0.08 * h, 0.38 * w, 0.3 * h);
  Tolerance step_tol;
  step_tol.nominal = kStepUm;
  step_tol.lower = -0.5;
  step_tol.upper = 0.5;
  step_tol.min_coverage_percent = 90;
  *r.add_measurements() = MeasureOne("step_A", step, step_tol, ctx);

  MeasurementSpec sa;
  sa.kind = MeasurementKind::kSa;
  sa.roi = RegionOfInterest::Rectangle(0.05 * w, 0.6 * h, 0.4 * w, 0.35 * h);
  Tolerance sa_tol;
  sa_tol.nominal = 0.0;
  sa_tol.upper = 0.4;
  sa_tol.min_coverage_percent = 90;
  *r.add_measurements() = MeasureOne("roughness_patch", sa, sa_tol, ctx);

  std::vector<Verdict> verdicts;
  for (const auto& m : r.measurements())
    verdicts.push_back(m.verdict() == v1::VERDICT_OK       ? Verdict::kOk
                       : m.verdict() == v1::VERDICT_NOT_OK ? Verdict::kNotOk
                                                           : Verdict::kNotDecidable);
  r.set_verdict(ToProtoVerdict(OverallVerdict(verdicts)));

  // Across the step and through the disc without depth: the plot shows the gap.
  LineProfileOptions line;
  line.start = {0.1 * w, 0.5 * h};
  line.end = {0.9 * w, 0.5 * h};
  line.width_px = 9;
  line.spacing_px = 2;
  StatusOr<DepthNoiseModel> noise = EstimateDepthNoise(s.depth_um, cv::Mat(), ctx.noise);
  if (!noise.ok()) {
    std::fprintf(stderr, "report_sample: noise model: %s\n", noise.status().ToString().c_str());
    return 1;
  }
  StatusOr<LineProfile> profile = ExtractLineProfile(s.depth_um, kPixelSizeUm, line, &*noise, "across_step");
  if (!profile.ok()) {
    std::fprintf(stderr, "report_sample: profile: %s\n", profile.status().ToString().c_str());
    return 1;
  }
  v1::ProfileResult* p = r.add_profiles();
  p->set_name("across_step");
  p->set_width_um(line.width_px * kPixelSizeUm);
  for (size_t i = 0; i < profile->position_um.size(); ++i) {
    p->add_position_um(profile->position_um[i]);
    p->add_height_um(profile->height_um[i]);
    p->add_standard_uncertainty_um(profile->uncertainty_um[i]);
  }
  p->set_coverage_percent(profile->coverage_percent());

  // Scan metadata as a scan on the simulated rig reports it.
  v1::DepthSummary& d = in.depth;
  d.set_width(size.width);
  d.set_height(size.height);
  d.set_pixel_size_um(kPixelSizeUm);
  double z_min = std::numeric_limits<double>::infinity(), z_max = -z_min, sq = 0, abs_sum = 0;
  int valid = 0;
  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      const float v = s.depth_um.at<float>(y, x);
      if (!std::isfinite(v)) continue;
      z_min = std::min(z_min, double(v));
      z_max = std::max(z_max, double(v));
      const double e = v - s.truth_um.at<float>(y, x);
      sq += e * e;
      abs_sum += std::abs(e);
      ++valid;
    }
  }
  d.set_valid_percent(100.0 * valid / double(size.area()));
  d.set_z_min_um(z_min);
  d.set_z_max_um(z_max);
  d.set_frame_count(int(ctx.noise.z_positions_um.size()));
  d.set_has_ground_truth(true);
  d.set_rmse_um(std::sqrt(sq / std::max(valid, 1)));
  d.set_mean_abs_error_um(abs_sum / std::max(valid, 1));
  d.set_engine_seconds(0.35);
  d.set_method(v1::RECONSTRUCTION_METHOD_SFF);
  d.set_illumination("HF+ADAPT");
  d.set_alignment(v1::FRAME_ALIGNMENT_NONE);
  d.set_alignment_seen_percent(100.0);

  in.depth_um = s.depth_um;
  in.all_in_focus = s.all_in_focus;
  const auto render_start = std::chrono::steady_clock::now();
  StatusOr<std::string> html = RenderInspectionReport(in);
  const double render_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - render_start).count();
  if (!html.ok()) {
    std::fprintf(stderr, "report_sample: %s\n", html.status().ToString().c_str());
    return 1;
  }
  std::ofstream out(argv[1], std::ios::binary | std::ios::trunc);
  out << *html;
  out.close();
  if (!out) {
    std::fprintf(stderr, "report_sample: cannot write %s\n", argv[1]);
    return 1;
  }
  const char* verdict = r.verdict() == v1::VERDICT_OK       ? "OK"
                        : r.verdict() == v1::VERDICT_NOT_OK ? "NOT OK"
                                                            : "NOT DECIDABLE";
  std::printf("%s %zu bytes, verdict %s, rendered in %.3f s\n", argv[1], html->size(), verdict, render_seconds);
  for (const auto& m : r.measurements()) {
    std::printf("  %s %s = %.4f +- %.4f %s, coverage %.1f %%: %s (%s)\n", m.name().c_str(), m.parameter().c_str(),
                m.value(), m.expanded_uncertainty(), m.unit().c_str(), m.coverage_percent(),
                v1::Verdict_Name(m.verdict()).c_str(), m.reason().c_str());
  }
  return 0;
}

}  // namespace
}  // namespace inspection

int main(int argc, char** argv) { return inspection::Run(argc, argv); }
