// inspectctl reconstruct: a depth map from an uploaded stack folder or a stored scan, followed
// to its end and downloaded (USAGE.md "reconstruct").
#include <memory>
#include <string>

#include "client_cli/commands.h"
#include "client_cli/follow.h"
#include "client_cli/reconstruction_flags.h"

namespace inspection::client::cli {
namespace {

namespace fs = std::filesystem;

struct ReconstructFlags {
  std::string stack_dir, scan_id, out_dir;
  ReconstructionFlags reconstruction;
  std::string label, request_id;
};

int RunReconstruct(const ReconstructFlags& f, Session& session) {
  v1::ReconstructStart start;
  start.set_request_id(f.request_id);
  start.set_label(f.label);
  *start.mutable_options() = f.reconstruction.ToProto();
  FollowOutcome outcome;
  if (!f.scan_id.empty()) {
    start.set_scan_id(f.scan_id);
    outcome = Follow(session.printer, [&](const EventCallback& cb, v1::Job* job) {
      return session.client.ReconstructStored(start, cb, job);
    });
  } else {
    outcome = Follow(session.printer, [&](const EventCallback& cb, v1::Job* job) {
      return session.client.ReconstructUpload(f.stack_dir, start, cb, job, [&](int64_t done, int64_t total) {
        session.printer.OnBytes("upload", done, total);
      });
    });
  }
  return FinishJob(session.client, session.out, session.printer, outcome, fs::path(f.out_dir), false);
}

}  // namespace

void RegisterReconstructCommand(CLI::App& app, CliContext& context) {
  auto* cmd = app.add_subcommand("reconstruct", "Depth map from an uploaded stack folder or a stored scan");
  auto f = std::make_shared<ReconstructFlags>();
  // Exactly one source: an uploaded folder or a stored scan.
  auto* source = cmd->add_option_group("source", "Exactly one of");
  source->add_option("--stack", f->stack_dir, "Stack folder to upload (stack.json + frames)")
      ->check(CLI::ExistingDirectory);
  source->add_option("--scan-id", f->scan_id, "A stored scan (JobResult.scan_id)");
  source->require_option(1);
  cmd->add_option("--out", f->out_dir, "Folder for the results")->required();
  f->reconstruction.Add(cmd);
  cmd->add_option("--label", f->label, "Free text kept with the job");
  cmd->add_option("--request-id", f->request_id, "Idempotency key");
  context.AddCommand(cmd, [f](Session& session) { return RunReconstruct(*f, session); });
}

}  // namespace inspection::client::cli
