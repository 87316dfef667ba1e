// MqttPublisher: publishes every stored inspection result and every rig state change of this
// server to an MQTT broker (libmosquitto), for plants that collect machine data centrally.
//
// Results come from the stored result feed (ResultFeed, DataStore sequence numbers), one at a
// time with QoS 1 on a persistent session: the next result is sent only after the broker's
// PUBACK for the previous one, and the sequence number of the last acknowledged result is kept
// in a file. So a broker outage, a network break or an inspectd restart neither loses results
// nor reorders them: publishing resumes after the last acknowledged one. QoS 1 is at-least-once
// (a PUBACK lost in a crash means that one result is sent again); every payload carries the
// sequence number so a consumer drops a repeat (docs/plant-protocols.md).
//
// Rig states are sampled (state_source) and the latest one is a retained message; states that
// changed and changed back while the broker was away are not replayed, only the current one.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/results/result_feed.h"

struct mosquitto;

namespace inspection {

struct MqttOptions {
  std::string host;  // broker host; empty = MQTT off
  int port = 1883;
  std::string site = "site";  // topics: <topic_prefix>/<site>/<rig>/{results,state}
  std::string rig = "rig";
  std::string topic_prefix = "inspect";
  std::string client_id;  // empty = "inspectd-<site>-<rig>"; fixed, so the broker keeps the session
  std::string username;
  std::string password_file;  // first line is the password; never logged
  std::string tls_ca_file;    // PEM CA of the broker: enables TLS
  std::string tls_cert_file;  // client certificate and key (brokers that require them)
  std::string tls_key_file;
  int keepalive_s = 30;
  // The sequence number of the last result the broker acknowledged. Missing = start after the
  // newest stored result (history is not flooded onto a broker that is configured later).
  std::filesystem::path sequence_file;

  bool enabled() const { return !host.empty(); }
  std::string results_topic() const { return topic_prefix + "/" + site + "/" + rig + "/results"; }
  std::string state_topic() const { return topic_prefix + "/" + site + "/" + rig + "/state"; }
};

struct RigStateSample {
  v1::RigState state = v1::RIG_STATE_UNSPECIFIED;
  std::string detail;
};

// The JSON payloads (schemas in docs/plant-protocols.md).
std::string ResultPayload(const MqttOptions& options, const v1::InspectionResult& result);
std::string StatePayload(const MqttOptions& options, const RigStateSample& state);

class MqttPublisher {
 public:
  // Checks the options, reads the password and the sequence file and starts connecting in the
  // background (an absent broker is not an error: results wait for it). state_source may be
  // empty (no rig).
  static StatusOr<std::unique_ptr<MqttPublisher>> Start(const MqttOptions& options, ResultFeed* feed,
                                                        DataStore* store,
                                                        std::function<RigStateSample()> state_source);
  ~MqttPublisher();
  void Stop();

  bool connected() const { return connected_.load(); }
  int64_t last_acknowledged_sequence() const { return last_acked_.load(); }
  int refused_connections() const { return refused_.load(); }  // CONNACK errors (credentials, id)

 private:
  MqttPublisher() = default;
  void Run();
  // Publishes and waits for the PUBACK (re-sending after a reconnect); false when stopping.
  bool PublishAcknowledged(const std::string& topic, const std::string& payload, bool retain);
  Status SaveSequence(int64_t sequence);

  static void OnConnect(mosquitto*, void* self, int rc);
  static void OnDisconnect(mosquitto*, void* self, int rc);
  static void OnPublish(mosquitto*, void* self, int mid);

  MqttOptions options_;
  ResultFeed* feed_ = nullptr;
  std::function<RigStateSample()> state_source_;
  mosquitto* mosq_ = nullptr;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> connected_{false};
  std::atomic<int64_t> last_acked_{0};
  std::atomic<int> refused_{0};
  std::mutex mu_;
  std::condition_variable cv_;  // connect, disconnect, PUBACK, Stop
  uint64_t connections_ = 0;    // connects seen, so a waiter notices a reconnect
  int acked_mid_ = -1;          // the last message id the broker acknowledged
};

}  // namespace inspection
