// MqttPublisher (server/plant/mqtt_publisher.h): the result feed and the rig state over MQTT.
#include "server/plant/mqtt_publisher.h"

#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/time_util.h>
#include <mosquitto.h>
#include <spdlog/spdlog.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

namespace inspection {

namespace {

constexpr auto kFeedWait = std::chrono::milliseconds(200);  // also how often the rig state is sampled

std::string NowRfc3339() {
  return google::protobuf::util::TimeUtil::ToString(google::protobuf::util::TimeUtil::GetCurrentTime());
}

StatusOr<std::string> FirstLine(const std::string& path, const char* what) {
  std::ifstream in(path);
  if (!in) return Status::InvalidArgument(std::string(what) + ": cannot read " + path);
  std::string line;
  std::getline(in, line);
  if (!line.empty() && line.back() == '\r') line.pop_back();
  if (line.empty()) return Status::InvalidArgument(std::string(what) + ": " + path + " is empty");
  return line;
}

}  // namespace

std::string ResultPayload(const MqttOptions& o, const v1::InspectionResult& result) {
  google::protobuf::util::JsonPrintOptions jo;
  jo.preserve_proto_field_names = true;
  std::string result_json;
  // Serialising a valid message cannot fail; an empty object would still carry the sequence.
  if (!google::protobuf::util::MessageToJsonString(result, &result_json, jo).ok()) result_json = "{}";
  nlohmann::ordered_json head;
  head["schema"] = "inspectd.mqtt.result.v1";
  head["site"] = o.site;
  head["rig"] = o.rig;
  head["sequence"] = result.sequence();
  std::string text = head.dump();
  text.pop_back();  // the result as protobuf's JSON, byte for byte, so a consumer can parse it back
  return text + ",\"result\":" + result_json + "}";
}

std::string StatePayload(const MqttOptions& o, const RigStateSample& s) {
  nlohmann::ordered_json j;
  j["schema"] = "inspectd.mqtt.state.v1";
  j["site"] = o.site;
  j["rig"] = o.rig;
  j["state"] = v1::RigState_Name(s.state);
  j["detail"] = s.detail;
  j["time"] = NowRfc3339();
  return j.dump();
}

StatusOr<std::unique_ptr<MqttPublisher>> MqttPublisher::Start(const MqttOptions& options, ResultFeed* feed,
                                                              DataStore* store,
                                                              std::function<RigStateSample()> state_source) {
  if (!options.enabled()) return Status::InvalidArgument("mqtt_host is empty");
  if (options.port < 1 || options.port > 65535) {
    return Status::InvalidArgument("mqtt_port " + std::to_string(options.port) + " is not a TCP port");
  }
  for (const auto& [name, value] : {std::pair{"mqtt_site", options.site}, std::pair{"mqtt_rig", options.rig},
                                    std::pair{"mqtt_topic_prefix", options.topic_prefix}}) {
    if (value.empty() || value.find_first_of("/+#") != std::string::npos) {
      return Status::InvalidArgument(std::string(name) + " '" + value +
                                     "' must be a non-empty topic level without '/', '+' or '#'");
    }
  }
  if (options.tls_cert_file.empty() != options.tls_key_file.empty()) {
    return Status::InvalidArgument("mqtt_tls_cert and mqtt_tls_key go together");
  }
  if (!options.tls_cert_file.empty() && options.tls_ca_file.empty()) {
    return Status::InvalidArgument("mqtt_tls_cert needs mqtt_tls_ca (the broker's CA)");
  }
  if (options.sequence_file.empty()) return Status::InvalidArgument("the MQTT sequence file is not set");
  std::unique_ptr<MqttPublisher> p(new MqttPublisher());
  p->options_ = options;
  if (p->options_.client_id.empty()) p->options_.client_id = "inspectd-" + options.site + "-" + options.rig;
  p->feed_ = feed;
  p->state_source_ = std::move(state_source);

  std::error_code ec;
  if (std::filesystem::exists(options.sequence_file, ec)) {
    INSPECT_ASSIGN_OR_RETURN(std::string text, FirstLine(options.sequence_file.string(), "MQTT sequence file"));
    try {
      size_t used = 0;
      const long long v = std::stoll(text, &used);
      if (used != text.size() || v < 0) throw std::invalid_argument(text);
      p->last_acked_ = v;
    } catch (const std::exception&) {
      return Status::InvalidArgument("MQTT sequence file " + options.sequence_file.string() +
                                     ": not a sequence number: '" + text + "'");
    }
  } else {
    INSPECT_ASSIGN_OR_RETURN(int64_t newest, store->LastResultSequence());
    p->last_acked_ = newest;
    std::filesystem::create_directories(options.sequence_file.parent_path(), ec);
    INSPECT_RETURN_IF_ERROR(p->SaveSequence(newest));
  }

  mosquitto_lib_init();
  p->mosq_ = mosquitto_new(p->options_.client_id.c_str(), /*clean_session=*/false, p.get());
  if (!p->mosq_) return Status::Internal("mosquitto_new failed");
  mosquitto_int_option(p->mosq_, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
  // One message in flight: the next result goes out after the previous one's PUBACK (order).
  mosquitto_max_inflight_messages_set(p->mosq_, 1);
  mosquitto_reconnect_delay_set(p->mosq_, 1, 10, true);
  mosquitto_connect_callback_set(p->mosq_, &MqttPublisher::OnConnect);
  mosquitto_disconnect_callback_set(p->mosq_, &MqttPublisher::OnDisconnect);
  mosquitto_publish_callback_set(p->mosq_, &MqttPublisher::OnPublish);
  if (!options.username.empty()) {
    std::string password;
    if (!options.password_file.empty()) {
      INSPECT_ASSIGN_OR_RETURN(password, FirstLine(options.password_file, "mqtt_password_file"));
    }
    if (mosquitto_username_pw_set(p->mosq_, options.username.c_str(),
                                  options.password_file.empty() ? nullptr : password.c_str()) != MOSQ_ERR_SUCCESS) {
      return Status::InvalidArgument("mqtt_username is not valid UTF-8");
    }
  } else if (!options.password_file.empty()) {
    return Status::InvalidArgument("mqtt_password_file needs mqtt_username");
  }
  if (!options.tls_ca_file.empty()) {
    const int rc = mosquitto_tls_set(p->mosq_, options.tls_ca_file.c_str(), nullptr,
                                     options.tls_cert_file.empty() ? nullptr : options.tls_cert_file.c_str(),
                                     options.tls_key_file.empty() ? nullptr : options.tls_key_file.c_str(), nullptr);
    if (rc != MOSQ_ERR_SUCCESS) {
      return Status::InvalidArgument("MQTT TLS files (mqtt_tls_ca, mqtt_tls_cert, mqtt_tls_key): " +
                                     std::string(mosquitto_strerror(rc)));
    }
  }
  // An unreachable broker is retried by the network loop; results wait in the store meanwhile.
  const int rc = mosquitto_connect_async(p->mosq_, options.host.c_str(), options.port, options.keepalive_s);
  if (rc != MOSQ_ERR_SUCCESS) {
    spdlog::warn("MQTT broker {}:{} not reachable yet ({}); retrying", options.host, options.port,
                 mosquitto_strerror(rc));
  }
  if (mosquitto_loop_start(p->mosq_) != MOSQ_ERR_SUCCESS) return Status::Internal("mosquitto_loop_start failed");
  p->thread_ = std::thread([raw = p.get()] { raw->Run(); });
  spdlog::info("MQTT publishing to {}:{} as {} on {} and {} (after result {})", options.host, options.port,
               p->options_.client_id, options.results_topic(), options.state_topic(), p->last_acked_.load());
  return p;
}

void MqttPublisher::OnConnect(mosquitto*, void* self, int rc) {
  auto* p = static_cast<MqttPublisher*>(self);
  if (rc != 0) {
    ++p->refused_;
    // Bad credentials or a refused client id: say so once per attempt; the loop retries.
    spdlog::warn("MQTT broker {}:{} refused the connection: {}", p->options_.host, p->options_.port,
                 mosquitto_connack_string(rc));
    return;
  }
  {
    std::lock_guard<std::mutex> lock(p->mu_);
    ++p->connections_;
    p->connected_ = true;
  }
  spdlog::info("MQTT connected to {}:{}", p->options_.host, p->options_.port);
  p->cv_.notify_all();
}

void MqttPublisher::OnDisconnect(mosquitto*, void* self, int rc) {
  auto* p = static_cast<MqttPublisher*>(self);
  {
    std::lock_guard<std::mutex> lock(p->mu_);
    p->connected_ = false;
  }
  if (rc != 0 && !p->stop_) spdlog::warn("MQTT connection to {}:{} lost; results are kept until it is back",
                                         p->options_.host, p->options_.port);
  p->cv_.notify_all();
}

void MqttPublisher::OnPublish(mosquitto*, void* self, int mid) {
  auto* p = static_cast<MqttPublisher*>(self);
  {
    std::lock_guard<std::mutex> lock(p->mu_);
    p->acked_mid_ = mid;
  }
  p->cv_.notify_all();
}

bool MqttPublisher::PublishAcknowledged(const std::string& topic, const std::string& payload, bool retain) {
  while (!stop_) {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return stop_ || connected_; });
    if (stop_) return false;
    const uint64_t connection = connections_;
    lock.unlock();
    int mid = 0;
    const int rc = mosquitto_publish(mosq_, &mid, topic.c_str(), int(payload.size()), payload.data(), 1, retain);
    lock.lock();
    if (rc != MOSQ_ERR_SUCCESS) {
      // Not connected after all: wait for the next connection and send it again.
      cv_.wait(lock, [&] { return stop_ || connections_ != connection; });
      continue;
    }
    // The session is persistent, so libmosquitto re-sends an unacknowledged message after a
    // reconnect itself; only a message the broker lost with its session is sent again here.
    while (!stop_ && acked_mid_ != mid) {
      if (connections_ != connection && connected_) {
        const uint64_t reconnected = connections_;
        if (cv_.wait_for(lock, std::chrono::seconds(5),
                         [&] { return stop_ || acked_mid_ == mid || connections_ != reconnected; })) {
          continue;
        }
        break;  // no PUBACK five seconds after the reconnect: publish again
      }
      cv_.wait(lock);
    }
    if (acked_mid_ == mid) return true;
  }
  return false;
}

