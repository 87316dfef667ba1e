// inspectd's log lines: "text" (the default, for people) or "json" (one JSON object per line,
// for log collectors: time, level, message, and job_id while a job's work runs on the thread).
// The job id comes from a thread-local scope that the JobManager's workers open around a job,
// so procedures log through plain spdlog calls and still get their job attributed.
#pragma once

#include <spdlog/formatter.h>

#include <memory>
#include <string>
#include <string_view>

#include "core/status.h"

namespace inspection {

// Marks the current thread as working for `job_id` until destroyed; nests (restores the outer).
class ScopedLogJob {
 public:
  explicit ScopedLogJob(std::string job_id);
  ~ScopedLogJob();
  ScopedLogJob(const ScopedLogJob&) = delete;
  ScopedLogJob& operator=(const ScopedLogJob&) = delete;

  // The job of the current thread; empty outside any scope.
  static const std::string& Current();

 private:
  std::string previous_;
};

// {"time":"2026-11-25T19:40:01.123Z","level":"info","message":"...","job_id":"scan-..."} + '\n'.
// Time in UTC with milliseconds; job_id only when known; the logger's name as "logger" when it
// is not the default one.
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
