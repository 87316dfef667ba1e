// inspectd's configuration (server/app/server_config.h): precedence flags > INSPECTD_* environment >
// JSON file > defaults, strict keys and types, --print-config output read back.
#include "server/app/server_config.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

namespace inspection {
namespace {

namespace fs = std::filesystem;
using Env = std::vector<std::pair<std::string, std::string>>;

class ConfigFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("server_config_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    std::ofstream(dir_ / name) << text;
    return (dir_ / name).string();
  }
  fs::path dir_;
};

bool Contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(ServerConfig, DefaultsAreTheServerDefaults) {
  auto options = ToServerOptions(InspectdConfig{});
  ASSERT_TRUE(options.ok()) << options.status().ToString();
  const ServerOptions d;
  EXPECT_EQ(options->listen_address, d.listen_address);
  EXPECT_EQ(options->data_dir, d.data_dir);
  EXPECT_EQ(options->rig_queue_capacity, d.rig_queue_capacity);
  // Set as configured; main.cc leaves it unset (on unless authentication) when no layer set it.
  EXPECT_EQ(options->reflection, std::optional<bool>(true));
  EXPECT_FALSE(d.reflection.has_value());
  EXPECT_EQ(options->tls_cert_file, "");
  EXPECT_EQ(options->auth_token, "");
  EXPECT_EQ(options->simulation.specimen, d.simulation.specimen);
  EXPECT_EQ(options->simulation.seed, d.simulation.seed);
  EXPECT_EQ(options->simulation.camera_size, d.simulation.camera_size);
}

TEST(ServerConfig, NamesDerivedFromTheKey) {
  const ConfigKey* key = FindConfigKey("auth_token_file");
  ASSERT_NE(key, nullptr);
  EXPECT_EQ(key->FlagName(), "--auth-token-file");
  EXPECT_EQ(key->EnvironmentName(), "INSPECTD_AUTH_TOKEN_FILE");
  EXPECT_EQ(FindConfigKey("auth-token-file"), nullptr);  // file keys use '_' only
  EXPECT_EQ(InspectdConfigKeys().size(), 52u);           // every inspectd flag before --config
}

TEST(ServerConfig, DatabaseSettingsAreCheckedRedactedAndReachServerOptions) {
  ConfigLayers layers;
  layers.environment = {{"INSPECTD_DATABASE", "postgresql://inspect:pw@db.example:5432/site"},
                        {"INSPECTD_DATABASE_PASSWORD_FILE", "/run/secrets/db"}};
  auto r = ResolveInspectdConfig(layers);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  auto o = ToServerOptions(r->config);
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->database.url, "postgresql://inspect:pw@db.example:5432/site");
  EXPECT_EQ(o->database.password_file, "/run/secrets/db");
  const std::string printed = ConfigToJson(r->config);
  EXPECT_EQ(printed.find(":pw@"), std::string::npos) << printed;
  EXPECT_NE(printed.find("postgresql://inspect:***@db.example:5432/site"), std::string::npos) << printed;

  for (const std::string bad : {"mysql://x", "postgresql://h:port/db"}) {
    layers.flags = {{"database", bad}};
    auto b = ResolveInspectdConfig(layers);
    ASSERT_FALSE(b.ok()) << bad;
    EXPECT_EQ(b.status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(b.status().message().rfind("database: ", 0), 0u) << b.status().message();
  }
  layers = {};
  layers.flags = {{"database_password_file", "/run/secrets/db"}};  // SQLite has no password
  EXPECT_EQ(ResolveInspectdConfig(layers).status().code(), StatusCode::kInvalidArgument);
}

TEST(ServerConfig, OperationsSettingsAreCheckedAndReachServerOptions) {
  ConfigLayers layers;
  layers.environment = {{"INSPECTD_NO_RIG", "true"}, {"INSPECTD_LOG_FORMAT", "json"}};
  layers.flags = {{"http_listen", "0.0.0.0:9464"}};
  auto r = ResolveInspectdConfig(layers);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->config.no_rig);
  EXPECT_EQ(r->config.log_format, "json");
  auto options = ToServerOptions(r->config);
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->no_rig);
  EXPECT_EQ(options->http_listen_address, "0.0.0.0:9464");

  auto rejected = [](InspectdConfig c, const std::string& needle) {
    const Status s = ValidateConfig(c);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << needle;
    EXPECT_NE(s.message().find(needle), std::string::npos) << s.message();
  };
  InspectdConfig c;
  c.log_format = "xml";
  rejected(c, "log_format 'xml' must be text or json");
  c = InspectdConfig();
  c.http_listen = "9464";
  rejected(c, "http_listen '9464' must be host:port");
  c.http_listen = "127.0.0.1:99999";
  rejected(c, "http_listen '127.0.0.1:99999' must be host:port");
  c.http_listen = c.listen;
  rejected(c, "must differ from listen");
  c = InspectdConfig();
  c.no_rig = true;
  c.rig_config = "/etc/inspection/rig.json";
  rejected(c, "no_rig and rig_config exclude each other");
}

