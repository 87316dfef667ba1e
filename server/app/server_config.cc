// inspectd's configuration layers (server_config.h): JSON file, INSPECTD_* environment, flags.
#include "server/app/server_config.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstdio>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>

#include "server/storage/data_store.h"
#include "server/http/http_endpoint.h"
#include "server/logging/log_format.h"

extern char** environ;

namespace inspection {

namespace {

using Json = nlohmann::ordered_json;

template <class... Fs>
struct Overloaded : Fs... {
  using Fs::operator()...;
};
template <class... Fs>
Overloaded(Fs...) -> Overloaded<Fs...>;

std::string Quoted(std::string_view s) { return "'" + std::string(s) + "'"; }

// Levenshtein distance, for "did you mean" on a misspelt key.
size_t EditDistance(std::string_view a, std::string_view b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diagonal = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

std::string Suggestion(std::string_view name) {
  const ConfigKey* best = nullptr;
  size_t best_distance = 3;  // more than two edits away is another word, not a typo
  for (const auto& key : InspectdConfigKeys()) {
    size_t d = EditDistance(name, key.name);
    if (d < best_distance) best_distance = d, best = &key;
  }
  return best ? " (did you mean " + Quoted(best->name) + "?)" : "";
}

std::string UnknownKeyMessage(std::string_view name) {
  std::string known;
  for (const auto& key : InspectdConfigKeys()) known += (known.empty() ? "" : ", ") + std::string(key.name);
  return "unknown key " + Quoted(name) + Suggestion(name) + "; known keys: " + known;
}

template <class T>
bool ParseInteger(std::string_view text, T* out) {
  const char* end = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(text.data(), end, *out);
  return ec == std::errc() && ptr == end && !text.empty();
}

bool ParseBool(std::string_view text, bool* out) {
  std::string t(text);
  std::transform(t.begin(), t.end(), t.begin(), [](unsigned char c) { return std::tolower(c); });
  if (t == "true" || t == "1" || t == "yes" || t == "on") return *out = true, true;
  if (t == "false" || t == "0" || t == "no" || t == "off") return *out = false, true;
  return false;
}

bool ParseCameraSize(const std::string& s, cv::Size* out) {
  int w = 0, h = 0;
  char tail = 0;
  if (std::sscanf(s.c_str(), "%dx%d%c", &w, &h, &tail) != 2 || w < 16 || h < 16) return false;
  *out = {w, h};
  return true;
}

std::string JsonTypeName(const Json& v) {
  if (v.is_number_integer()) return "integer";
  if (v.is_number_float()) return "number";
  return v.type_name();
}

// One JSON value into one setting; strict JSON types (a quoted "4" is not an integer).
Status SetFromJson(const ConfigKey& key, const Json& v, InspectdConfig* config) {
  auto wrong = [&](const char* expected) {
    return Status::InvalidArgument("key " + Quoted(key.name) + " must be " + expected + ", got " + JsonTypeName(v) +
                                   " " + v.dump());
  };
  return std::visit(Overloaded{
                        [&](std::string InspectdConfig::*f) -> Status {
                          if (!v.is_string()) return wrong("a string");
                          config->*f = v.get<std::string>();
                          return Status::Ok();
                        },
                        [&](int InspectdConfig::*f) -> Status {
                          if (!v.is_number_integer()) return wrong("an integer");
                          if (v.is_number_unsigned() ? v.get<uint64_t>() > uint64_t(std::numeric_limits<int>::max())
                                                     : (v.get<int64_t>() < std::numeric_limits<int>::min() ||
                                                        v.get<int64_t>() > std::numeric_limits<int>::max())) {
                            return wrong("an integer in int range");
                          }
                          config->*f = int(v.get<int64_t>());
                          return Status::Ok();
                        },
                        [&](uint64_t InspectdConfig::*f) -> Status {
                          if (!v.is_number_unsigned()) return wrong("an integer >= 0");
                          config->*f = v.get<uint64_t>();
                          return Status::Ok();
                        },
                        [&](bool InspectdConfig::*f) -> Status {
                          if (!v.is_boolean()) return wrong("true or false");
                          config->*f = v.get<bool>();
                          return Status::Ok();
                        },
                    },
                    key.field);
}

}  // namespace

std::string ConfigKey::FlagName() const {
  std::string flag = "--" + std::string(name);
  std::replace(flag.begin(), flag.end(), '_', '-');
  return flag;
}

std::string ConfigKey::EnvironmentName() const {
  std::string env = "INSPECTD_" + std::string(name);
  std::transform(env.begin(), env.end(), env.begin(), [](unsigned char c) { return std::toupper(c); });
  return env;
}

const std::vector<ConfigKey>& InspectdConfigKeys() {
  using C = InspectdConfig;
  static const std::vector<ConfigKey> keys = {
      {"listen", &C::listen, "host:port to listen on (port 0 = any free port)"},
      {"data_dir", &C::data_dir, "where scans, artifacts, calibrations and the job database live"},
      {"database", &C::database,
       "where the job database lives: empty or 'sqlite' = <data_dir>/inspection.db; postgresql://user@host:port/db "
       "= a PostgreSQL server shared by a pool or a site (no password in it: use database_password_file)"},
      {"database_password_file", &C::database_password_file,
       "file whose first line is the PostgreSQL password (never logged)"},
      {"rig_id", &C::rig_id, "this rig's name on the site's result feed; empty: the host name"},
      {"site_database", &C::site_database,
       "postgresql://... of the site's store: every inspection result is forwarded there (store-and-forward, in "
       "order, once), so one feed covers every rig; empty: off"},
      {"site_database_password_file", &C::site_database_password_file,
       "file whose first line is the site database's password (never logged)"},
      {"queue_capacity", &C::queue_capacity, "rig jobs that may wait behind the running one"},
      {"reflection", &C::reflection,
       "gRPC server reflection (by default off when authentication is configured, else on)"},
      {"tls_cert", &C::tls_cert, "PEM certificate chain; enables TLS with tls_key (reloaded when the file changes)"},
      {"tls_key", &C::tls_key, "PEM private key"},
      {"tls_client_ca", &C::tls_client_ca,
       "PEM CA bundle: client certificates become mandatory (mTLS); the identity is the certificate's CN or a SAN"},
      {"insecure", &C::insecure, "allow plaintext (no TLS) on a non-loopback listen address"},
      {"auth_token_file", &C::auth_token_file, "file holding a bearer token that every call must present"},
      {"token_file", &C::token_file, "named bearer tokens, one 'identity token' line per identity"},
      {"policy", &C::policy, "JSON access policy: identities -> roles (viewer, operator, engineer, admin)"},
      {"rig_config", &C::rig_config, "rig configuration file (JSON, docs/devices.md); empty: the simulated rig"},
      {"degraded", &C::degraded, "start even when configured devices are absent (health NOT_SERVING until ResetRig)"},
      {"specimen", &C::specimen, "simulated rig: specimen name or file:/path/scene.json"},
      {"seed", &C::seed, "simulated rig: random seed"},
      {"camera_size", &C::camera_size, "simulated rig: camera WIDTHxHEIGHT"},
      {"log_level", &C::log_level, "trace, debug, info, warn, error, critical or off"},
      {"log_format", &C::log_format, "text, or json for one JSON object per line (time, level, message, job_id)"},
      {"no_rig", &C::no_rig,
       "reconstruct only: open no rig; Scan, Calibrate, GetRigStatus, ResetRig and specimens answer "
       "FAILED_PRECONDITION"},
      {"http_listen", &C::http_listen,
       "host:port for Prometheus /metrics and the web dashboard (port 0 = any); empty: off"},
      {"scene_dir", &C::scene_dir,
       "simulated rig: folder of user scenes (<name>.json) that SetSpecimen accepts by name; empty: built-ins only"},
      {"audit_log", &C::audit_log,
       "audit trail (JSON Lines, rotated at 16 MiB, 8 kept) of every mutating or denied call; empty: "
       "<data_dir>/audit/audit.jsonl"},
      {"min_free_mb", &C::min_free_mb,
       "free-space reserve of the data disk (MiB): below it new scans and uploads are refused with RESOURCE_EXHAUSTED; "
       "0: none"},
      {"retention_max_age_s", &C::retention_max_age_s,
       "retention: finished jobs older than this (seconds) are deleted, oldest first; 0: no age limit"},
      {"retention_max_mb", &C::retention_max_mb,
       "retention: finished jobs' data (artifacts and stored stacks) is kept below this many MiB; 0: no limit"},
      {"retention_keep_last", &C::retention_keep_last,
       "retention: the newest N finished jobs are kept whatever the limits (pinned jobs always are)"},
      {"retention_interval_s", &C::retention_interval_s, "retention: seconds between sweeps"},
      {"verification_interval_days", &C::verification_interval_days,
       "days a full instrument verification stays valid; the rig is 'verification due' after them"},
      {"decode_threads", &C::decode_threads,
       "reconstruct: threads decoding a stack's frames as they arrive; 0: all hardware threads"},
      {"decode_budget_mb", &C::decode_budget_mb,
       "reconstruct: decoded frames kept per reconstruction (MiB); frames beyond it are decoded again when the "
       "engine needs them (bounds memory)"},
      {"artifact_threads", &C::artifact_threads,
       "reconstruct: artifact files written at once; 0: all hardware threads"},
      {"mqtt_host", &C::mqtt_host,
       "MQTT broker host: every inspection result and rig state change is published (QoS 1); empty: off"},
      {"mqtt_port", &C::mqtt_port, "MQTT broker port (1883 plain, 8883 usual for TLS)"},
      {"mqtt_site", &C::mqtt_site, "MQTT topic level for the site: <mqtt_topic_prefix>/<site>/<rig>/{results,state}"},
      {"mqtt_rig", &C::mqtt_rig, "MQTT topic level for this rig"},
      {"mqtt_topic_prefix", &C::mqtt_topic_prefix, "first MQTT topic level"},
      {"mqtt_client_id", &C::mqtt_client_id,
       "MQTT client id of the persistent session; empty: inspectd-<site>-<rig>"},
      {"mqtt_username", &C::mqtt_username, "MQTT user name; empty: anonymous"},
      {"mqtt_password_file", &C::mqtt_password_file, "file whose first line is the MQTT password"},
      {"mqtt_tls_ca", &C::mqtt_tls_ca, "PEM CA of the MQTT broker: enables TLS"},
      {"mqtt_tls_cert", &C::mqtt_tls_cert, "PEM client certificate for the MQTT broker (with mqtt_tls_key)"},
      {"mqtt_tls_key", &C::mqtt_tls_key, "PEM private key of mqtt_tls_cert"},
      // Reconstruct pool (database: postgresql://...).
      {"pool_lease_s", &C::pool_lease_s,
       "pool: seconds a replica's lease on a job lasts unrenewed; a replica silent this long (killed) is taken "
       "for dead and another reruns the job"},
      {"pool_workers", &C::pool_workers, "pool: reconstructions this replica runs at once"},
      {"pool_poll_ms", &C::pool_poll_ms, "pool: how often idle replicas look for work and watchers for events (ms)"},
      {"drain_timeout_s", &C::drain_timeout_s,
       "pool: on SIGTERM, seconds the running reconstructions may take to finish before they are handed back"},
      {"engine_threads", &C::engine_threads,
       "reconstruct: SFF engine threads per reconstruction (set each replica's share of a shared host); 0: all "
       "hardware threads"},
  };
  return keys;
}

const ConfigKey* FindConfigKey(std::string_view name) {
  for (const auto& key : InspectdConfigKeys()) {
    if (key.name == name) return &key;
  }
  return nullptr;
}

Status SetConfigFromText(const ConfigKey& key, std::string_view text, std::string_view origin, InspectdConfig* config) {
  auto bad = [&](const char* expected) {
    return Status::InvalidArgument(std::string(origin) + " " + Quoted(text) + " must be " + expected);
  };
  return std::visit(Overloaded{
                        [&](std::string InspectdConfig::*f) -> Status {
                          config->*f = std::string(text);
                          return Status::Ok();
                        },
                        [&](int InspectdConfig::*f) -> Status {
                          return ParseInteger(text, &(config->*f)) ? Status::Ok() : bad("an integer");
                        },
                        [&](uint64_t InspectdConfig::*f) -> Status {
                          return ParseInteger(text, &(config->*f)) ? Status::Ok() : bad("an integer >= 0");
                        },
                        [&](bool InspectdConfig::*f) -> Status {
                          return ParseBool(text, &(config->*f)) ? Status::Ok() : bad("true or false");
                        },
                    },
                    key.field);
}

Status ApplyConfigJson(std::string_view json_text, std::string_view origin, InspectdConfig* config,
                       ConfigSources* sources) {
  const std::string prefix = std::string(origin) + ": ";
  // A duplicate key is not an error; the last one wins, as in most JSON readers.
  Json doc;
  try {
    doc = Json::parse(json_text);
  } catch (const Json::exception& e) {  // the message carries line and column
    return Status::InvalidArgument(prefix + "not valid JSON: " + e.what());
  }
  if (!doc.is_object()) return Status::InvalidArgument(prefix + "must be a JSON object of settings");
  // Check every key before changing anything: a bad file leaves the configuration as it was.
  InspectdConfig updated = *config;
  for (const auto& [name, value] : doc.items()) {
    // The OPC UA gateway (gateway/opcua) reads its settings from the same file: inspectd checks
    // only that its block is an object and leaves its keys to the gateway.
    if (name == kOpcuaGatewayBlock) {
      if (!value.is_object()) {
        return Status::InvalidArgument(prefix + Quoted(name) + " must be a JSON object (the OPC UA gateway's settings)");
      }
      continue;
    }
    const ConfigKey* key = FindConfigKey(name);
    if (!key) return Status::InvalidArgument(prefix + UnknownKeyMessage(name));
    INSPECT_RETURN_IF_ERROR(SetFromJson(*key, value, &updated).WithContext(std::string(origin)));
  }
  *config = updated;
  if (sources) {
    for (const auto& item : doc.items()) {
      if (item.key() != kOpcuaGatewayBlock) (*sources)[item.key()] = std::string(origin);
    }
  }
  return Status::Ok();
}

Status ApplyConfigFile(const std::string& path, InspectdConfig* config, ConfigSources* sources) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidArgument("config file " + Quoted(path) + " cannot be read");
  std::stringstream text;
  text << in.rdbuf();
  if (in.bad()) return Status::InvalidArgument("config file " + Quoted(path) + " cannot be read");
  return ApplyConfigJson(text.str(), path, config, sources);
}

Status ApplyConfigEnvironment(const std::vector<std::pair<std::string, std::string>>& environment,
                              InspectdConfig* config, ConfigSources* sources, std::vector<std::string>* unknown) {
  const std::string prefix = "INSPECTD_";
  InspectdConfig updated = *config;
  ConfigSources found;
  std::vector<std::string> unknown_names;
  for (const auto& [name, value] : environment) {
    if (name.compare(0, prefix.size(), prefix) != 0 || name == kConfigFileEnvironment) continue;
    const ConfigKey* key = nullptr;
    for (const auto& k : InspectdConfigKeys()) {
      if (k.EnvironmentName() == name) key = &k;
    }
    if (!key) {
      unknown_names.push_back(name);
      continue;
    }
    INSPECT_RETURN_IF_ERROR(SetConfigFromText(*key, value, "environment variable " + name, &updated));
    found[std::string(key->name)] = name;
  }
  *config = updated;
  if (sources) {
    for (auto& [k, v] : found) (*sources)[k] = v;
  }
  if (unknown) *unknown = std::move(unknown_names);
  return Status::Ok();
}

StatusOr<ResolvedConfig> ResolveInspectdConfig(const ConfigLayers& layers) {
  ResolvedConfig r;
  for (const auto& key : InspectdConfigKeys()) r.sources[std::string(key.name)] = "default";
  r.config_file = layers.config_flag;
  if (r.config_file.empty()) {
    for (const auto& [name, value] : layers.environment) {
      if (name == kConfigFileEnvironment) r.config_file = value;
    }
  }
  if (!r.config_file.empty()) INSPECT_RETURN_IF_ERROR(ApplyConfigFile(r.config_file, &r.config, &r.sources));
  INSPECT_RETURN_IF_ERROR(ApplyConfigEnvironment(layers.environment, &r.config, &r.sources, &r.unknown_environment));
  for (const auto& [name, text] : layers.flags) {
    const ConfigKey* key = FindConfigKey(name);
    if (!key) return Status::InvalidArgument(UnknownKeyMessage(name));
    INSPECT_RETURN_IF_ERROR(SetConfigFromText(*key, text, key->FlagName(), &r.config));
    r.sources[std::string(key->name)] = key->FlagName();
  }
  INSPECT_RETURN_IF_ERROR(ValidateConfig(r.config));
  return r;
}

Status ValidateConfig(const InspectdConfig& c) {
  auto bad = [](std::string_view key, const std::string& value, const std::string& why) {
    return Status::InvalidArgument(std::string(key) + " " + Quoted(value) + " " + why);
  };
  if (c.listen.empty()) return Status::InvalidArgument("listen must not be empty (host:port)");
  if (c.data_dir.empty()) return Status::InvalidArgument("data_dir must not be empty");
  INSPECT_RETURN_IF_ERROR(ValidateDatabaseOptions({c.database, c.database_password_file}));
  if (!c.site_database.empty()) {
    ResultForwardingOptions f;
    f.rig_id = c.rig_id.empty() ? "host" : c.rig_id;  // the host name is filled in by ToServerOptions
    f.site = {c.site_database, c.site_database_password_file};
    INSPECT_RETURN_IF_ERROR(ValidateResultForwardingOptions(f));
  } else if (!c.site_database_password_file.empty()) {
    return Status::InvalidArgument("site_database_password_file: set, but site_database is not");
  }
  if (c.queue_capacity < 0) return bad("queue_capacity", std::to_string(c.queue_capacity), "must be >= 0");
  cv::Size size;
  if (!ParseCameraSize(c.camera_size, &size)) {
    return bad("camera_size", c.camera_size, "must be WIDTHxHEIGHT, each >= 16, e.g. 1024x768");
  }
  static const char* kLevels[] = {"trace", "debug", "info", "warn", "error", "critical", "off"};
  if (std::none_of(std::begin(kLevels), std::end(kLevels), [&](const char* l) { return c.log_level == l; })) {
    return bad("log_level", c.log_level, "must be one of trace, debug, info, warn, error, critical, off");
  }
  if (Status s = CheckLogFormat(c.log_format); !s.ok()) return s;
  if (!c.http_listen.empty()) {
    std::string host;
    int port = 0;
    INSPECT_RETURN_IF_ERROR(SplitHostPort(c.http_listen, "http_listen", &host, &port));
    if (c.http_listen == c.listen && port != 0) {
      return bad("http_listen", c.http_listen, "must differ from listen (gRPC and HTTP need their own ports)");
    }
  }
  if (c.no_rig && !c.rig_config.empty()) {
    return Status::InvalidArgument("no_rig and rig_config exclude each other (rig_config '" + c.rig_config + "')");
  }
  if (!c.tls_client_ca.empty() && c.tls_cert.empty()) {
    return Status::InvalidArgument("tls_client_ca needs tls_cert and tls_key (mTLS is TLS first)");
  }
  if (!c.auth_token_file.empty() && !c.token_file.empty()) {
    return Status::InvalidArgument("auth_token_file and token_file exclude each other (one token, or named tokens)");
  }
  if (!c.policy.empty() && c.token_file.empty() && c.tls_client_ca.empty()) {
    return Status::InvalidArgument("policy needs identities: token_file or tls_client_ca");
  }
  if (c.min_free_mb < 0) return bad("min_free_mb", std::to_string(c.min_free_mb), "must be >= 0");
  if (c.retention_keep_last < 0) {
    return bad("retention_keep_last", std::to_string(c.retention_keep_last), "must be >= 0");
  }
  if (c.retention_interval_s < 1) {
    return bad("retention_interval_s", std::to_string(c.retention_interval_s), "must be >= 1");
  }
  if (c.verification_interval_days < 1 || c.verification_interval_days > 3650) {
    return bad("verification_interval_days", std::to_string(c.verification_interval_days), "must be 1..3650");
  }
  if (c.decode_threads < 0) return bad("decode_threads", std::to_string(c.decode_threads), "must be >= 0");
  if (c.decode_budget_mb < 0) return bad("decode_budget_mb", std::to_string(c.decode_budget_mb), "must be >= 0");
  if (c.artifact_threads < 0) return bad("artifact_threads", std::to_string(c.artifact_threads), "must be >= 0");
  if (c.pool_lease_s < 1) return bad("pool_lease_s", std::to_string(c.pool_lease_s), "must be >= 1");
  if (c.pool_workers < 1) return bad("pool_workers", std::to_string(c.pool_workers), "must be >= 1");
  if (c.pool_poll_ms < 10) return bad("pool_poll_ms", std::to_string(c.pool_poll_ms), "must be >= 10");
  if (c.drain_timeout_s < 0) return bad("drain_timeout_s", std::to_string(c.drain_timeout_s), "must be >= 0");
  if (c.engine_threads < 0) return bad("engine_threads", std::to_string(c.engine_threads), "must be >= 0");
  if (c.tls_cert.empty() != c.tls_key.empty()) {
    return Status::InvalidArgument("TLS needs both tls_cert and tls_key (only " +
                                   std::string(c.tls_cert.empty() ? "tls_key" : "tls_cert") + " is set)");
  }
  return Status::Ok();
}

std::string ConfigToJson(const InspectdConfig& config) {
  Json doc = Json::object();
  for (const auto& key : InspectdConfigKeys()) {
    std::visit([&](auto InspectdConfig::*f) { doc[std::string(key.name)] = config.*f; }, key.field);
  }
  doc["database"] = RedactDatabaseUrl(config.database);  // a password in a URL is never printed
  doc["site_database"] = RedactDatabaseUrl(config.site_database);
  return doc.dump(2) + "\n";
}

StatusOr<ServerOptions> ToServerOptions(const InspectdConfig& c) {
  INSPECT_RETURN_IF_ERROR(ValidateConfig(c));
  ServerOptions o;
  o.listen_address = c.listen;
  o.data_dir = c.data_dir;
  o.database = {c.database, c.database_password_file};
  if (!c.site_database.empty()) {
    o.site_forwarding.site = {c.site_database, c.site_database_password_file};
    o.site_forwarding.rig_id = c.rig_id;
    if (o.site_forwarding.rig_id.empty()) {
      char host[256] = {};
      if (gethostname(host, sizeof(host) - 1) == 0) o.site_forwarding.rig_id = host;
    }
  }
  o.rig_queue_capacity = c.queue_capacity;
  o.reflection = c.reflection;
  o.tls_cert_file = c.tls_cert;
  o.tls_key_file = c.tls_key;
  o.tls_client_ca_file = c.tls_client_ca;
  o.insecure = c.insecure;
  o.token_file = c.token_file;
  o.policy_file = c.policy;
  o.scene_dir = c.scene_dir;
  o.audit_log = c.audit_log;
  o.min_free_mb = c.min_free_mb;
  o.retention.max_age_s = int64_t(std::min<uint64_t>(c.retention_max_age_s, uint64_t(1) << 40));
  o.retention.max_bytes = int64_t(std::min<uint64_t>(c.retention_max_mb, uint64_t(1) << 40) << 20);
  o.retention.keep_last = c.retention_keep_last;
  o.retention_interval_s = c.retention_interval_s;
  o.verification_interval_days = c.verification_interval_days;
  o.no_rig = c.no_rig;
  o.reconstruct.decode_threads = c.decode_threads;
  o.reconstruct.max_decoded_bytes = int64_t(c.decode_budget_mb) << 20;
  o.reconstruct.artifact_threads = c.artifact_threads;
  o.http_listen_address = c.http_listen;
  o.mqtt.host = c.mqtt_host;
  o.mqtt.port = c.mqtt_port;
  o.mqtt.site = c.mqtt_site;
  o.mqtt.rig = c.mqtt_rig;
  o.mqtt.topic_prefix = c.mqtt_topic_prefix;
  o.mqtt.client_id = c.mqtt_client_id;
  o.mqtt.username = c.mqtt_username;
  o.mqtt.password_file = c.mqtt_password_file;
  o.mqtt.tls_ca_file = c.mqtt_tls_ca;
  o.mqtt.tls_cert_file = c.mqtt_tls_cert;
  o.mqtt.tls_key_file = c.mqtt_tls_key;
  o.pool.lease = std::chrono::seconds(c.pool_lease_s);
  o.pool.workers = c.pool_workers;
  o.pool.poll = std::chrono::milliseconds(c.pool_poll_ms);
  o.drain_timeout = std::chrono::seconds(c.drain_timeout_s);
  o.reconstruct.engine_threads = c.engine_threads;
  o.simulation.specimen = c.specimen;
  o.simulation.seed = c.seed;
  (void)ParseCameraSize(c.camera_size, &o.simulation.camera_size);  // checked by ValidateConfig
  if (!c.auth_token_file.empty()) {
    std::ifstream in(c.auth_token_file);
    if (!std::getline(in, o.auth_token) || o.auth_token.empty()) {
      return Status::InvalidArgument("auth_token_file " + Quoted(c.auth_token_file) + " is unreadable or empty");
    }
  }
  return o;
}

std::vector<std::pair<std::string, std::string>> ProcessEnvironment() {
  std::vector<std::pair<std::string, std::string>> env;
  for (char** e = environ; e && *e; ++e) {
    std::string_view entry(*e);
    size_t eq = entry.find('=');
    if (eq == std::string_view::npos) continue;
    env.emplace_back(std::string(entry.substr(0, eq)), std::string(entry.substr(eq + 1)));
  }
  return env;
}

}  // namespace inspection
