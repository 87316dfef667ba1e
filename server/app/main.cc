// inspectd: the inspection service beside one microscope rig. Runs the simulated rig unless a
// rig configuration names real devices.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <csignal>
#include <iostream>
#include <map>
#include <thread>
#include <type_traits>
#include <variant>

#include "devices/rig_config.h"
#include "server/app/inspection_server.h"
#include "server/logging/log_format.h"
#include "server/app/server_config.h"
#include "server/storage/data_store.h"

using namespace inspection;

namespace {

// The value a setting has before any file, variable or flag, for --help.
std::string DefaultText(const ConfigKey& key) {
  static const InspectdConfig defaults;
  return std::visit(
      [](auto InspectdConfig::*f) -> std::string {
        const auto& value = defaults.*f;
        using T = std::decay_t<decltype(value)>;
        if constexpr (std::is_same_v<T, std::string>)
          return value;
        else if constexpr (std::is_same_v<T, bool>)
          return value ? "on" : "off";
        else
          return std::to_string(value);
      },
      key.field);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "inspectd: shape-from-focus inspection service for one microscope rig.\n"
      "Every setting is also a key of the --config file and an INSPECTD_* environment variable;\n"
      "flags > environment > file > defaults. --print-config shows the result."};
  std::string config_path;
  bool print_config = false;
  app.add_option("--config", config_path, "JSON configuration file (env INSPECTD_CONFIG)");
  app.add_flag("--print-config", print_config, "print the effective configuration as JSON and exit");
  // Flags from the settings table; std::map keeps the bound strings in place while it grows.
  std::map<std::string, std::string> flag_text;
  std::map<std::string, bool> flag_bool;
  std::vector<std::pair<const ConfigKey*, CLI::Option*>> flag_options;
  for (const auto& key : InspectdConfigKeys()) {
    const std::string name(key.name);
    const std::string help = std::string(key.help) + " (key " + name + ", env " + key.EnvironmentName() + ")";
    CLI::Option* option = nullptr;
    if (key.is_bool()) {
      // A setting named no_x is its own negation: --no-x, without a --no-no-x.
      const bool negative = key.name.substr(0, 3) == "no_";
      const std::string flags = negative ? key.FlagName() : key.FlagName() + ",!--no-" + key.FlagName().substr(2);
      option = app.add_flag(flags, flag_bool[name], help + " [default: " + DefaultText(key) + "]");
    } else {
      const char* type = std::holds_alternative<std::string InspectdConfig::*>(key.field) ? "TEXT" : "INT";
      option = app.add_option(key.FlagName(), flag_text[name], help)->type_name(type)->default_str(DefaultText(key));
    }
    flag_options.emplace_back(&key, option);
  }
  app.set_version_flag("--version", INSPECT_VERSION);
  CLI11_PARSE(app, argc, argv);

  ConfigLayers layers;
  layers.config_flag = config_path;
  layers.environment = ProcessEnvironment();
  for (const auto& [key, option] : flag_options) {
    if (option->count() == 0) continue;
    const std::string name(key->name);
    layers.flags.emplace_back(name, key->is_bool() ? (flag_bool[name] ? "true" : "false") : flag_text[name]);
  }
  auto resolved = ResolveInspectdConfig(layers);
  if (!resolved.ok()) {
    std::cerr << "inspectd: " << resolved.status().message() << "\n";
    return 2;
  }
  const InspectdConfig& config = resolved->config;
  if (print_config) {
    std::cout << ConfigToJson(config);
    return 0;
  }

  ConfigureLogging(config.log_format, config.log_level);
  for (const auto& name : resolved->unknown_environment) {
    spdlog::warn("environment variable {} names no setting; ignored", name);
  }
  for (const auto& [name, source] : resolved->sources) spdlog::debug("setting {} from {}", name, source);
  auto options = ToServerOptions(config);
  if (!options.ok()) {
    std::cerr << "inspectd: " << options.status().message() << "\n";
    return 2;
  }
  ServerOptions opt = std::move(*options);
  // Reflection not set anywhere: on without authentication, off with it (InspectionServer).
  if (resolved->sources.at("reflection") == "default") opt.reflection.reset();

