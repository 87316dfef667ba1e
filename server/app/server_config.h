// inspectd's configuration: every command-line setting, read from a JSON file, INSPECTD_*
// environment variables and flags, with flags > environment > file > built-in defaults.
// One table (InspectdConfigKeys) names each setting once; the flag, the environment variable and
// the file key are derived from it, so adding a setting is one line here and one in the table.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

#include "core/util/status.h"
#include "server/app/inspection_server.h"

namespace inspection {

// The effective settings of one inspectd process. Defaults are ServerOptions' defaults.
struct InspectdConfig {
  std::string listen = ServerOptions{}.listen_address;
  std::string data_dir = ServerOptions{}.data_dir.string();
  std::string database;                // "" = SQLite in data_dir; postgresql://... for a pool or a site
  std::string database_password_file;  // PostgreSQL password (first line); never logged
  std::string rig_id;                       // this rig's name on the site's feed; empty = the host name
  std::string site_database;                // postgresql://... : forward results to the site; empty = off
  std::string site_database_password_file;  // its password (first line); never logged
  int queue_capacity = ServerOptions{}.rig_queue_capacity;
  bool reflection = true;  // as a default: on unless authentication is configured (main.cc)
  std::string tls_cert;
  std::string tls_key;
  std::string tls_client_ca;  // PEM CA bundle: client certificates become mandatory (mTLS)
  bool insecure = false;      // plaintext beyond loopback
  std::string auth_token_file;
  std::string token_file;  // named tokens: "identity token" per line
  std::string policy;      // JSON policy file: identities -> roles
  std::string rig_config;  // empty = the simulated rig
  bool degraded = false;
  std::string specimen = SimulatedRigOptions{}.specimen;
  uint64_t seed = SimulatedRigOptions{}.seed;
  std::string camera_size = "1024x768";  // simulated rig: WIDTHxHEIGHT
  std::string log_level = "info";
  std::string log_format = "text";   // text or json (one object per line)
  bool no_rig = false;               // reconstruct only: no rig is opened
  std::string http_listen;           // host:port for /metrics and the dashboard; empty = none
  std::string scene_dir;             // simulated rig: user scenes by name; empty = built-ins only
  std::string audit_log;             // JSON Lines audit trail; empty = <data_dir>/audit/audit.jsonl
  int min_free_mb = 0;               // free-space reserve for new scans and uploads; 0 = none
  uint64_t retention_max_age_s = 0;  // finished jobs older than this are deleted; 0 = no limit
  uint64_t retention_max_mb = 0;     // finished jobs' data above this is deleted, oldest first; 0 = none
  int retention_keep_last = 0;       // the newest N finished jobs are always kept
  int retention_interval_s = ServerOptions{}.retention_interval_s;
  int verification_interval_days = ServerOptions{}.verification_interval_days;  // 1..3650
  // Reconstruction pipeline: decode threads, the decoded frames kept per
  // reconstruction (MiB), artifact files written at once; 0 threads = all hardware threads.
  int decode_threads = ServerOptions{}.reconstruct.decode_threads;
  int decode_budget_mb = int(ServerOptions{}.reconstruct.max_decoded_bytes >> 20);
  int artifact_threads = ServerOptions{}.reconstruct.artifact_threads;
  // MQTT publishing of results and rig states (server/plant/mqtt_publisher.h); no host = off.
  std::string mqtt_host;
  int mqtt_port = MqttOptions{}.port;
  std::string mqtt_site = MqttOptions{}.site;
  std::string mqtt_rig = MqttOptions{}.rig;
  std::string mqtt_topic_prefix = MqttOptions{}.topic_prefix;
  std::string mqtt_client_id;
  std::string mqtt_username;
  std::string mqtt_password_file;  // the password itself never appears in the configuration
  std::string mqtt_tls_ca;
  std::string mqtt_tls_cert;
  std::string mqtt_tls_key;
  // Reconstruct pool (a shared PostgreSQL database; server/jobs/job_manager.h pool mode).
  int pool_lease_s = 30;         // a replica silent this long is taken for dead; its job runs again
  int pool_workers = 1;          // reconstructions this replica runs at once
  int pool_poll_ms = 250;        // idle replicas look for work, watchers for events, this often
  int drain_timeout_s = 60;      // SIGTERM: running jobs may finish this long, then are handed back
  int engine_threads = 0;        // SFF engine threads per reconstruction; 0 = all hardware threads

