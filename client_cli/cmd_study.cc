// inspectctl study type1|list|show: Type-1 gauge studies (docs/inspectctl.md "Gauge capability").
// `type1` runs the study as a rig job and follows it like a scan, then prints each measurement's
// Cg, Cgk, bias test and U/T; `list` and `show` read the stored studies.
#include <cmath>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "client_cli/commands.h"
#include "client_cli/follow.h"

namespace inspection::client::cli {
namespace {

struct Type1Flags {
  std::string recipe_id;
  int recipe_version = 0;
  int repeats = 25;
  std::vector<std::string> references;  // name=value
  std::string part_id;
  double reposition_xy_um = 0.0;
  double reposition_z_um = 0.0;
  std::string label, request_id;
};

int UsageError(const std::string& message) {
  PrintErrorLine(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, message));
  return kExitUsage;
}

void PrintStudy(const v1::Study& s) {
  std::cout << "type-1 study " << s.study_id() << ": recipe " << s.recipe_id() << " v" << s.recipe_version();
  if (!s.part_id().empty()) std::cout << ", reference part " << s.part_id();
  std::cout << ", " << s.repeats() << " repeats: " << (s.capable() ? "CAPABLE" : "NOT CAPABLE") << '\n';
  std::cout << "  re-positioning: " << s.repositioning() << '\n';
  std::cout << "  calibration: " << (s.calibration_id().empty() ? "none (uncalibrated)" : s.calibration_id()) << '\n';
  std::cout << Format("  %-16s %4s %12s %10s %12s %10s %7s %7s %11s %7s %7s %6s\n", "measurement", "n", "mean", "s",
                      "reference", "T", "Cg", "Cgk", "bias", "t", "p", "U/T%");
  for (const v1::MeasurementCapability& c : s.measurements()) {
    std::cout << Format("  %-16s %4d %12.6g %10.4g %12.6g %10.4g %7.3f %7.3f %11.4g %7.3f %7.3g %6.1f\n",
                        c.name().c_str(), c.n(), c.mean(), c.stddev(), c.reference(), c.tolerance(), c.cg(), c.cgk(),
                        c.bias(), c.t_statistic(), c.p_value(), c.u_over_t_percent());
    std::cout << "    " << c.reason() << (c.bias_significant() ? "; bias significant" : "; bias not significant")
              << " (t_crit " << Format("%.3f", c.t_critical()) << "); reference: " << c.reference_source() << " ["
              << c.unit() << "]\n";
  }
  if (!s.report_artifact_id().empty()) {
    std::cout << "  report: " << s.report_artifact_id() << " (inspectctl download " << s.report_artifact_id()
              << " --out study_report.html)\n";
  }
}

int RunType1(const Type1Flags& f, Session& session) {
  v1::StartStudyRequest request;
  request.set_request_id(f.request_id);
  request.set_label(f.label);
  request.set_recipe_id(f.recipe_id);
  request.set_recipe_version(f.recipe_version);
  request.set_repeats(f.repeats);
  request.set_part_id(f.part_id);
  request.set_reposition_xy_um(f.reposition_xy_um);
  request.set_reposition_z_um(f.reposition_z_um);
  for (const std::string& r : f.references) {
    const size_t eq = r.find('=');
    if (eq == std::string::npos || eq == 0) return UsageError("--reference '" + r + "' is not NAME=VALUE");
    try {
      size_t used = 0;
      const double v = std::stod(r.substr(eq + 1), &used);
      if (used != r.size() - eq - 1 || !std::isfinite(v)) throw std::invalid_argument(r);
      (*request.mutable_reference_values())[r.substr(0, eq)] = v;
    } catch (const std::exception&) {
      return UsageError("--reference '" + r + "': the value is not a number");
    }
  }
  FollowOutcome outcome = Follow(session.printer, [&](const EventCallback& cb, v1::Job* job) {
    return session.client.StartStudy(request, cb, job);
  });
  const int code = FinishJob(session.client, session.out, session.printer, outcome, std::nullopt, false);
  if (code == kExitOk && outcome.have_job && outcome.job.result().has_study() && !session.out.json &&
      !session.out.quiet) {
    PrintStudy(outcome.job.result().study());
  }
  return code;
}

int RunShow(const std::string& study_id, Session& session) {
  v1::Study study;
  if (grpc::Status s = session.client.GetStudy(study_id, &study); !s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(study));
    return kExitOk;
  }
  PrintStudy(study);
  return kExitOk;
}

