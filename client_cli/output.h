// inspectctl output: exit codes, the one-line error format, plain text lines, JSON Lines and the
// progress display while following a job (docs/inspectctl.md "Progress display", "Exit codes", "JSON output").
#pragma once

#include <grpcpp/grpcpp.h>

#include <cstdint>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>

#include "client_cli/inspection_client.h"

namespace inspection::client::cli {

using json = nlohmann::ordered_json;

// Exit codes (docs/inspectctl.md "Exit codes").
constexpr int kExitOk = 0;
constexpr int kExitUsage = 2;
constexpr int kExitUnreachable = 3;
constexpr int kExitFailed = 4;
constexpr int kExitCancelled = 5;
constexpr int kExitIntegrity = 6;
constexpr int kExitDetached = 130;  // Ctrl-C while following: the job keeps running

// How results are shown: the global --json and --quiet flags, and whether stdout is a terminal.
struct Output {
  bool json = false;
  bool quiet = false;
  bool tty = false;
};

// ---- Text helpers

std::string Format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string Lower(std::string s);
// Enum names without their prefix: JOB_STATE_SUCCEEDED -> "SUCCEEDED" (Lower() for lists).
std::string Short(const std::string& enum_name, const std::string& prefix);
// "verified", "verification due", "verification failed" ("unknown" for UNSPECIFIED).
std::string VerificationStateText(v1::VerificationState state);
// "OK", "INVALID_ARGUMENT", ...: the gRPC status name printed in error lines.
const char* CodeName(grpc::StatusCode code);
// RFC 3339 to the second; "-" when unset.
std::string TimeText(const google::protobuf::Timestamp& t);

// ---- Errors

// Prints "inspectctl: CODE: message" on stderr (the one error line of every failure).
void PrintErrorLine(const grpc::Status& status);
// The exit code of an RPC error: UNAVAILABLE 3, DATA_LOSS 6, CANCELLED 5, anything else 4.
int ExitCodeFor(const grpc::Status& status);
// PrintErrorLine, then ExitCodeFor.
int ReportError(const grpc::Status& status);

// ---- JSON Lines

// A proto message in protobuf's JSON mapping with proto field names and default values included.
json ProtoJson(const google::protobuf::Message& message);
// One JSON object on one stdout line, flushed (consumers read it as it comes).
void PrintJsonLine(const json& j);

// ---- Plain summaries

// "depth: WxH px ...", and the error against ground truth when the server had one.
void PrintDepthSummary(const v1::DepthSummary& d);
// The alignment line of a depth summary (none and the default's fallback reason included) and
// one line per frame with its transform.
void PrintAlignment(const v1::DepthSummary& d);
// "inspection: recipe R v2, part P, station S: NOT_OK", then one line per measurement: name,
// parameter, value and unit, U (k = 2), coverage, verdict, and the reason when not OK.
void PrintInspection(const v1::InspectionResult& inspection);
// A calibration's steps and its figures sorted by name, one per line, each line indented.
void PrintFigures(const v1::CalibrationSummary& summary, const std::string& indent);

// ---- Progress

// Shows job events and byte transfers: a redrawn single line on a terminal, one plain line per
// event otherwise, JSON Lines with --json. Safe to call from the upload and event threads.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(const Output& out) : out_(out) {}
  ~ProgressPrinter() { Finish(); }
  ProgressPrinter(const ProgressPrinter&) = delete;
  ProgressPrinter& operator=(const ProgressPrinter&) = delete;

  void OnEvent(const v1::JobEvent& event);
  void OnBytes(const std::string& what, int64_t done, int64_t total);
  // Ends an open progress line, so that what follows starts on a line of its own.
  void Finish();

 private:
  static std::string EventText(const v1::JobEvent& e, bool terminal);
  void Redraw(std::string line);
  void EndLine();

  const Output out_;
  // Guards line_open_ and the order of what reaches stdout.
  std::mutex mu_;
  bool line_open_ = false;
};

}  // namespace inspection::client::cli
