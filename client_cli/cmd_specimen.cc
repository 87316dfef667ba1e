// inspectctl specimen list|set: the specimen under the simulated rig's objective (docs/inspectctl.md
// "specimen"); a real rig answers FAILED_PRECONDITION.
#include <iostream>
#include <memory>
#include <string>

#include "client_cli/commands.h"

namespace inspection::client::cli {
namespace {

// The built-in specimens, the current one marked "*" (a scene file is listed after them).
int PrintSpecimens(const v1::ListSpecimensResponse& list, const Output& out) {
  if (out.json) {
    PrintJsonLine(ProtoJson(list));
    return kExitOk;
  }
  for (const auto& name : list.specimens()) std::cout << (name == list.current() ? "* " : "  ") << name << '\n';
  if (list.current().rfind("file:", 0) == 0) std::cout << "* " << list.current() << '\n';
  return kExitOk;
}

}  // namespace

void RegisterSpecimenCommands(CLI::App& app, CliContext& context) {
  auto* specimen_cmd = app.add_subcommand("specimen", "Simulated rig only: the specimen under the objective");
  specimen_cmd->require_subcommand(1);

  auto* list_cmd = specimen_cmd->add_subcommand("list", "Built-in specimens and the current one");
  context.AddCommand(list_cmd, [](Session& session) {
    v1::ListSpecimensResponse list;
    if (grpc::Status s = session.client.ListSpecimens(&list); !s.ok()) return ReportError(s);
    return PrintSpecimens(list, session.out);
  });

  auto* set_cmd = specimen_cmd->add_subcommand(
      "set", "Load a specimen: a built-in name or a scene of the server's --scene-dir, by name");
  auto specimen = std::make_shared<std::string>();
  set_cmd->add_option("name", *specimen, "Specimen")->required();
  context.AddCommand(set_cmd, [specimen](Session& session) {
    v1::ListSpecimensResponse list;
    if (grpc::Status s = session.client.SetSpecimen(*specimen, &list); !s.ok()) return ReportError(s);
    return PrintSpecimens(list, session.out);
  });
}

}  // namespace inspection::client::cli
