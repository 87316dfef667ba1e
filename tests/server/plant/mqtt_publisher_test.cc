// MqttPublisher against a real mosquitto broker started by the test on a free loopback port, with
// mosquitto_sub (QoS 1, persistent session) as the consumer: every stored result arrives once,
// in order and byte for byte as stored, also across a broker restart in the middle of a run and
// across a publisher restart; the rig state is a retained message.
#include "server/plant/mqtt_publisher.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <pwd.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "tests/server/test_certs.h"


extern char** environ;

namespace inspection::testing {
namespace {

using Clock = std::chrono::steady_clock;

std::filesystem::path MakeTempDir() {
  std::string tmpl = (std::filesystem::temp_directory_path() / "mqtt_test_XXXXXX").string();
  return mkdtemp(tmpl.data());
}

int FreeLoopbackPort() {
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  close(fd);
  return ntohs(a.sin_port);
}

bool Accepts(int port) {
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  const bool ok = connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  close(fd);
  return ok;
}

template <class F>
bool PollFor(F done, std::chrono::seconds deadline = std::chrono::seconds(30)) {
  const auto end = Clock::now() + deadline;
  while (Clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // polling interval, not synchronisation
  }
  return done();
}

// A child process with its stdout and stderr in `out`.
pid_t Spawn(const std::vector<std::string>& argv, const std::string& out) {
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawnp(&pid, args[0], &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  return rc == 0 ? pid : -1;
}

void Terminate(pid_t* pid) {
  if (*pid <= 0) return;
  kill(*pid, SIGTERM);
  int status = 0;
  waitpid(*pid, &status, 0);
  *pid = -1;
}

// mosquitto with persistence, so the subscriber's session and its queued messages survive a restart.
class Broker {
 public:
  Broker(std::filesystem::path dir, int port) : dir_(std::move(dir)), port_(port) {
    std::ofstream conf(dir_ / "mosquitto.conf");
    // Started as root, mosquitto would drop to the user "mosquitto", which cannot write its
    // persistence file into our private temp dir (the sessions would then not survive a restart).
    const passwd* pw = getpwuid(getuid());
    conf << "listener " << port_ << " 127.0.0.1\nallow_anonymous true\npersistence true\npersistence_location "
         << dir_.string() << "/\nuser " << (pw ? pw->pw_name : "root") << "\n";
  }
  ~Broker() { Stop(); }
  bool Start() {
    pid_ = Spawn({"mosquitto", "-c", (dir_ / "mosquitto.conf").string()}, (dir_ / "broker.log").string());
    return pid_ > 0 && PollFor([&] { return Accepts(port_); }, std::chrono::seconds(10));
  }
  void Stop() { Terminate(&pid_); }

 private:
  std::filesystem::path dir_;
  int port_;
  pid_t pid_ = -1;
};

std::vector<std::string> Lines(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::vector<std::string> out;
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

v1::InspectionResult MakeResult(int i) {
  v1::InspectionResult r;
  r.set_recipe_id("tilt");
  r.set_recipe_version(1);
  r.set_part_id("part-" + std::to_string(i));
  r.set_job_id("job-" + std::to_string(i));
  r.set_station("line-2");
  r.set_verdict(i % 3 == 0 ? v1::VERDICT_NOT_OK : v1::VERDICT_OK);
  v1::MeasurementResult* m = r.add_measurements();
  m->set_name("tilt");
  m->set_value(5.0 + 0.01 * i);
  m->set_standard_uncertainty(0.02);
  m->set_verdict(r.verdict());
  return r;
}

class MqttPublisherTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = MakeTempDir();
    auto store = DataStore::Open(dir_ / "data");
    ASSERT_TRUE(store.ok()) << store.status().message();
    store_ = std::move(*store);
    feed_ = std::make_unique<ResultFeed>(store_.get());
    port_ = FreeLoopbackPort();
    options_.host = "127.0.0.1";
    options_.port = port_;
    options_.site = "plant1";
    options_.rig = "rig7";
    options_.sequence_file = dir_ / "data" / "plant" / "mqtt_sequence";
  }
  void TearDown() override {
    if (publisher_) publisher_->Stop();
    Terminate(&sub_);
    broker_.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  void StartSubscriber() {
    sub_ = Spawn({"mosquitto_sub", "-h", "127.0.0.1", "-p", std::to_string(port_), "-V", "mqttv311", "-q", "1", "-c",
                  "-i", "test-consumer", "-v", "-t", "inspect/plant1/rig7/#"},
                 (dir_ / "sub.out").string());
    ASSERT_GT(sub_, 0);
  }
  std::vector<std::string> ResultLines() {
    std::vector<std::string> out;
    const std::string prefix = options_.results_topic() + " ";
    for (const auto& l : Lines(dir_ / "sub.out"))
      if (l.rfind(prefix, 0) == 0) out.push_back(l.substr(prefix.size()));
    return out;
  }
  std::vector<std::string> StateLines() {
    std::vector<std::string> out;
    const std::string prefix = options_.state_topic() + " ";
    for (const auto& l : Lines(dir_ / "sub.out"))
      if (l.rfind(prefix, 0) == 0) out.push_back(l.substr(prefix.size()));
    return out;
  }
  std::string Sequences() {
    std::string out;
    for (const auto& l : ResultLines()) out += std::to_string(nlohmann::json::parse(l)["sequence"].get<int64_t>()) + " ";
    return out;
  }
  void Append(int from, int to) {
    for (int i = from; i <= to; ++i) ASSERT_TRUE(feed_->Append(MakeResult(i)).ok());
  }
  void StartPublisher() {
    auto p = MqttPublisher::Start(options_, feed_.get(), store_.get(), [this] {
      std::lock_guard<std::mutex> lock(state_mu_);
      return state_;
    });
    ASSERT_TRUE(p.ok()) << p.status().message();
    publisher_ = std::move(*p);
  }

  std::filesystem::path dir_;
  std::unique_ptr<DataStore> store_;
  std::unique_ptr<ResultFeed> feed_;
  int port_ = 0;
  MqttOptions options_;
  std::unique_ptr<Broker> broker_;
  std::unique_ptr<MqttPublisher> publisher_;
  pid_t sub_ = -1;
  std::mutex state_mu_;
  RigStateSample state_{v1::RIG_STATE_READY, ""};
};

TEST_F(MqttPublisherTest, EveryResultArrivesOnceInOrderAsStoredAcrossABrokerAndAPublisherRestart) {
  broker_ = std::make_unique<Broker>(dir_, port_);
  ASSERT_TRUE(broker_->Start());
  StartPublisher();
  StartSubscriber();
  // The retained state reaches the consumer as soon as it has subscribed.
  ASSERT_TRUE(PollFor([&] { return !StateLines().empty(); })) << "no state message";
  EXPECT_EQ(nlohmann::json::parse(StateLines()[0])["state"], "RIG_STATE_READY");

  Append(1, 4);
  // The broker forwards before it acknowledges: wait for both.
  ASSERT_TRUE(PollFor([&] { return ResultLines().size() >= 4 && publisher_->last_acknowledged_sequence() == 4; }));

  // The broker goes away in the middle of the run: results and a state change wait.
  broker_->Stop();
  ASSERT_TRUE(PollFor([&] { return !publisher_->connected(); }));
  Append(5, 8);
  {
    std::lock_guard<std::mutex> lock(state_mu_);
    state_ = {v1::RIG_STATE_BUSY, ""};
  }
  EXPECT_EQ(publisher_->last_acknowledged_sequence(), 4);
  EXPECT_EQ(ResultLines().size(), 4u);
  ASSERT_TRUE(broker_->Start());
  Append(9, 12);
  ASSERT_TRUE(PollFor([&] { return ResultLines().size() >= 12 && publisher_->last_acknowledged_sequence() == 12; }))
      << ResultLines().size() << " results arrived: " << Sequences() << "; acknowledged up to "
      << publisher_->last_acknowledged_sequence();
  ASSERT_TRUE(PollFor([&] { return StateLines().size() >= 2; }));
  EXPECT_EQ(nlohmann::json::parse(StateLines().back())["state"], "RIG_STATE_BUSY");

  // inspectd restarts: the publisher resumes after the last acknowledged result, no repeats.
  publisher_->Stop();
  publisher_.reset();
  Append(13, 13);
  StartPublisher();
  ASSERT_TRUE(PollFor([&] { return ResultLines().size() >= 13 && publisher_->last_acknowledged_sequence() == 13; }));
  publisher_->Stop();

  auto stored = store_->ResultsAfter(0, 100);
  ASSERT_TRUE(stored.ok());
  ASSERT_EQ(stored->size(), 13u);
  const std::vector<std::string> got = ResultLines();
  ASSERT_EQ(got.size(), 13u) << "a result arrived twice or not at all";
  for (size_t i = 0; i < got.size(); ++i) {
    const v1::InspectionResult& want = (*stored)[i];
    EXPECT_EQ(got[i], ResultPayload(options_, want)) << "message " << i;
    const auto j = nlohmann::json::parse(got[i]);
    EXPECT_EQ(j["schema"], "inspectd.mqtt.result.v1");
    EXPECT_EQ(j["site"], "plant1");
    EXPECT_EQ(j["rig"], "rig7");
    EXPECT_EQ(j["sequence"].get<int64_t>(), int64_t(i + 1));
    v1::InspectionResult parsed;
    ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(j["result"].dump(), &parsed).ok());
    EXPECT_EQ(parsed.SerializeAsString(), want.SerializeAsString()) << "message " << i;
    EXPECT_EQ(parsed.part_id(), "part-" + std::to_string(i + 1));
  }
  EXPECT_EQ(Lines(options_.sequence_file).at(0), "13");
}

TEST_F(MqttPublisherTest, ResultsStoredBeforeTheFirstStartAreNotFloodedOntoTheBroker) {
  Append(1, 3);
  broker_ = std::make_unique<Broker>(dir_, port_);
  ASSERT_TRUE(broker_->Start());
  StartPublisher();
  EXPECT_EQ(publisher_->last_acknowledged_sequence(), 3);
  EXPECT_EQ(Lines(options_.sequence_file).at(0), "3");
}

TEST_F(MqttPublisherTest, BadSettingsAreRefusedNamingTheSetting) {
  auto start = [&](MqttOptions o) { return MqttPublisher::Start(o, feed_.get(), store_.get(), nullptr).status(); };
  MqttOptions o = options_;
  o.site = "a/b";
  EXPECT_EQ(start(o).code(), StatusCode::kInvalidArgument);
  EXPECT_NE(start(o).message().find("mqtt_site 'a/b'"), std::string::npos) << start(o).message();
  o = options_;
  o.port = 70000;
  EXPECT_NE(start(o).message().find("mqtt_port 70000"), std::string::npos);
  o = options_;
  o.username = "inspectd";
  o.password_file = (dir_ / "missing").string();
  EXPECT_NE(start(o).message().find("mqtt_password_file: cannot read"), std::string::npos) << start(o).message();
  o = options_;
  o.tls_cert_file = "c.pem";
  EXPECT_NE(start(o).message().find("mqtt_tls_cert and mqtt_tls_key"), std::string::npos);
  o = options_;
  std::filesystem::create_directories(o.sequence_file.parent_path());
  std::ofstream(o.sequence_file) << "12x\n";
  EXPECT_NE(start(o).message().find("not a sequence number: '12x'"), std::string::npos) << start(o).message();
}

// TLS with the broker's CA and a user name whose password comes from a file; a wrong password
// is refused by the broker (CONNACK "not authorised") and nothing is published.
TEST_F(MqttPublisherTest, TlsAndCredentialsAndAWrongPasswordIsRefused) {
  const KeyAndCert ca = MakeCertificate("test-ca", "", nullptr, 1);
  const KeyAndCert server = MakeCertificate("localhost", "DNS:localhost,IP:127.0.0.1", &ca, 2);
  WriteText(dir_ / "ca.pem", ca.cert_pem);
  WriteText(dir_ / "server.pem", server.cert_pem);
  WriteText(dir_ / "server.key", server.key_pem);
  WriteText(dir_ / "password", "s3cret\n");
  WriteText(dir_ / "wrong", "guess\n");
  ASSERT_EQ(std::system(("mosquitto_passwd -b -c " + (dir_ / "users").string() + " inspectd s3cret").c_str()), 0);
  const passwd* pw = getpwuid(getuid());
  std::ofstream(dir_ / "mosquitto.conf") << "listener " << port_ << " 127.0.0.1\ncafile " << (dir_ / "ca.pem").string()
                                         << "\ncertfile " << (dir_ / "server.pem").string() << "\nkeyfile "
                                         << (dir_ / "server.key").string() << "\nallow_anonymous false\npassword_file "
                                         << (dir_ / "users").string() << "\nuser " << (pw ? pw->pw_name : "root")
                                         << "\n";
  pid_t broker = Spawn({"mosquitto", "-c", (dir_ / "mosquitto.conf").string()}, (dir_ / "broker.log").string());
  ASSERT_TRUE(PollFor([&] { return Accepts(port_); }, std::chrono::seconds(10)));
  sub_ = Spawn({"mosquitto_sub", "-h", "127.0.0.1", "-p", std::to_string(port_), "--cafile", (dir_ / "ca.pem").string(),
                "-u", "inspectd", "-P", "s3cret", "-q", "1", "-v", "-t", "inspect/plant1/rig7/#"},
               (dir_ / "sub.out").string());
  options_.tls_ca_file = (dir_ / "ca.pem").string();
  options_.username = "inspectd";

  options_.password_file = (dir_ / "wrong").string();
  StartPublisher();
  ASSERT_TRUE(PollFor([&] { return publisher_->refused_connections() >= 1; }));
  EXPECT_FALSE(publisher_->connected());
  publisher_->Stop();
  publisher_.reset();

  options_.password_file = (dir_ / "password").string();
  options_.client_id = "inspectd-tls";
  StartPublisher();
  // The retained state reaching the consumer says it has subscribed.
  ASSERT_TRUE(PollFor([&] { return publisher_->connected() && !StateLines().empty(); }));
  Append(1, 2);
  ASSERT_TRUE(PollFor([&] { return ResultLines().size() >= 2 && publisher_->last_acknowledged_sequence() == 2; }))
      << Sequences();
  EXPECT_EQ(Sequences(), "1 2 ");
  EXPECT_EQ(publisher_->refused_connections(), 0);
  publisher_->Stop();
  Terminate(&broker);
}

}  // namespace
}  // namespace inspection::testing
