// inspectctl verify [--interim]: instrument verification on the rig's material measures
// (docs/inspectctl.md "verify", docs/verification.md). Runs the Verify job and follows it like
// calibrate, then prints the record: each ISO 25178-600 characteristic with its expanded
// uncertainty U = 2u and unit, the step heights and the rig's verification state.
#include <iostream>
#include <memory>
#include <optional>
#include <string>

#include "client_cli/commands.h"
#include "client_cli/follow.h"

namespace inspection::client::cli {
namespace {

struct VerifyFlags {
  bool interim = false;
  std::string label, request_id;
};

void PrintVerification(const v1::VerificationRecord& r) {
  const bool full = r.mode() == v1::VERIFICATION_MODE_FULL;
  std::cout << (full ? "full" : "interim") << " verification " << r.verification_id() << ": "
            << VerificationStateText(r.state()) << " (" << r.scans() << " scans, calibration "
            << (r.calibration_id().empty() ? "none" : r.calibration_id()) << ")\n";
  std::cout << Format("  %-14s %14s %14s  %s\n", "characteristic", "value", "U (k=2)", "unit");
  for (const v1::VerificationCharacteristic& c : r.characteristics()) {
    std::cout << Format("  %-14s %14.6g %14.4g  %s\n", c.name().c_str(), c.value(), c.expanded_uncertainty(),
                        c.unit().empty() ? "1" : c.unit().c_str());
  }
  for (const v1::VerificationStepPoint& s : r.steps()) {
    std::cout << Format("  step %-8s certified %.4f um, measured %.4f +- %.4f um\n", s.specimen().c_str(),
                        s.certified_um(), s.measured_um(), 2 * s.measured_u_um());
  }
  if (!r.full_verification_id().empty()) std::cout << "  limits from full verification " << r.full_verification_id() << '\n';
  for (const std::string& f : r.findings()) std::cout << "  finding: " << f << '\n';
}

int RunVerify(const VerifyFlags& f, Session& session) {
  v1::VerifyRequest request;
  request.set_request_id(f.request_id);
  request.set_label(f.label);
  request.set_mode(f.interim ? v1::VERIFICATION_MODE_INTERIM : v1::VERIFICATION_MODE_FULL);
  FollowOutcome outcome = Follow(session.printer, [&](const EventCallback& cb, v1::Job* job) {
    return session.client.Verify(request, cb, job);
  });
  // The state is the result, not an error: a failed interim check exits 0 like a NOT OK verdict.
  const int code = FinishJob(session.client, session.out, session.printer, outcome, std::nullopt, false);
  if (code == kExitOk && outcome.have_job && outcome.job.result().has_verification() && !session.out.json &&
      !session.out.quiet) {
    PrintVerification(outcome.job.result().verification());
  }
  return code;
}

}  // namespace

void RegisterVerifyCommand(CLI::App& app, CliContext& context) {
  auto* verify_cmd = app.add_subcommand(
      "verify", "Verify the instrument on its material measures (ISO 25178-600 characteristics, role engineer)");
  auto f = std::make_shared<VerifyFlags>();
  verify_cmd->add_flag("--interim", f->interim,
                       "The short interim check (the flat and one step) against the last full verification");
  verify_cmd->add_option("--label", f->label, "Free text kept with the job");
  verify_cmd->add_option("--request-id", f->request_id, "Idempotency key");
  context.AddCommand(verify_cmd, [f](Session& session) { return RunVerify(*f, session); });
}

}  // namespace inspection::client::cli
