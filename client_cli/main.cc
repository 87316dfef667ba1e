// inspectctl: command-line client of the inspection service (inspection.v1). Starts scans,
// reconstructions and calibrations, follows their progress, fetches results. See docs/inspectctl.md.
// The commands live in cmd_*.cc (one file per group); this file assembles and runs them.
#include <CLI/CLI.hpp>

#include "client_cli/cli_context.h"
#include "client_cli/commands.h"
#include "client_cli/output.h"

namespace inspection::client::cli {
namespace {

int Main(int argc, char** argv) {
  CliContext context;
  CLI::App app{"inspectctl: client of the inspection service (shape from focus on a microscope rig)", "inspectctl"};
  app.require_subcommand(1);
  app.fallthrough();  // global options may follow the command
  context.AddGlobalOptions(app);

  // The order here is the order of `inspectctl --help`.
  RegisterStatusCommands(app, context);
  RegisterScanCommand(app, context);
  RegisterReconstructCommand(app, context);
  RegisterJobCommands(app, context);
  RegisterCalibrationCommands(app, context);
  RegisterSpecimenCommands(app, context);
  RegisterRecipeCommands(app, context);
  RegisterResultCommands(app, context);
  RegisterStudyCommands(app, context);
  RegisterVerifyCommand(app, context);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // prints the help or the usage error
    return code == 0 ? kExitOk : kExitUsage;
  }
  return context.Run();
}

}  // namespace
}  // namespace inspection::client::cli

int main(int argc, char** argv) { return inspection::client::cli::Main(argc, argv); }