// the reconstruction pipeline's decode threads, decode budget and artifact threads.
TEST(ServerConfig, ReconstructPipelineSettingsReachServerOptions) {
  const ServerOptions d;
  auto defaults = ToServerOptions(InspectdConfig{});
  ASSERT_TRUE(defaults.ok());
  EXPECT_EQ(defaults->reconstruct.decode_threads, d.reconstruct.decode_threads);
  EXPECT_EQ(defaults->reconstruct.max_decoded_bytes, d.reconstruct.max_decoded_bytes);
  EXPECT_EQ(defaults->reconstruct.artifact_threads, d.reconstruct.artifact_threads);
  EXPECT_EQ(InspectdConfig{}.decode_budget_mb, 1024);

  ConfigLayers layers;
  layers.environment = {{"INSPECTD_DECODE_THREADS", "3"}, {"INSPECTD_DECODE_BUDGET_MB", "256"}};
  layers.flags = {{"artifact_threads", "1"}};
  auto r = ResolveInspectdConfig(layers);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  auto options = ToServerOptions(r->config);
  ASSERT_TRUE(options.ok()) << options.status().ToString();
  EXPECT_EQ(options->reconstruct.decode_threads, 3);
  EXPECT_EQ(options->reconstruct.max_decoded_bytes, int64_t(256) << 20);
  EXPECT_EQ(options->reconstruct.artifact_threads, 1);
  EXPECT_FALSE(options->reconstruct.sequential);

  InspectdConfig c;
  c.decode_budget_mb = -1;
  const Status s = ValidateConfig(c);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("decode_budget_mb '-1' must be >= 0"), std::string::npos) << s.message();
  c = InspectdConfig();
  c.decode_threads = -2;
  EXPECT_NE(ValidateConfig(c).message().find("decode_threads"), std::string::npos);
}

TEST_F(ConfigFileTest, FlagsOverrideEnvironmentOverrideFileOverrideDefaults) {
  std::string file = Write("inspectd.json", R"({
    "listen": "0.0.0.0:1001", "queue_capacity": 7, "specimen": "lens", "seed": 11,
    "reflection": false, "log_level": "warn"
  })");
  ConfigLayers layers;
  layers.config_flag = file;
  layers.environment = {{"INSPECTD_LISTEN", "0.0.0.0:2002"},
                        {"INSPECTD_QUEUE_CAPACITY", "9"},
                        {"INSPECTD_REFLECTION", "on"},
                        {"PATH", "/usr/bin"}};
  layers.flags = {{"listen", "127.0.0.1:3003"}, {"reflection", "false"}};
  auto r = ResolveInspectdConfig(layers);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const InspectdConfig& c = r->config;
  EXPECT_EQ(c.listen, "127.0.0.1:3003");  // file, environment and flag: the flag
  EXPECT_EQ(c.reflection, false);         // file false, environment on, flag false: the flag
  EXPECT_EQ(c.queue_capacity, 9);         // file and environment: the environment
  EXPECT_EQ(c.specimen, "lens");          // file only
  EXPECT_EQ(c.seed, 11u);
  EXPECT_EQ(c.log_level, "warn");
  EXPECT_EQ(c.camera_size, "1024x768");  // nowhere: the default
  EXPECT_EQ(c.data_dir, InspectdConfig{}.data_dir);
  EXPECT_EQ(r->config_file, file);
  EXPECT_EQ(r->sources.at("listen"), "--listen");
  EXPECT_EQ(r->sources.at("reflection"), "--reflection");
  EXPECT_EQ(r->sources.at("queue_capacity"), "INSPECTD_QUEUE_CAPACITY");
  EXPECT_EQ(r->sources.at("specimen"), file);
  EXPECT_EQ(r->sources.at("camera_size"), "default");
  EXPECT_TRUE(r->unknown_environment.empty());
}

