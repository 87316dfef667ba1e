// What the commands of inspectctl share: the connection options (--server, --tls-ca,
// --token-file, --connect-timeout), the output format (--json, --quiet), and the dispatch of
// the one parsed command once the server is reachable (docs/inspectctl.md "Global options").
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "client_cli/inspection_client.h"
#include "client_cli/output.h"

namespace inspection::client::cli {

// What a command's handler gets once the connection is up.
struct Session {
  InspectionClient& client;
  const Output& out;
  ProgressPrinter& printer;
};

// A command's handler: does the command's work and returns its exit code (output.h).
using CommandHandler = std::function<int(Session& session)>;

// The connection and output options of the whole app, and the handlers of its commands. Each
// command group registers its CLI11 subcommands with their handlers (commands.h); after parsing,
// Run connects and calls the handler of the command given. Not thread-safe (used by main only).
class CliContext {
 public:
  // Server address from INSPECT_SERVER (else 127.0.0.1:50051), connect timeout 5 s.
  CliContext();

  // --server, --tls-ca, --token-file, --connect-timeout, --json, -q/--quiet on `app`.
  void AddGlobalOptions(CLI::App& app);

  // `handler` runs when `command` (a leaf subcommand of the app) is the one parsed. The handler
  // owns the variables the command's options write to (capture them by shared_ptr).
  void AddCommand(const CLI::App* command, CommandHandler handler);

  // After a successful parse: reads the token file (exit 2 when unusable), waits for the server
  // (exit 3 when unreachable), then runs the parsed command's handler and returns its exit code.
  int Run();

 private:
  ClientOptions client_options_;
  std::string token_file_;
  Output out_;
  std::vector<std::pair<const CLI::App*, CommandHandler>> commands_;
};

// The names of a name -> proto enum map, for CLI::IsMember.
template <typename T>
std::vector<std::string> Keys(const std::map<std::string, T>& m) {
  std::vector<std::string> keys;
  for (const auto& [k, v] : m) keys.push_back(k);
  return keys;
}

}  // namespace inspection::client::cli
