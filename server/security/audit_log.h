// Append-only audit trail of who changed what: one JSON object per line for every mutating call
// and every denied call (time, identity, peer, method, target id, outcome code). It never holds
// tokens, request bodies or image data: records carry only the fields below, and free text is
// cut to kMaxAuditTextBytes. The file rotates by size (audit.jsonl -> audit.jsonl.1 -> ...).
// Thread-safe: handlers append from many threads.
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>

#include "core/util/status.h"

namespace inspection {

inline constexpr size_t kMaxAuditTextBytes = 256;

struct AuditRecord {
  std::string identity;  // who (certificate subject or token identity; "anonymous" without auth)
  std::string role;      // the role they had
  std::string peer;      // transport address
  std::string method;    // RPC name, e.g. "Scan"
  std::string target;    // job / recipe / artifact / scan id the call acted on, if any
  StatusCode code = StatusCode::kOk;
  std::string message;  // outcome message (cut); never a credential
};

struct AuditLogOptions {
  std::filesystem::path path;         // e.g. <data-dir>/audit/audit.jsonl
  int64_t max_file_bytes = 16 << 20;  // rotate when the current file would exceed this
  int max_rotated_files = 8;          // audit.jsonl.1 .. .N kept; older ones deleted
};

class AuditLog {
 public:
  static StatusOr<std::unique_ptr<AuditLog>> Open(const AuditLogOptions& options);

  // Writes one line and flushes it. A failed write is logged (spdlog) and counted, never thrown:
  // auditing must not take the service down, and the caller's result is already decided.
  void Append(const AuditRecord& record);
  int64_t failed_writes() const;

  // The JSON line for a record (exposed for tests and the log mirror).
  static std::string Format(const AuditRecord& record, int64_t unix_ms);

 private:
  explicit AuditLog(AuditLogOptions options) : options_(std::move(options)) {}
  Status OpenCurrent();
  void RotateLocked();

  const AuditLogOptions options_;
  mutable std::mutex mu_;  // guards the members below
  std::ofstream out_;
  int64_t bytes_ = 0;
  int64_t failed_ = 0;
};

}  // namespace inspection
