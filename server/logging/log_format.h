// inspectd's log lines: "text" (the default, for people) or "json" (one JSON object per line,
// for log collectors: time, level, message, job_id while a job's work runs on the thread, and
// identity while an RPC or a job runs for a caller).
// Both come from thread-local scopes: the JobManager's workers open one around a job (its id and
// its owner), the gRPC interceptor of log_identity_interceptor.h one around each call (the
// authenticated caller), so handlers and procedures log through plain spdlog calls and still get
// their job and caller attributed.
#pragma once

#include <spdlog/formatter.h>

#include <memory>
#include <string>
#include <string_view>

#include "core/util/status.h"

namespace inspection {

// Marks the current thread as working for `identity` (the authenticated caller: certificate CN
// or SAN, token name, "anonymous" without authentication) until destroyed; nests (restores the
// outer). An empty identity leaves the outer one in force.
class ScopedLogIdentity {
 public:
  explicit ScopedLogIdentity(std::string identity);
  ~ScopedLogIdentity();
  ScopedLogIdentity(const ScopedLogIdentity&) = delete;
  ScopedLogIdentity& operator=(const ScopedLogIdentity&) = delete;

  // The identity of the current thread; empty outside any scope.
  static const std::string& Current();

 private:
  std::string previous_;
};

// Marks the current thread as working for `job_id` until destroyed; nests (restores the outer).
// `owner`, the identity that started the job, is the thread's identity for as long (empty: the
// outer identity stays).
class ScopedLogJob {
 public:
  explicit ScopedLogJob(std::string job_id, std::string owner = {});
  ~ScopedLogJob();
  ScopedLogJob(const ScopedLogJob&) = delete;
  ScopedLogJob& operator=(const ScopedLogJob&) = delete;

  // The job of the current thread; empty outside any scope.
  static const std::string& Current();

 private:
  std::string previous_;
  ScopedLogIdentity identity_;
};

// {"time":"2026-11-25T19:40:01.123Z","level":"info","message":"...","job_id":"scan-...",
//  "identity":"station-7"} + '\n'.
// Time in UTC with milliseconds; job_id and identity only when known; the logger's name as
// "logger" when it is not the default one.
class JsonLogFormatter final : public spdlog::formatter {
 public:
  void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override;
  std::unique_ptr<spdlog::formatter> clone() const override;
};

// The log formats `log_format` accepts.
Status CheckLogFormat(std::string_view format);
// Sets the default logger's level and format ("text" or "json"); `format` must pass
// CheckLogFormat.
void ConfigureLogging(std::string_view format, std::string_view level);

// One line in the configured format, written to stdout whatever the level: inspectd's
// "listening on" line, which scripts and tests wait for.
void PrintAnnouncement(std::string_view format, const std::string& message);

}  // namespace inspection
