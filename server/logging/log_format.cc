// Text and JSON log lines for inspectd (log_format.h).
#include "server/logging/log_format.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <nlohmann/json.hpp>

namespace inspection {

namespace {

thread_local std::string current_log_job;
thread_local std::string current_log_identity;

const char* kTextPattern = "%Y-%m-%dT%H:%M:%S.%e%z %l inspectd: %v";

std::string UtcTime(std::chrono::system_clock::time_point t) {
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(t.time_since_epoch()).count();
  const std::time_t seconds = std::time_t(ms / 1000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  char buf[64];  // room for any int year: GCC checks the worst case
  std::snprintf(buf, sizeof(buf), "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday,
                tm.tm_hour, tm.tm_min, tm.tm_sec, int(ms % 1000));
  return buf;
}

std::string JsonLine(std::chrono::system_clock::time_point time, std::string_view level, std::string_view message,
                     std::string_view logger) {
  nlohmann::ordered_json j;
  j["time"] = UtcTime(time);
  j["level"] = level;
  // Messages may carry bytes from requests (file names): replace invalid UTF-8, never throw.
  j["message"] = std::string(message);
  const std::string& job = ScopedLogJob::Current();
  if (!job.empty()) j["job_id"] = job;
  // Identities come from certificates and token files: replaced like the message if not UTF-8.
  const std::string& identity = ScopedLogIdentity::Current();
  if (!identity.empty()) j["identity"] = identity;
  if (!logger.empty()) j["logger"] = logger;
  return j.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
}

}  // namespace

ScopedLogIdentity::ScopedLogIdentity(std::string identity) : previous_(current_log_identity) {
  if (!identity.empty()) current_log_identity = std::move(identity);
}

ScopedLogIdentity::~ScopedLogIdentity() { current_log_identity = std::move(previous_); }

const std::string& ScopedLogIdentity::Current() { return current_log_identity; }

ScopedLogJob::ScopedLogJob(std::string job_id, std::string owner)
    : previous_(std::move(current_log_job)), identity_(std::move(owner)) {
  current_log_job = std::move(job_id);
}

ScopedLogJob::~ScopedLogJob() { current_log_job = std::move(previous_); }

const std::string& ScopedLogJob::Current() { return current_log_job; }

void JsonLogFormatter::format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) {
  const auto level = spdlog::level::to_string_view(msg.level);
  const std::string line = JsonLine(msg.time, std::string_view(level.data(), level.size()),
                                    std::string_view(msg.payload.data(), msg.payload.size()),
                                    std::string_view(msg.logger_name.data(), msg.logger_name.size()));
  dest.append(line.data(), line.data() + line.size());
}

std::unique_ptr<spdlog::formatter> JsonLogFormatter::clone() const { return std::make_unique<JsonLogFormatter>(); }

Status CheckLogFormat(std::string_view format) {
  if (format == "text" || format == "json") return Status::Ok();
  return Status::InvalidArgument("log_format '" + std::string(format) + "' must be text or json");
}

void ConfigureLogging(std::string_view format, std::string_view level) {
  spdlog::set_level(spdlog::level::from_str(std::string(level)));
  if (format == "json") {
    spdlog::set_formatter(std::make_unique<JsonLogFormatter>());
  } else {
    spdlog::set_pattern(kTextPattern);
  }
}

void PrintAnnouncement(std::string_view format, const std::string& message) {
  if (format == "json") {
    std::cout << JsonLine(std::chrono::system_clock::now(), "info", message, "") << std::flush;
  } else {
    std::cout << message << std::endl;
  }
}

}  // namespace inspection
