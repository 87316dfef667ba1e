// Writes a sample Type-1 study report (server/results/study_report.h) for the browser test: 25
// repeats of a step standard (certified 1.000 um, tolerance +-0.1 um: not capable) and of a
// second step read against +-0.5 um (capable), with normal noise from a fixed seed, the figures
// computed by server/results/study_result.h as a study job computes them.
//
// Usage: study_report_sample OUT.html
// Prints "<path> <bytes> bytes, <CAPABLE|NOT CAPABLE>" and per measurement
// "values NAME v1 v2 ..." and "figures NAME cg cgk" (what the browser test checks the page against).
#include <cstdio>
#include <fstream>
#include <random>
#include <string>

#include <google/protobuf/util/json_util.h>

#include "server/results/study_report.h"
#include "server/results/study_result.h"

namespace inspection {
namespace {

int Main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: study_report_sample OUT.html\n");
    return 1;
  }
  v1::Recipe recipe;
  const std::string json = R"({
    "recipe_id": "pgr-1um", "version": 3, "description": "PGR step standard 1 um <ISO 5436-1 type A> & friends",
    "measurements": [
      {"name": "step", "parameter": "step_height", "tolerance": {"nominal": 1.0, "lower": -0.1, "upper": 0.1}},
      {"name": "step_wide", "parameter": "step_height", "tolerance": {"nominal": 1.0, "lower": -0.5, "upper": 0.5}}
    ]})";
  if (!google::protobuf::util::JsonStringToMessage(json, &recipe).ok()) return 1;
  std::mt19937_64 rng(20261202);
  std::normal_distribution<double> noise(0.004, 0.012);
  std::vector<v1::InspectionResult> repeats;
  for (int i = 0; i < 25; ++i) {
    v1::InspectionResult r;
    const double v = 1.0 + noise(rng);
    for (const char* name : {"step", "step_wide"}) {
      v1::MeasurementResult* m = r.add_measurements();
      m->set_name(name);
      m->set_parameter("step_height");
      m->set_measured(true);
      m->set_value(v);
      m->set_unit("um");
      m->set_expanded_uncertainty(0.03);
    }
    repeats.push_back(r);
  }
  google::protobuf::Map<std::string, double> references;
  references["step"] = 1.0;
  auto capabilities = StudyCapabilities(recipe, references, repeats);
  if (!capabilities.ok()) {
    std::fprintf(stderr, "%s\n", capabilities.status().ToString().c_str());
    return 1;
  }
  v1::Study study;
  study.set_study_id("study-sample");
  study.set_recipe_id(recipe.recipe_id());
  study.set_recipe_version(recipe.version());
  study.set_part_id("PGR-0815 <certified>");
  study.set_repeats(25);
  study.set_repositioning("simulated: random placement per repeat, sigma 5 um xy, 2 um z");
  study.mutable_finish_time()->set_seconds(1796000000);
  bool capable = true;
  for (auto& c : *capabilities) {
    capable = capable && c.capable();
    *study.add_measurements() = c;
  }
  study.set_capable(capable);
  auto html = RenderStudyReport(study, recipe.description());
  if (!html.ok()) {
    std::fprintf(stderr, "%s\n", html.status().ToString().c_str());
    return 1;
  }
  std::ofstream(argv[1], std::ios::binary) << *html;
  std::printf("%s %zu bytes, %s\n", argv[1], html->size(), capable ? "CAPABLE" : "NOT CAPABLE");
  for (const auto& c : study.measurements()) {
    std::printf("values %s", c.name().c_str());
    for (double v : c.values()) std::printf(" %.10g", v);
    std::printf("\nfigures %s %.6f %.6f %d\n", c.name().c_str(), c.cg(), c.cgk(), c.capable());
  }
  return 0;
}

}  // namespace
}  // namespace inspection

int main(int argc, char** argv) { return inspection::Main(argc, argv); }
