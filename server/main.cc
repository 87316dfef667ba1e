// inspectd: the inspection service beside one microscope rig. Runs the simulated rig unless a
// rig configuration names real devices.
#include <csignal>
#include <fstream>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "devices/rig_config.h"
#include "server/inspection_server.h"

using namespace inspection;

namespace {

bool ParseSize(const std::string& s, cv::Size* out) {
  int w = 0, h = 0;
  if (std::sscanf(s.c_str(), "%dx%d", &w, &h) != 2 || w < 16 || h < 16) return false;
  *out = {w, h};
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"inspectd: shape-from-focus inspection service for one microscope rig"};
  ServerOptions opt;
  std::string data_dir = opt.data_dir.string();
  std::string camera_size = "1024x768";
  std::string log_level = "info";
  std::string token_file;
  bool no_reflection = false;
  std::string rig_config;
  bool degraded = false;
  app.add_option("--listen", opt.listen_address, "host:port to listen on (port 0 = any free port)")->capture_default_str();
  app.add_option("--data-dir", data_dir, "where scans, artifacts, calibrations and the job database live")->capture_default_str();
  app.add_option("--queue-capacity", opt.rig_queue_capacity, "rig jobs that may wait behind the running one")->capture_default_str();
  app.add_flag("--no-reflection", no_reflection, "disable gRPC server reflection");
  app.add_option("--tls-cert", opt.tls_cert_file, "PEM certificate chain; enables TLS with --tls-key");
  app.add_option("--tls-key", opt.tls_key_file, "PEM private key");
  app.add_option("--auth-token-file", token_file, "file holding a bearer token that every call must present");
  app.add_option("--rig-config", rig_config, "rig configuration file (JSON, devices/README.md); default: the simulated rig");
  app.add_flag("--degraded", degraded, "start even when configured devices are absent (health NOT_SERVING until ResetRig)");
  app.add_option("--specimen", opt.simulation.specimen, "simulated rig: specimen name or file:/path/scene.json")->capture_default_str();
  app.add_option("--seed", opt.simulation.seed, "simulated rig: random seed")->capture_default_str();
  app.add_option("--camera-size", camera_size, "simulated rig: camera WIDTHxHEIGHT")->capture_default_str();
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error")->capture_default_str();
  app.set_version_flag("--version", INSPECT_VERSION);
  CLI11_PARSE(app, argc, argv);

  spdlog::set_level(spdlog::level::from_str(log_level));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%e%z %l inspectd: %v");
  opt.data_dir = data_dir;
  opt.reflection = !no_reflection;
  if (!ParseSize(camera_size, &opt.simulation.camera_size)) {
    std::cerr << "inspectd: --camera-size '" << camera_size << "' must be WIDTHxHEIGHT, e.g. 1024x768\n";
    return 2;
  }
  if (!token_file.empty()) {
    std::ifstream in(token_file);
    if (!std::getline(in, opt.auth_token) || opt.auth_token.empty()) {
      std::cerr << "inspectd: --auth-token-file '" << token_file << "' is unreadable or empty\n";
      return 2;
    }
  }

  // Block termination signals in every thread; one thread waits for them and shuts down.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  std::unique_ptr<Rig> rig;
  Status rig_startup;
  if (!rig_config.empty()) {
    auto config = LoadRigConfig(rig_config);
    if (!config.ok()) {
      std::cerr << "inspectd: " << config.status().message() << "\n";
      return 2;
    }
    RigStartOptions start;
    start.allow_degraded = degraded;
    auto created = CreateRig(*config, start);
    if (!created.ok()) {
      std::cerr << "inspectd: cannot start the rig: " << created.status().message() << "\n";
      return 1;
    }
    rig = std::move(*created);
    rig_startup = rig->CheckDevices();
    if (!rig_startup.ok()) spdlog::warn("rig started degraded: {}", rig_startup.message());
  }
  auto server = InspectionServer::Start(opt, std::move(rig), rig_startup);
  if (!server.ok()) {
    std::cerr << "inspectd: " << server.status().ToString() << "\n";
    return 1;
  }
  std::cout << "inspectd listening on " << (*server)->address() << std::endl;
  std::thread waiter([&] {
    int sig = 0;
    sigwait(&signals, &sig);
    spdlog::info("signal {}: shutting down", sig);
    (*server)->Shutdown();
  });
  (*server)->Wait();
  waiter.join();
  return 0;
}