TEST_F(ConfigFileTest, FileFromEnvironmentUnlessFlagNamesOne) {
  std::string from_env = Write("env.json", R"({"specimen": "coin"})");
  std::string from_flag = Write("flag.json", R"({"specimen": "lens"})");
  ConfigLayers layers;
  layers.environment = {{kConfigFileEnvironment, from_env}};
  auto r = ResolveInspectdConfig(layers);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->config.specimen, "coin");
  EXPECT_EQ(r->config_file, from_env);
  layers.config_flag = from_flag;
  r = ResolveInspectdConfig(layers);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->config.specimen, "lens");
  EXPECT_EQ(r->config_file, from_flag);
}

TEST_F(ConfigFileTest, UnknownKeyIsAnErrorNamingKeyAndFile) {
  std::string file = Write("typo.json", R"({"listen": "0.0.0.0:1", "queue_capacty": 3})");
  InspectdConfig c;
  Status s = ApplyConfigFile(file, &c);
  ASSERT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(s.message(), file + ": unknown key 'queue_capacty' (did you mean 'queue_capacity'?)"))
      << s.message();
  EXPECT_EQ(c, InspectdConfig{});  // nothing applied from a rejected file, not even "listen"

  s = ApplyConfigJson(R"({"frobnicate": 1})", "x.json", &c);
  EXPECT_TRUE(Contains(s.message(), "x.json: unknown key 'frobnicate'; known keys: listen, data_dir,")) << s.message();
  // Flag spellings are not file keys.
  s = ApplyConfigJson(R"({"data-dir": "/d"})", "x.json", &c);
  EXPECT_TRUE(Contains(s.message(), "unknown key 'data-dir' (did you mean 'data_dir'?)")) << s.message();
}

TEST(ServerConfig, WrongJsonTypesNameTheKey) {
  struct Case {
    const char* json;
    const char* message;
  } cases[] = {
      {R"({"queue_capacity": "4"})", "key 'queue_capacity' must be an integer, got string \"4\""},
      {R"({"queue_capacity": 2.5})", "key 'queue_capacity' must be an integer, got number 2.5"},
      {R"({"queue_capacity": 3000000000})", "key 'queue_capacity' must be an integer in int range"},
      {R"({"seed": -1})", "key 'seed' must be an integer >= 0, got integer -1"},
      {R"({"reflection": "false"})", "key 'reflection' must be true or false, got string \"false\""},
      {R"({"listen": 50051})", "key 'listen' must be a string, got integer 50051"},
      {R"({"tls_cert": null})", "key 'tls_cert' must be a string, got null"},
  };
  for (const auto& c : cases) {
    InspectdConfig config;
    Status s = ApplyConfigJson(c.json, "f.json", &config);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << c.json;
    EXPECT_TRUE(Contains(s.message(), std::string("f.json: ") + c.message)) << c.json << " -> " << s.message();
  }
}

TEST_F(ConfigFileTest, UnreadableOrMalformedFile) {
  InspectdConfig c;
  Status s = ApplyConfigFile((dir_ / "absent.json").string(), &c);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(s.message(), "config file '" + (dir_ / "absent.json").string() + "' cannot be read"))
      << s.message();

  std::string file = Write("broken.json", "{\n  \"listen\": \"a:1\",\n  \"seed\": \n}\n");
  s = ApplyConfigFile(file, &c);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(s.message(), file + ": not valid JSON")) << s.message();
  EXPECT_TRUE(Contains(s.message(), "line 4")) << s.message();

  s = ApplyConfigJson("[1, 2]", "list.json", &c);
  EXPECT_TRUE(Contains(s.message(), "list.json: must be a JSON object of settings")) << s.message();
  EXPECT_EQ(c, InspectdConfig{});
}

