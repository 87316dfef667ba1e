// inspectctl status / reset: the rig's state, devices, calibration, queue and scan defaults
// (docs/inspectctl.md "status", "reset").
#include <iostream>
#include <memory>

#include "client_cli/commands.h"

namespace inspection::client::cli {
namespace {

int PrintRigStatus(const v1::RigStatus& rig, const Output& out) {
  if (out.json) {
    PrintJsonLine(ProtoJson(rig));
    return kExitOk;
  }
  std::cout << "state: " << Lower(Short(v1::RigState_Name(rig.state()), "RIG_STATE_"));
  if (!rig.state_detail().empty()) std::cout << " (" << rig.state_detail() << ")";
  std::cout << '\n';
  for (const auto& d : rig.devices()) {
    std::cout << Format("  %-9s %-12s %s %s %s", d.role().c_str(), d.driver().c_str(), d.model().c_str(),
                        d.serial().c_str(), d.connected() ? "connected" : "DISCONNECTED");
    if (!d.detail().empty()) std::cout << " - " << d.detail();
    std::cout << '\n';
  }
  std::cout << "calibration: " << (rig.active_calibration_id().empty() ? "none" : rig.active_calibration_id()) << '\n';
  if (rig.verification_state() != v1::VERIFICATION_STATE_UNSPECIFIED) {
    std::cout << "verification: " << VerificationStateText(rig.verification_state());
    if (!rig.verification_detail().empty()) std::cout << " (" << rig.verification_detail() << ")";
    std::cout << '\n';
  }
  std::cout << "running job: " << (rig.running_job_id().empty() ? "none" : rig.running_job_id()) << ", queue "
            << rig.queued_jobs() << "/" << rig.queue_capacity() << '\n';
  if (rig.simulated()) std::cout << "simulated rig, specimen: " << rig.specimen() << '\n';
  const auto& d = rig.scan_defaults();
  std::cout << Format("pixel size: %.4f um; scan defaults: z %.1f .. %.1f um step %.2f um, exposure %.0f us",
                      rig.pixel_size_um(), d.z_start_um(), d.z_end_um(), d.z_step_um(), d.exposure_us());
  if (d.focus_search_step_um() > 0.0) std::cout << Format(", focus search step %.1f um", d.focus_search_step_um());
  std::cout << '\n';
  std::cout << "server version: " << rig.server_version() << '\n';
  return kExitOk;
}

}  // namespace

void RegisterStatusCommands(CLI::App& app, CliContext& context) {
  auto* status_cmd = app.add_subcommand("status", "Rig state, devices, calibration and queue");
  context.AddCommand(status_cmd, [](Session& session) {
    v1::RigStatus rig;
    if (grpc::Status s = session.client.GetRigStatus(&rig); !s.ok()) return ReportError(s);
    return PrintRigStatus(rig, session.out);
  });

  auto* reset_cmd = app.add_subcommand("reset", "Reconnect the rig's devices after an error");
  context.AddCommand(reset_cmd, [](Session& session) {
    v1::RigStatus rig;
    if (grpc::Status s = session.client.ResetRig(&rig); !s.ok()) return ReportError(s);
    return PrintRigStatus(rig, session.out);
  });
}

}  // namespace inspection::client::cli