int RunList(const std::string& recipe_id, int limit, Session& session) {
  v1::ListStudiesRequest request;
  request.set_recipe_id(recipe_id);
  request.set_page_size(limit);
  v1::ListStudiesResponse list;
  if (grpc::Status s = session.client.ListStudies(request, &list); !s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(list));
    return kExitOk;
  }
  for (const v1::Study& s : list.studies()) {
    std::cout << s.study_id() << "  " << TimeText(s.finish_time()) << "  recipe " << s.recipe_id() << " v"
              << s.recipe_version() << "  " << s.repeats() << " repeats  " << (s.capable() ? "CAPABLE" : "NOT CAPABLE");
    for (const v1::MeasurementCapability& c : s.measurements()) {
      std::cout << Format("  %s Cg %.2f Cgk %.2f", c.name().c_str(), c.cg(), c.cgk());
    }
    std::cout << '\n';
  }
  if (list.studies_size() == 0 && !session.out.quiet) std::cout << "no studies\n";
  return kExitOk;
}

}  // namespace

void RegisterStudyCommands(CLI::App& app, CliContext& context) {
  auto* study_cmd = app.add_subcommand("study", "Gauge capability studies (Type-1: Cg, Cgk, bias)");
  study_cmd->require_subcommand(1);

  auto* type1_cmd = study_cmd->add_subcommand("type1", "Repeat a recipe's scan on one reference part and judge capability");
  auto f = std::make_shared<Type1Flags>();
  type1_cmd->add_option("--recipe", f->recipe_id, "Recipe id")->required();
  type1_cmd->add_option("--recipe-version", f->recipe_version, "Recipe version (default: the current one)");
  type1_cmd->add_option("--repeats", f->repeats, "Repeated scans, 10..1000 (default 25)");
  type1_cmd->add_option("--reference", f->references,
                        "Repeatable NAME=VALUE: the reference part's certified value of a measurement "
                        "(default: the tolerance's nominal, and the result says so)");
  type1_cmd->add_option("--part", f->part_id, "The reference part's id");
  type1_cmd->add_option("--reposition-xy", f->reposition_xy_um,
                        "Simulated rig: sigma of the lateral re-positioning per repeat, um (0 = default 5)");
  type1_cmd->add_option("--reposition-z", f->reposition_z_um,
                        "Simulated rig: sigma of the height re-positioning per repeat, um (0 = default 2)");
  type1_cmd->add_option("--label", f->label, "Free text kept with the job");
  type1_cmd->add_option("--request-id", f->request_id, "Idempotency key");
  context.AddCommand(type1_cmd, [f](Session& session) { return RunType1(*f, session); });

  auto* list_cmd = study_cmd->add_subcommand("list", "Stored studies, newest first");
  auto recipe = std::make_shared<std::string>();
  auto limit = std::make_shared<int>(0);
  list_cmd->add_option("--recipe", *recipe, "Only this recipe's studies");
  list_cmd->add_option("--limit", *limit, "At most this many (default 50)");
  context.AddCommand(list_cmd, [recipe, limit](Session& session) { return RunList(*recipe, *limit, session); });

  auto* show_cmd = study_cmd->add_subcommand("show", "One stored study");
  auto study_id = std::make_shared<std::string>();
  show_cmd->add_option("id", *study_id, "Study id (the study job's id)")->required();
  context.AddCommand(show_cmd, [study_id](Session& session) { return RunShow(*study_id, session); });
}

}  // namespace inspection::client::cli