TEST(ServerConfig, EnvironmentValuesParsedStrictlyAndUnknownOnesReported) {
  InspectdConfig c;
  std::vector<std::string> unknown;
  Status s = ApplyConfigEnvironment({{"INSPECTD_QUEUE_CAPACITY", "4x"}}, &c, nullptr, &unknown);
  EXPECT_EQ(s.message(), "environment variable INSPECTD_QUEUE_CAPACITY '4x' must be an integer");
  s = ApplyConfigEnvironment({{"INSPECTD_SEED", "-3"}}, &c);
  EXPECT_EQ(s.message(), "environment variable INSPECTD_SEED '-3' must be an integer >= 0");
  s = ApplyConfigEnvironment({{"INSPECTD_DEGRADED", "maybe"}}, &c);
  EXPECT_EQ(s.message(), "environment variable INSPECTD_DEGRADED 'maybe' must be true or false");
  EXPECT_EQ(c, InspectdConfig{});

  // Kubernetes adds INSPECTD_PORT etc. for a Service named inspectd: reported, not fatal.
  ConfigSources sources;
  s = ApplyConfigEnvironment({{"INSPECTD_PORT", "tcp://10.0.0.1:50051"},
                              {"INSPECTD_SEED", "18446744073709551615"},
                              {"INSPECTD_DEGRADED", "YES"},
                              {"inspectd_seed", "5"},  // names are case-sensitive, as in a shell
                              {kConfigFileEnvironment, "/nonexistent.json"}},
                             &c, &sources, &unknown);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(c.seed, 18446744073709551615ull);
  EXPECT_TRUE(c.degraded);
  EXPECT_EQ(sources.at("seed"), "INSPECTD_SEED");
  EXPECT_EQ(unknown, std::vector<std::string>{"INSPECTD_PORT"});
}

TEST(ServerConfig, FlagTextParsedLikeEnvironment) {
  ConfigLayers layers;
  layers.flags = {{"queue_capacity", "-1"}};
  auto r = ResolveInspectdConfig(layers);
  EXPECT_EQ(r.status().message(), "queue_capacity '-1' must be >= 0");
  layers.flags = {{"queue_capacity", "many"}};
  r = ResolveInspectdConfig(layers);
  EXPECT_EQ(r.status().message(), "--queue-capacity 'many' must be an integer");
}

TEST(ServerConfig, ValidationNamesTheSetting) {
  InspectdConfig c;
  c.camera_size = "1024";
  EXPECT_EQ(ValidateConfig(c).message(), "camera_size '1024' must be WIDTHxHEIGHT, each >= 16, e.g. 1024x768");
  c.camera_size = "640x480px";
  EXPECT_FALSE(ValidateConfig(c).ok());
  c.camera_size = "640x480";
  EXPECT_TRUE(ValidateConfig(c).ok());
  c.log_level = "loud";
  EXPECT_TRUE(Contains(ValidateConfig(c).message(), "log_level 'loud' must be one of trace,"));
  c.log_level = "debug";
  c.tls_cert = "/etc/cert.pem";
  EXPECT_EQ(ValidateConfig(c).message(), "TLS needs both tls_cert and tls_key (only tls_cert is set)");
  c.tls_key = "/etc/key.pem";
  EXPECT_TRUE(ValidateConfig(c).ok());
  c.listen = "";
  EXPECT_TRUE(Contains(ValidateConfig(c).message(), "listen must not be empty"));

  auto options = ToServerOptions(c);
  EXPECT_EQ(options.status().code(), StatusCode::kInvalidArgument);
}

TEST_F(ConfigFileTest, PrintedConfigurationReadsBackEqual) {
  InspectdConfig c;
  c.listen = "0.0.0.0:50051";
  c.data_dir = "/var/lib/inspection";
  c.queue_capacity = 0;
  c.reflection = false;
  c.rig_config = "/etc/inspection/rig.json";
  c.degraded = true;
  c.seed = 18446744073709551615ull;
  c.camera_size = "640x480";
  const std::string json = ConfigToJson(c);
  auto doc = nlohmann::ordered_json::parse(json);
  ASSERT_EQ(doc.size(), InspectdConfigKeys().size());
  size_t i = 0;
  for (const auto& item : doc.items()) EXPECT_EQ(item.key(), InspectdConfigKeys()[i++].name);  // table order
  EXPECT_EQ(doc["seed"].get<uint64_t>(), 18446744073709551615ull);
  EXPECT_EQ(doc["reflection"], false);

  InspectdConfig back;
  ASSERT_TRUE(ApplyConfigFile(Write("printed.json", json), &back).ok());
  EXPECT_EQ(back, c);
}

TEST_F(ConfigFileTest, TokenFileReadIntoServerOptions) {
  InspectdConfig c;
  c.auth_token_file = Write("token", "s3cret-token\nsecond line ignored\n");
  c.camera_size = "320x240";
  c.specimen = "lens";
  c.seed = 42;
  auto o = ToServerOptions(c);
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->auth_token, "s3cret-token");
  EXPECT_EQ(o->simulation.camera_size, cv::Size(320, 240));
  EXPECT_EQ(o->simulation.specimen, "lens");
  EXPECT_EQ(o->simulation.seed, 42u);

  c.auth_token_file = Write("empty", "");
  o = ToServerOptions(c);
  EXPECT_EQ(o.status().message(), "auth_token_file '" + c.auth_token_file + "' is unreadable or empty");
  c.auth_token_file = (dir_ / "absent").string();
  EXPECT_FALSE(ToServerOptions(c).ok());
}

