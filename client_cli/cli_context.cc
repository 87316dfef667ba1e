// Global options of inspectctl, the token file, the connection, and dispatch to the parsed
// command (docs/inspectctl.md "Global options", "Exit codes").
#include "client_cli/cli_context.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace inspection::client::cli {
namespace {

// Reads the bearer token (surrounding whitespace dropped); returns an error text, "" when read.
std::string ReadToken(const std::string& path, std::string* token) {
  std::ifstream in(path);
  if (!in) return "cannot read token file " + path;
  std::stringstream ss;
  ss << in.rdbuf();
  std::string t = ss.str();
  const auto not_space = [](unsigned char c) { return !std::isspace(c); };
  t.erase(t.begin(), std::find_if(t.begin(), t.end(), not_space));
  t.erase(std::find_if(t.rbegin(), t.rend(), not_space).base(), t.end());
  if (t.empty()) return "token file " + path + " is empty";
  *token = t;
  return "";
}

}  // namespace

CliContext::CliContext() {
  const char* env_server = std::getenv("INSPECT_SERVER");
  client_options_.target = env_server != nullptr && *env_server != '\0' ? env_server : "127.0.0.1:50051";
  client_options_.connect_timeout_seconds = 5.0;
}

void CliContext::AddGlobalOptions(CLI::App& app) {
  app.add_option("--server", client_options_.target, "Server address HOST:PORT (env INSPECT_SERVER)")
      ->capture_default_str();
  app.add_option("--tls-ca", client_options_.tls_ca_file,
                 "PEM file of the CA that signed the server's certificate (enables TLS)")
      ->envname("INSPECT_TLS_CA");
  app.add_option("--token-file", token_file_, "File holding a bearer token sent with every call")
      ->envname("INSPECT_TOKEN_FILE");
  app.add_option("--connect-timeout", client_options_.connect_timeout_seconds, "Seconds to wait for the server")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_flag("--json", out_.json, "Machine-readable output: JSON Lines while following, then one result object");
  app.add_flag("-q,--quiet", out_.quiet, "No progress output");
}

void CliContext::AddCommand(const CLI::App* command, CommandHandler handler) {
  commands_.emplace_back(command, std::move(handler));
}

int CliContext::Run() {
  out_.tty = !out_.json && isatty(STDOUT_FILENO) == 1;
  if (!token_file_.empty()) {
    if (std::string err = ReadToken(token_file_, &client_options_.auth_token); !err.empty()) {
      PrintErrorLine(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, err));
      return kExitUsage;
    }
  }
  InspectionClient client(client_options_);
  if (grpc::Status s = client.WaitConnected(); !s.ok()) {
    // Anything but an unreachable server is a bad option (e.g. an unreadable CA file).
    PrintErrorLine(s);
    return s.error_code() == grpc::StatusCode::UNAVAILABLE ? kExitUnreachable : kExitUsage;
  }
  ProgressPrinter printer(out_);
  Session session{client, out_, printer};
  for (const auto& [command, handler] : commands_) {
    if (command->parsed()) return handler(session);
  }
  return kExitUsage;
}

}  // namespace inspection::client::cli
