// Audit log: JSON Lines, flushed per record, rotated by size (see audit_log.h).
#include "server/security/audit_log.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <system_error>

namespace inspection {

namespace {

std::string Cut(const std::string& s) {
  if (s.size() <= kMaxAuditTextBytes) return s;
  // Cut on a UTF-8 boundary so the line stays valid JSON text.
  size_t n = kMaxAuditTextBytes;
  while (n > 0 && (static_cast<unsigned char>(s[n]) & 0xC0) == 0x80) --n;
  return s.substr(0, n) + "...";
}

std::string Iso8601(int64_t unix_ms) {
  const std::time_t secs = static_cast<std::time_t>(unix_ms / 1000);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char buf[40];
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday,
                tm.tm_hour, tm.tm_min, tm.tm_sec, static_cast<int>(unix_ms % 1000));
  return buf;
}

}  // namespace

StatusOr<std::unique_ptr<AuditLog>> AuditLog::Open(const AuditLogOptions& options) {
  if (options.path.empty()) return Status::InvalidArgument("audit log path is empty");
  if (options.max_file_bytes < 1024) return Status::InvalidArgument("audit log max_file_bytes must be >= 1024");
  if (options.max_rotated_files < 1) return Status::InvalidArgument("audit log max_rotated_files must be >= 1");
  std::error_code ec;
  std::filesystem::create_directories(options.path.parent_path(), ec);
  if (ec) return Status::Internal("cannot create audit log folder " + options.path.parent_path().string());
  std::unique_ptr<AuditLog> log(new AuditLog(options));
  INSPECT_RETURN_IF_ERROR(log->OpenCurrent());
  return log;
}

Status AuditLog::OpenCurrent() {
  out_.close();
  out_.clear();
  out_.open(options_.path, std::ios::app | std::ios::binary);
  if (!out_) return Status::Internal("cannot open audit log " + options_.path.string());
  std::error_code ec;
  const auto size = std::filesystem::file_size(options_.path, ec);
  bytes_ = ec ? 0 : static_cast<int64_t>(size);
  return Status::Ok();
}

std::string AuditLog::Format(const AuditRecord& r, int64_t unix_ms) {
  nlohmann::json j;
  j["time"] = Iso8601(unix_ms);
  j["identity"] = Cut(r.identity);
  j["role"] = r.role;
  j["peer"] = Cut(r.peer);
  j["method"] = Cut(r.method);
  if (!r.target.empty()) j["target"] = Cut(r.target);
  j["code"] = StatusCodeName(r.code);
  if (!r.message.empty()) j["message"] = Cut(r.message);
  // Invalid UTF-8 from a client (ids are client text) is replaced, not allowed to break the line.
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

void AuditLog::RotateLocked() {
  out_.close();
  std::error_code ec;
  const std::string base = options_.path.string();
  std::filesystem::remove(base + "." + std::to_string(options_.max_rotated_files), ec);
  for (int i = options_.max_rotated_files - 1; i >= 1; --i) {
    const std::string from = base + "." + std::to_string(i);
    if (std::filesystem::exists(from, ec)) std::filesystem::rename(from, base + "." + std::to_string(i + 1), ec);
  }
  std::filesystem::rename(options_.path, base + ".1", ec);
  if (Status st = OpenCurrent(); !st.ok()) spdlog::error("audit: {}", st.ToString());
}

void AuditLog::Append(const AuditRecord& record) {
  const int64_t now_ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count();
  const std::string line = Format(record, now_ms) + "\n";
  std::lock_guard lock(mu_);
  if (bytes_ > 0 && bytes_ + static_cast<int64_t>(line.size()) > options_.max_file_bytes) RotateLocked();
  out_.write(line.data(), static_cast<std::streamsize>(line.size()));
  out_.flush();
  if (!out_) {
    ++failed_;
    out_.clear();
    spdlog::error("audit: cannot write to {}", options_.path.string());
    return;
  }
  bytes_ += static_cast<int64_t>(line.size());
}

int64_t AuditLog::failed_writes() const {
  std::lock_guard lock(mu_);
  return failed_;
}

}  // namespace inspection