TEST(VerificationIntervalConfig, TheIntervalReachesServerOptionsAndBadValuesNameTheKey) {
  ConfigLayers layers;
  layers.environment = {{"INSPECTD_VERIFICATION_INTERVAL_DAYS", "7"}};
  auto r = ResolveInspectdConfig(layers);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  auto o = ToServerOptions(r->config);
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->verification_interval_days, 7);
  EXPECT_EQ(ServerOptions{}.verification_interval_days, 30);
  for (const char* bad : {"0", "3651"}) {
    layers.environment = {{"INSPECTD_VERIFICATION_INTERVAL_DAYS", bad}};
    // Refused as the layers resolve (before any server option exists), naming the key.
    auto rb = ResolveInspectdConfig(layers);
    ASSERT_FALSE(rb.ok()) << bad;
    EXPECT_EQ(rb.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(rb.status().message().find("verification_interval_days"), std::string::npos) << rb.status().message();
  }
}

}  // namespace
}  // namespace inspection

namespace inspection {
namespace {

TEST(ServerConfigTrust, TrustSettingsReachServerOptionsAndAreCheckedTogether) {
  InspectdConfig c;
  c.tls_cert = "/pki/server.pem";
  c.tls_key = "/pki/server.key";
  c.tls_client_ca = "/pki/clients.pem";
  c.insecure = true;
  c.token_file = "/pki/tokens";
  c.policy = "/pki/policy.json";
  c.scene_dir = "/srv/scenes";
  c.audit_log = "/var/log/inspectd/audit.jsonl";
  auto o = ToServerOptions(c);
  ASSERT_TRUE(o.ok()) << o.status().ToString();
  EXPECT_EQ(o->tls_client_ca_file, "/pki/clients.pem");
  EXPECT_TRUE(o->insecure);
  EXPECT_EQ(o->token_file, "/pki/tokens");
  EXPECT_EQ(o->policy_file, "/pki/policy.json");
  EXPECT_EQ(o->scene_dir, "/srv/scenes");
  EXPECT_EQ(o->audit_log, "/var/log/inspectd/audit.jsonl");

  InspectdConfig no_tls;
  no_tls.tls_client_ca = "/pki/clients.pem";
  EXPECT_EQ(ValidateConfig(no_tls).message(), "tls_client_ca needs tls_cert and tls_key (mTLS is TLS first)");
  InspectdConfig both_tokens;
  both_tokens.auth_token_file = "/a";
  both_tokens.token_file = "/b";
  EXPECT_EQ(ValidateConfig(both_tokens).message(),
            "auth_token_file and token_file exclude each other (one token, or named tokens)");
  InspectdConfig lonely_policy;
  lonely_policy.policy = "/pki/policy.json";
  EXPECT_EQ(ValidateConfig(lonely_policy).message(), "policy needs identities: token_file or tls_client_ca");
}

// --- OPC UA gateway block -------------------------------------------------------------------
// The gateway (gateway/opcua) shares the config file: its "opcua" object is accepted and left
// alone, anything else under that name is refused with the key named.
TEST_F(ConfigFileTest, OpcuaGatewayBlockIsAcceptedAndNotRead) {
  std::string file = Write("gw.json", R"({"listen": "0.0.0.0:7", "opcua": {"port": 4840, "anything": [1]}})");
  InspectdConfig c;
  ConfigSources sources;
  ASSERT_TRUE(ApplyConfigFile(file, &c, &sources).ok());
  EXPECT_EQ(c.listen, "0.0.0.0:7");
  EXPECT_EQ(sources.count("opcua"), 0u);
  EXPECT_EQ(sources["listen"], file);

  InspectdConfig untouched;
  Status s = ApplyConfigJson(R"({"listen": "0.0.0.0:8", "opcua": 4840})", "gw.json", &untouched);
  ASSERT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(s.message(), "gw.json: 'opcua' must be a JSON object (the OPC UA gateway's settings)");
  EXPECT_EQ(untouched, InspectdConfig{});
}

}  // namespace
}  // namespace inspection