Status MqttPublisher::SaveSequence(int64_t sequence) {
  const auto tmp = options_.sequence_file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << sequence << "\n";
    if (!out.flush()) return Status::Internal("cannot write the MQTT sequence file " + tmp);
  }
  std::error_code ec;
  std::filesystem::rename(tmp, options_.sequence_file, ec);
  if (ec) return Status::Internal("cannot replace " + options_.sequence_file.string() + ": " + ec.message());
  return Status::Ok();
}

void MqttPublisher::Run() {
  RigStateSample published;
  while (!stop_) {
    if (state_source_) {
      RigStateSample now = state_source_();
      if (now.state != published.state || now.detail != published.detail) {
        if (!PublishAcknowledged(options_.state_topic(), StatePayload(options_, now), /*retain=*/true)) return;
        published = std::move(now);
      }
    }
    auto batch = feed_->Next(last_acked_, 16, kFeedWait);
    if (!batch.ok()) {
      spdlog::error("MQTT: reading the result feed: {}", batch.status().message());
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait_for(lock, std::chrono::seconds(1), [&] { return stop_.load(); });
      continue;
    }
    for (const v1::InspectionResult& r : *batch) {
      if (!PublishAcknowledged(options_.results_topic(), ResultPayload(options_, r), /*retain=*/false)) return;
      last_acked_ = r.sequence();
      if (Status s = SaveSequence(r.sequence()); !s.ok()) spdlog::error("MQTT: {}", s.message());
    }
  }
}

void MqttPublisher::Stop() {
  if (!mosq_) return;
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  mosquitto_disconnect(mosq_);
  mosquitto_loop_stop(mosq_, false);
  mosquitto_destroy(mosq_);
  mosq_ = nullptr;
}

MqttPublisher::~MqttPublisher() {
  if (thread_.joinable() || mosq_) Stop();
}

}  // namespace inspection
