// inspectctl calibrate / calibration show|list: run the rig's calibration steps (thesis 4.3)
// and inspect the stored bundles (docs/inspectctl.md "calibrate", "calibration show").
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

const std::map<std::string, v1::CalibrationStep>& Steps() {
  static const std::map<std::string, v1::CalibrationStep> m = {
      {"camera-response", v1::CALIBRATION_STEP_CAMERA_RESPONSE},
      {"projector-response", v1::CALIBRATION_STEP_PROJECTOR_RESPONSE},
      {"geometry", v1::CALIBRATION_STEP_GEOMETRY},
      {"psf", v1::CALIBRATION_STEP_PSF},
      {"scatter-matrix", v1::CALIBRATION_STEP_SCATTER_MATRIX},
      {"integral-psf", v1::CALIBRATION_STEP_INTEGRAL_PSF},
      {"z-linearity", v1::CALIBRATION_STEP_Z_LINEARITY},
      {"focus-breathing", v1::CALIBRATION_STEP_FOCUS_BREATHING},
  };
  return m;
}

struct CalibrateFlags {
  std::vector<std::string> steps;
  std::string label, request_id;
};

int RunCalibrate(const CalibrateFlags& f, Session& session) {
  v1::CalibrateRequest request;
  request.set_request_id(f.request_id);
  request.set_label(f.label);
  for (const auto& s : f.steps) request.add_steps(Steps().at(Lower(s)));
  FollowOutcome outcome = Follow(session.printer, [&](const EventCallback& cb, v1::Job* job) {
    return session.client.Calibrate(request, cb, job);
  });
  return FinishJob(session.client, session.out, session.printer, outcome, std::nullopt, false);
}

int RunShow(const std::string& calibration_id, Session& session) {
  v1::Calibration cal;
  if (grpc::Status s = session.client.GetCalibration(calibration_id, &cal); !s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(cal));
    return kExitOk;
  }
  std::cout << "calibration " << cal.calibration_id() << (cal.active() ? " (active)" : "") << '\n';
  std::cout << "  created " << TimeText(cal.create_time()) << ", format version " << cal.version() << ", job "
            << cal.job_id() << '\n';
  PrintFigures(cal.summary(), "  ");
  // The newest verification of each mode made under this calibration (inspectctl verify).
  for (const v1::VerificationRecord* v : {&cal.latest_full_verification(), &cal.latest_interim_verification()}) {
    if (v->verification_id().empty()) continue;
    std::cout << "  " << (v->mode() == v1::VERIFICATION_MODE_FULL ? "full" : "interim") << " verification "
              << v->verification_id() << " at " << TimeText(v->finish_time()) << ": " << VerificationStateText(v->state());
    for (const v1::VerificationCharacteristic& c : v->characteristics()) {
      std::cout << Format(", %s %.5g", c.name().c_str(), c.value());
    }
    std::cout << '\n';
  }
  return kExitOk;
}

int RunList(Session& session) {
  v1::ListCalibrationsResponse list;
  if (grpc::Status s = session.client.ListCalibrations(&list); !s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(list));
    return kExitOk;
  }
  for (const auto& cal : list.calibrations()) {
    std::cout << cal.calibration_id() << (cal.active() ? " (active)" : "") << "  " << TimeText(cal.create_time())
              << "  job " << cal.job_id() << '\n';
    PrintFigures(cal.summary(), "    ");
  }
  if (list.calibrations_size() == 0 && !session.out.quiet) std::cout << "no calibrations\n";
  return kExitOk;
}

}  // namespace

void RegisterCalibrationCommands(CLI::App& app, CliContext& context) {
  auto* calibrate_cmd = app.add_subcommand("calibrate", "Run calibration steps on the rig (all when none given)");
  auto calibrate = std::make_shared<CalibrateFlags>();
  calibrate_cmd
      ->add_option(
          "--step", calibrate->steps,
          "Repeatable: " +
              [] {
                std::string s;
                for (const auto& k : Keys(Steps())) s += (s.empty() ? "" : ", ") + k;
                return s;
              }())
      ->check(CLI::IsMember(Keys(Steps()), CLI::ignore_case));
  calibrate_cmd->add_option("--label", calibrate->label, "Free text kept with the job");
  calibrate_cmd->add_option("--request-id", calibrate->request_id, "Idempotency key");
  context.AddCommand(calibrate_cmd, [calibrate](Session& session) { return RunCalibrate(*calibrate, session); });

  auto* calibration_cmd = app.add_subcommand("calibration", "Calibration bundles kept by the server");
  calibration_cmd->require_subcommand(1);
  auto* show_cmd = calibration_cmd->add_subcommand("show", "One bundle (default: the active one)");
  auto calibration_id = std::make_shared<std::string>();
  show_cmd->add_option("id", *calibration_id, "Calibration id");
  context.AddCommand(show_cmd, [calibration_id](Session& session) { return RunShow(*calibration_id, session); });
  auto* list_cmd = calibration_cmd->add_subcommand("list", "All bundles");
  context.AddCommand(list_cmd, [](Session& session) { return RunList(session); });
}

}  // namespace inspection::client::cli