  bool operator==(const InspectdConfig&) const = default;
};

// One setting. `name` is the file key (snake_case); the flag is --name with '-' for '_'
// (a boolean also gets --no-name), the environment variable INSPECTD_NAME in upper case.
struct ConfigKey {
  using Field = std::variant<std::string InspectdConfig::*, int InspectdConfig::*, uint64_t InspectdConfig::*,
                             bool InspectdConfig::*>;
  std::string_view name;
  Field field;
  std::string_view help;

  std::string FlagName() const;         // "--data-dir"
  std::string EnvironmentName() const;  // "INSPECTD_DATA_DIR"
  bool is_bool() const { return std::holds_alternative<bool InspectdConfig::*>(field); }
};

// Every setting, in the order --print-config prints them.
const std::vector<ConfigKey>& InspectdConfigKeys();
const ConfigKey* FindConfigKey(std::string_view name);

// The file named by --config, else by this variable.
inline constexpr const char* kConfigFileEnvironment = "INSPECTD_CONFIG";
// The config file's block for the OPC UA gateway (gateway/opcua): an object inspectd does not read.
inline constexpr const char* kOpcuaGatewayBlock = "opcua";

// Where each effective value came from: "default", the file path, "INSPECTD_X" or "--x".
using ConfigSources = std::map<std::string, std::string, std::less<>>;

// Sets one setting from text as written on a command line or in the environment: integers in
// full ("4", not "4x"), booleans true/false/1/0/yes/no/on/off. `origin` names the flag or the
// variable in the error.
Status SetConfigFromText(const ConfigKey& key, std::string_view text, std::string_view origin, InspectdConfig* config);

// Applies a JSON object of settings. Unknown keys and values of the wrong JSON type are errors
// naming the key; `origin` (the file path) prefixes every message.
Status ApplyConfigJson(std::string_view json_text, std::string_view origin, InspectdConfig* config,
                       ConfigSources* sources = nullptr);
Status ApplyConfigFile(const std::string& path, InspectdConfig* config, ConfigSources* sources = nullptr);

// Applies the INSPECTD_* variables among `environment` (NAME, VALUE pairs; others are skipped).
// INSPECTD_CONFIG is the file's path, not a setting. A variable that names no setting is not an
// error (orchestrators add their own, e.g. Kubernetes service links INSPECTD_PORT); it is listed
// in `unknown` so the caller can warn about typos.
Status ApplyConfigEnvironment(const std::vector<std::pair<std::string, std::string>>& environment,
                              InspectdConfig* config, ConfigSources* sources = nullptr,
                              std::vector<std::string>* unknown = nullptr);

// The layers of one start, lowest first after the defaults.
struct ConfigLayers {
  std::string config_flag;  // --config (empty: not given)
  std::vector<std::pair<std::string, std::string>> environment;
  std::vector<std::pair<std::string, std::string>> flags;  // setting name -> text, as given
};
struct ResolvedConfig {
  InspectdConfig config;
  std::string config_file;  // the file that was read, empty if none
  ConfigSources sources;
  std::vector<std::string> unknown_environment;
};
// defaults < file (--config, else INSPECTD_CONFIG) < environment < flags, then ValidateConfig.
StatusOr<ResolvedConfig> ResolveInspectdConfig(const ConfigLayers& layers);

// Checks values no type can express: camera_size, log_level, log_format, listen, http_listen,
// TLS cert and key together, no_rig without rig_config.
Status ValidateConfig(const InspectdConfig& config);

// The configuration as a JSON object, every key in table order; ApplyConfigJson reads it back.
std::string ConfigToJson(const InspectdConfig& config);

// ServerOptions for InspectionServer::Start. Reads the token file (first line; missing, unreadable
// or empty is an error naming auth_token_file).
StatusOr<ServerOptions> ToServerOptions(const InspectdConfig& config);

// Environment of this process as (NAME, VALUE) pairs, for ConfigLayers.
std::vector<std::pair<std::string, std::string>> ProcessEnvironment();

}  // namespace inspection