  // Block termination signals in every thread; one thread waits for them and shuts down.
  // SIGHUP re-reads the access policy and token files (certificates reload by themselves).
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  std::unique_ptr<Rig> rig;
  Status rig_startup;
  if (!config.rig_config.empty() && !config.no_rig) {
    auto rig_config = LoadRigConfig(config.rig_config);
    if (!rig_config.ok()) {
      std::cerr << "inspectd: " << rig_config.status().message() << "\n";
      return 2;
    }
    RigStartOptions start;
    start.allow_degraded = config.degraded;
    auto created = CreateRig(*rig_config, start);
    if (!created.ok()) {
      std::cerr << "inspectd: cannot start the rig: " << created.status().message() << "\n";
      return 1;
    }
    rig = std::move(*created);
    rig_startup = rig->CheckDevices();
    if (!rig_startup.ok()) spdlog::warn("rig started degraded: {}", rig_startup.message());
  }
  // A database server that is not up yet (a pool starting beside its PostgreSQL, a site store
  // restarting) is waited for with backoff, not a crash loop; SIGTERM / SIGINT end the wait.
  // Meanwhile the gRPC port answers health checks with NOT_SERVING (up, not ready).
  std::unique_ptr<grpc::Server> waiting_health;
  for (int wait_s = 1;; wait_s = std::min(2 * wait_s, 30)) {
    auto probe = DataStore::Open(opt.data_dir, opt.database);
    if (probe.ok() || probe.status().code() != StatusCode::kUnavailable) break;  // Start reports other errors
    spdlog::warn("{}; retrying in {} s", probe.status().message(), wait_s);
    if (!waiting_health) {
      std::string address;
      auto health = InspectionServer::StartWaitingHealth(opt, &address);
      if (!health.ok()) {
        std::cerr << "inspectd: " << health.status().ToString() << "\n";
        return 1;
      }
      waiting_health = std::move(*health);
      PrintAnnouncement(config.log_format,
                        "inspectd health on " + address + ": NOT_SERVING until the database is reachable");
    }
    const timespec timeout{wait_s, 0};
    siginfo_t info;
    const int sig = sigtimedwait(&signals, &info, &timeout);
    if (sig == SIGTERM || sig == SIGINT) return 0;
  }
  if (waiting_health) waiting_health->Shutdown();  // frees the address for the real server
  waiting_health.reset();
  auto server = InspectionServer::Start(opt, std::move(rig), rig_startup);
  if (!server.ok()) {
    std::cerr << "inspectd: " << server.status().ToString() << "\n";
    return 1;
  }
  PrintAnnouncement(config.log_format, "inspectd listening on " + (*server)->address());
  if ((*server)->http_port() != 0) {
    const char* scheme = config.tls_cert.empty() ? "http" : "https";
    PrintAnnouncement(config.log_format,
                      std::string("inspectd http on ") + scheme + "://" + (*server)->http_address() + "/");
  }
  std::thread waiter([&] {
    for (;;) {
      int sig = 0;
      sigwait(&signals, &sig);
      if (sig == SIGHUP) {
        Status s = (*server)->ReloadAccessPolicy();
        if (s.ok()) {
          spdlog::info("SIGHUP: access policy and tokens reloaded");
        } else {
          spdlog::error("SIGHUP: access policy not reloaded, the previous one stays: {}", s.message());
        }
        continue;
      }
      spdlog::info("signal {}: shutting down", sig);
      // A pool replica finishes or hands back its reconstructions first (bounded by drain_timeout_s).
      if (sig == SIGTERM) (*server)->Drain();
      (*server)->Shutdown();
      return;
    }
  });
  (*server)->Wait();
  waiter.join();
  return 0;
}
