// inspectctl: command-line client of the inspection service (inspection.v1). Starts scans,
// reconstructions and calibrations, follows their progress, fetches results. See USAGE.md.
#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <csignal>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/time_util.h>
#include <nlohmann/json.hpp>

#include "client_cli/inspection_client.h"

namespace inspection::client {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

// Exit codes (USAGE.md "Exit codes").
constexpr int kExitOk = 0;
constexpr int kExitUsage = 2;
constexpr int kExitUnreachable = 3;
constexpr int kExitFailed = 4;
constexpr int kExitCancelled = 5;
constexpr int kExitIntegrity = 6;
constexpr int kExitDetached = 130;  // Ctrl-C while following: the job keeps running

std::string Format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string Format(const char* fmt, ...) {
  char buf[512];
  va_list args;
  va_start(args, fmt);
  std::vsnprintf(buf, sizeof buf, fmt, args);
  va_end(args);
  return buf;
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

const char* CodeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return "OK";
    case grpc::StatusCode::CANCELLED: return "CANCELLED";
    case grpc::StatusCode::UNKNOWN: return "UNKNOWN";
    case grpc::StatusCode::INVALID_ARGUMENT: return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND: return "NOT_FOUND";
    case grpc::StatusCode::ALREADY_EXISTS: return "ALREADY_EXISTS";
    case grpc::StatusCode::PERMISSION_DENIED: return "PERMISSION_DENIED";
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::FAILED_PRECONDITION: return "FAILED_PRECONDITION";
    case grpc::StatusCode::ABORTED: return "ABORTED";
    case grpc::StatusCode::OUT_OF_RANGE: return "OUT_OF_RANGE";
    case grpc::StatusCode::UNIMPLEMENTED: return "UNIMPLEMENTED";
    case grpc::StatusCode::INTERNAL: return "INTERNAL";
    case grpc::StatusCode::UNAVAILABLE: return "UNAVAILABLE";
    case grpc::StatusCode::DATA_LOSS: return "DATA_LOSS";
    case grpc::StatusCode::UNAUTHENTICATED: return "UNAUTHENTICATED";
    default: return "UNKNOWN";
  }
}

std::string TimeText(const google::protobuf::Timestamp& t) {
  if (t.seconds() == 0 && t.nanos() == 0) return "-";
  google::protobuf::Timestamp whole = t;
  whole.set_nanos(0);  // seconds are enough for people
  return google::protobuf::util::TimeUtil::ToString(whole);
}

// Enum names without their prefix: JOB_STATE_SUCCEEDED -> "SUCCEEDED" (Lower() for lists).
std::string Short(const std::string& enum_name, const std::string& prefix) {
  std::string s = enum_name.rfind(prefix, 0) == 0 ? enum_name.substr(prefix.size()) : enum_name;
  return s;
}

// ---------------------------------------------------------------------------------------------
// Names accepted on the command line for proto enums.

const std::map<std::string, v1::FocusMeasure>& FocusMeasures() {
  static const std::map<std::string, v1::FocusMeasure> m = {
      {"tenengrad", v1::FOCUS_MEASURE_TENENGRAD},
      {"modified-laplacian", v1::FOCUS_MEASURE_MODIFIED_LAPLACIAN},
      {"ml", v1::FOCUS_MEASURE_MODIFIED_LAPLACIAN},
      {"sum-modified-laplacian", v1::FOCUS_MEASURE_SUM_MODIFIED_LAPLACIAN},
      {"sml", v1::FOCUS_MEASURE_SUM_MODIFIED_LAPLACIAN},
      {"grey-level-variance", v1::FOCUS_MEASURE_GREY_LEVEL_VARIANCE},
      {"glv", v1::FOCUS_MEASURE_GREY_LEVEL_VARIANCE},
      {"helmli-mean", v1::FOCUS_MEASURE_HELMLI_MEAN},
      {"chebyshev-moments", v1::FOCUS_MEASURE_CHEBYSHEV_MOMENTS},
      {"grey-level-local-variance", v1::FOCUS_MEASURE_GREY_LEVEL_LOCAL_VARIANCE},
      {"gllv", v1::FOCUS_MEASURE_GREY_LEVEL_LOCAL_VARIANCE},
  };
  return m;
}

const std::map<std::string, v1::DepthInterpolation>& Interpolations() {
  static const std::map<std::string, v1::DepthInterpolation> m = {
      {"maximum", v1::DEPTH_INTERPOLATION_MAXIMUM},
      {"line-fit", v1::DEPTH_INTERPOLATION_LINE_FIT},
      {"gaussian", v1::DEPTH_INTERPOLATION_GAUSSIAN},
  };
  return m;
}

const std::map<std::string, v1::ArtifactKind>& Exports() {
  static const std::map<std::string, v1::ArtifactKind> m = {
      {"png16", v1::ARTIFACT_KIND_DEPTH_PNG16},
      {"ply", v1::ARTIFACT_KIND_DEPTH_PLY},
      {"x3p", v1::ARTIFACT_KIND_DEPTH_X3P},
  };
  return m;
}

const std::map<std::string, v1::CalibrationStep>& Steps() {
  static const std::map<std::string, v1::CalibrationStep> m = {
      {"camera-response", v1::CALIBRATION_STEP_CAMERA_RESPONSE},
      {"projector-response", v1::CALIBRATION_STEP_PROJECTOR_RESPONSE},
      {"geometry", v1::CALIBRATION_STEP_GEOMETRY},
      {"psf", v1::CALIBRATION_STEP_PSF},
      {"scatter-matrix", v1::CALIBRATION_STEP_SCATTER_MATRIX},
      {"integral-psf", v1::CALIBRATION_STEP_INTEGRAL_PSF},
  };
  return m;
}

const std::map<std::string, v1::JobKind>& Kinds() {
  static const std::map<std::string, v1::JobKind> m = {
      {"calibrate", v1::JOB_KIND_CALIBRATE}, {"scan", v1::JOB_KIND_SCAN}, {"reconstruct", v1::JOB_KIND_RECONSTRUCT}};
  return m;
}

const std::map<std::string, v1::JobState>& States() {
  static const std::map<std::string, v1::JobState> m = {
      {"queued", v1::JOB_STATE_QUEUED},       {"running", v1::JOB_STATE_RUNNING},
      {"succeeded", v1::JOB_STATE_SUCCEEDED}, {"failed", v1::JOB_STATE_FAILED},
      {"cancelled", v1::JOB_STATE_CANCELLED},
  };
  return m;
}

template <typename T>
std::vector<std::string> Keys(const std::map<std::string, T>& m) {
  std::vector<std::string> keys;
  for (const auto& [k, v] : m) keys.push_back(k);
  return keys;
}

// ---------------------------------------------------------------------------------------------
// Output

struct Output {
  bool json = false;
  bool quiet = false;
  bool tty = false;
};

json ProtoJson(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string text;
  if (!google::protobuf::util::MessageToJsonString(message, &text, options).ok()) return json::object();
  return json::parse(text, nullptr, false);
}

void PrintJsonLine(const json& j) {
  std::cout << j.dump() << '\n' << std::flush;
}

// Prints "inspectctl: CODE: message" on stderr and returns the exit code for it.
int ReportError(const grpc::Status& status) {
  std::cerr << "inspectctl: " << CodeName(status.error_code()) << ": " << status.error_message() << '\n';
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE) return kExitUnreachable;
  if (status.error_code() == grpc::StatusCode::DATA_LOSS) return kExitIntegrity;
  if (status.error_code() == grpc::StatusCode::CANCELLED) return kExitCancelled;
  return kExitFailed;
}

int TerminalWidth() {
  winsize ws{};
  if (ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col > 10) return ws.ws_col;
  return 80;
}

std::string Bar(double fraction, int width = 10) {
  fraction = std::clamp(fraction, 0.0, 1.0);
  const int filled = static_cast<int>(fraction * width + 0.5);
  return "[" + std::string(filled, '#') + std::string(width - filled, '-') + "]";
}

std::string Megabytes(int64_t bytes) { return Format("%.1f MB", static_cast<double>(bytes) / 1e6); }

// Shows job events and byte transfers: a redrawn single line on a terminal, one plain line per
// event otherwise, JSON Lines with --json. Safe to call from the upload and event threads.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(const Output& out) : out_(out) {}
  ~ProgressPrinter() { Finish(); }

  void OnEvent(const v1::JobEvent& event) {
    std::lock_guard<std::mutex> lock(mu_);
    if (out_.json) {
      PrintJsonLine(json{{"type", "event"}, {"event", ProtoJson(event)}});
      return;
    }
    if (out_.quiet) return;
    std::string line = EventText(event, out_.tty);
    if (out_.tty) {
      Redraw(Bar(event.progress()) + " " + line);
      // Keep the line of a terminal event on screen.
      if (event.state() >= v1::JOB_STATE_SUCCEEDED) EndLine();
    } else {
      std::cout << event.job_id() << " #" << event.sequence() << " " << line << '\n' << std::flush;
    }
  }

  void OnBytes(const std::string& what, int64_t done, int64_t total) {
    std::lock_guard<std::mutex> lock(mu_);
    if (out_.json || out_.quiet) return;
    const double fraction = total > 0 ? static_cast<double>(done) / static_cast<double>(total) : 0.0;
    // Only on a terminal: in logs the list of written files says enough.
    if (out_.tty) Redraw(Bar(fraction) + " " + what + " " + Megabytes(done) + " / " + Megabytes(total));
  }

  void Finish() {
    std::lock_guard<std::mutex> lock(mu_);
    EndLine();
  }

 private:
  static std::string EventText(const v1::JobEvent& e, bool terminal) {
    std::string text;
    const bool frame = e.has_frame() && e.frame().frame_count() > 0;
    // On a terminal a frame line leaves out the phase (it is always acquiring) to fit 80 columns.
    if (e.state() >= v1::JOB_STATE_SUCCEEDED) {
      text = Short(v1::JobState_Name(e.state()), "JOB_STATE_");
    } else if (!(frame && terminal)) {
      text = Short(v1::JobPhase_Name(e.phase()), "JOB_PHASE_");
    }
    if (frame) {
      const auto& f = e.frame();
      const auto& s = f.statistics();
      if (!text.empty()) text += ' ';
      text += Format("%d/%d z=%.1fum mean=%.0f sd=%.0f sat=%.1f%% under=%.1f%%", f.frame_index() + 1,
                     f.frame_count(), f.z_um(), s.mean_grey(), s.stddev_grey(), s.saturated_percent(),
                     s.underexposed_percent());
      // HDR exposures and ADAPT initialisation / iteration captures that are not stack frames.
      if (!f.stack_frame()) text += Format(" (capture %d, not kept)", f.acquisition_index() + 1);
    } else {
      text += Format(" %3.0f%%", 100.0 * e.progress());
    }
    if (!e.step().empty()) text += " step=" + e.step();
    if (e.remaining_seconds() >= 0.0 && e.state() < v1::JOB_STATE_SUCCEEDED) {
      text += Format(" %.1fs left", e.remaining_seconds());
    }
    if (!e.message().empty()) text += " " + e.message();
    return text;
  }

  void Redraw(std::string line) {
    const size_t width = static_cast<size_t>(TerminalWidth() - 1);
    if (line.size() > width) line.resize(width);
    std::cout << '\r' << line << "\x1b[K" << std::flush;
    line_open_ = true;
  }

  void EndLine() {
    if (line_open_) std::cout << '\n' << std::flush;
    line_open_ = false;
  }

  Output out_;
  std::mutex mu_;
  bool line_open_ = false;
};

// ---------------------------------------------------------------------------------------------
// Ctrl-C while following a job: stop following (the job keeps running on the server) and say
// how to re-attach. The message is prepared outside the handler; the handler only write()s.

char g_detach_message[512] =
    "\ninspectctl: interrupted before the server reported a job id; `inspectctl jobs` lists the jobs\n";
std::atomic<size_t> g_detach_length{std::strlen(g_detach_message)};

void OnInterrupt(int) {
  const ssize_t ignored = write(STDERR_FILENO, g_detach_message, g_detach_length.load());
  (void)ignored;
  _exit(kExitDetached);
}

void NoteJobId(const std::string& job_id) {
  static std::string noted;
  if (job_id.empty() || job_id == noted) return;
  noted = job_id;
  const std::string msg = "\ninspectctl: stopped following job " + job_id +
                          " (it keeps running); re-attach with: inspectctl watch " + job_id + "\n";
  const size_t n = std::min(msg.size(), sizeof g_detach_message - 1);
  g_detach_length.store(0);
  std::memcpy(g_detach_message, msg.data(), n);
  g_detach_length.store(n);
}

class InterruptGuard {
 public:
  InterruptGuard() {
    struct sigaction sa {};
    sa.sa_handler = OnInterrupt;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &previous_);
  }
  ~InterruptGuard() { sigaction(SIGINT, &previous_, nullptr); }

 private:
  struct sigaction previous_ {};
};

// ---------------------------------------------------------------------------------------------
// Summaries

void PrintDepthSummary(const v1::DepthSummary& d) {
  std::cout << Format("depth: %dx%d px (%.3f um/px), %d frames, valid %.1f %%, z %.2f .. %.2f um", d.width(),
                      d.height(), d.pixel_size_um(), d.frame_count(), d.valid_percent(), d.z_min_um(), d.z_max_um());
  if (d.engine_seconds() > 0.0) std::cout << Format(", engine %.3f s", d.engine_seconds());
  std::cout << '\n';
  if (d.has_ground_truth()) {
    std::cout << Format("vs ground truth: RMSE %.3f um, mean |error| %.3f um\n", d.rmse_um(), d.mean_abs_error_um());
  }
}

void PrintFigures(const v1::CalibrationSummary& summary, const std::string& indent) {
  if (summary.steps_size() > 0) {
    std::cout << indent << "steps:";
    for (const auto& s : summary.steps()) std::cout << ' ' << s;
    std::cout << '\n';
  }
  std::map<std::string, double> sorted(summary.figures().begin(), summary.figures().end());
  for (const auto& [name, value] : sorted) std::cout << indent << name << " = " << Format("%.6g", value) << '\n';
}

std::string JobLine(const v1::Job& job) {
  std::string line = Format("%-24s %-12s %-10s %-20s", job.job_id().c_str(),
                            Lower(Short(v1::JobKind_Name(job.kind()), "JOB_KIND_")).c_str(),
                            Lower(Short(v1::JobState_Name(job.state()), "JOB_STATE_")).c_str(),
                            TimeText(job.create_time()).c_str());
  if (job.state() == v1::JOB_STATE_QUEUED && job.queue_position() > 0) line += Format(" queue#%d", job.queue_position());
  if (!job.label().empty()) line += " label=" + job.label();
  if (job.state() == v1::JOB_STATE_FAILED) {
    line += std::string(" ") + CodeName(static_cast<grpc::StatusCode>(job.error_code())) + ": " + job.error_message();
  }
  if (job.state() == v1::JOB_STATE_SUCCEEDED && job.result().has_depth()) {
    const auto& d = job.result().depth();
    line += Format(" valid=%.1f%% z=%.1f..%.1fum", d.valid_percent(), d.z_min_um(), d.z_max_um());
    if (d.has_ground_truth()) line += Format(" rmse=%.2fum", d.rmse_um());
  }
  if (!job.result().calibration_id().empty() && job.kind() == v1::JOB_KIND_CALIBRATE) {
    line += " calibration=" + job.result().calibration_id();
  }
  return line;
}

// ---------------------------------------------------------------------------------------------
// Following a job to its end, then fetching results.

struct FollowOutcome {
  grpc::Status status;
  v1::Job job;
  bool have_job = false;
};

// Exit code for a followed job; when it did not succeed, prints the error line and sets *error.
int JobExitCode(const FollowOutcome& outcome, grpc::Status* error) {
  const v1::Job& job = outcome.job;
  int code = kExitOk;
  if (outcome.have_job && job.state() == v1::JOB_STATE_CANCELLED) {
    *error = grpc::Status(grpc::StatusCode::CANCELLED, "job " + job.job_id() + " was cancelled");
    code = kExitCancelled;
  } else if (outcome.have_job && job.state() == v1::JOB_STATE_FAILED) {
    // The stream's status carries the job's error; fall back to the job's fields.
    *error = outcome.status.ok()
                 ? grpc::Status(static_cast<grpc::StatusCode>(job.error_code()), job.error_message())
                 : outcome.status;
    code = kExitFailed;
  } else if (!outcome.status.ok()) {
    // An RPC error before the job ended (or before it existed): UNAVAILABLE means the server went away.
    *error = outcome.status;
    return ReportError(outcome.status);
  } else if (!outcome.have_job || job.state() != v1::JOB_STATE_SUCCEEDED) {
    *error = grpc::Status(grpc::StatusCode::INTERNAL, "the event stream ended without a terminal event");
    code = kExitFailed;
  } else {
    return kExitOk;
  }
  std::cerr << "inspectctl: " << CodeName(error->error_code()) << ": " << error->error_message() << '\n';
  return code;
}

// Downloads a succeeded job's results into dir, with progress.
grpc::Status FetchResults(InspectionClient& client, const v1::Job& job, const fs::path& dir, bool include_stack,
                          bool resume, ProgressPrinter& printer, std::vector<fs::path>* written) {
  grpc::Status s = client.DownloadResults(job, dir, include_stack, written, resume,
                                          [&](const std::string& name, int64_t done, int64_t total) {
                                            printer.OnBytes(name, done, total);
                                          });
  printer.Finish();
  return s;
}

// Common ending of scan / reconstruct / watch: exit code, result download, summary.
int FinishJob(InspectionClient& client, const Output& out, ProgressPrinter& printer, const FollowOutcome& outcome,
              const std::optional<fs::path>& out_dir, bool include_stack) {
  printer.Finish();
  grpc::Status error;
  const int code = JobExitCode(outcome, &error);
  json result = {{"type", "result"}};
  if (outcome.have_job) result["job"] = ProtoJson(outcome.job);
  if (code != kExitOk) {
    if (out.json) {
      result["error"] = {{"code", CodeName(error.error_code())}, {"message", error.error_message()}};
      result["exit_code"] = code;
      PrintJsonLine(result);
    }
    return code;
  }
  const v1::Job& job = outcome.job;
  std::vector<fs::path> written;
  if (out_dir) {
    grpc::Status s = FetchResults(client, job, *out_dir, include_stack, /*resume=*/false, printer, &written);
    if (!s.ok()) {
      const int err = ReportError(s);
      if (out.json) {
        result["error"] = {{"code", CodeName(s.error_code())}, {"message", s.error_message()}};
        result["exit_code"] = err;
        PrintJsonLine(result);
      }
      return err;
    }
  }
  if (out.json) {
    if (out_dir) {
      result["output_dir"] = fs::absolute(*out_dir).string();
      result["files"] = json::array();
      for (const auto& p : written) result["files"].push_back(p.filename().string());
    }
    result["exit_code"] = kExitOk;
    PrintJsonLine(result);
    return kExitOk;
  }
  if (out.quiet) {
    if (out_dir) std::cout << fs::absolute(*out_dir).string() << '\n';
    return kExitOk;
  }
  std::cout << "job " << job.job_id() << " succeeded";
  if (!job.result().scan_id().empty()) std::cout << " (scan " << job.result().scan_id() << ")";
  std::cout << '\n';
  if (out_dir) {
    std::cout << "results: " << fs::absolute(*out_dir).string() << '\n';
    for (const auto& p : written) std::cout << "  " << p.filename().string() << '\n';
  } else if (job.result().artifacts_size() > 0) {
    std::cout << "artifacts (inspectctl download ID --out FILE):\n";
    for (const auto& a : job.result().artifacts()) {
      std::cout << "  " << a.artifact_id() << "  " << a.file_name() << "  " << a.size_bytes() << " bytes\n";
    }
  }
  if (job.result().has_depth()) PrintDepthSummary(job.result().depth());
  if (job.kind() == v1::JOB_KIND_CALIBRATE) {
    std::cout << "calibration: " << job.result().calibration_id() << '\n';
    PrintFigures(job.result().calibration(), "  ");
  }
  return kExitOk;
}

// Runs one following call with Ctrl-C detaching and the printer attached.
template <typename Call>
FollowOutcome Follow(ProgressPrinter& printer, Call&& call) {
  InterruptGuard guard;
  FollowOutcome outcome;
  v1::Job job;
  outcome.status = call(
      [&](const v1::JobEvent& e) {
        NoteJobId(e.job_id());
        printer.OnEvent(e);
      },
      &job);
  outcome.have_job = !job.job_id().empty();
  outcome.job = std::move(job);
  return outcome;
}

// ---------------------------------------------------------------------------------------------
// Reconstruction options shared by scan and reconstruct.

struct ReconstructionFlags {
  std::string focus_measure;
  std::optional<int> window_px;
  std::string interpolation;
  std::optional<double> min_confidence;
  std::vector<std::string> exports;

  void Add(CLI::App* cmd) {
    cmd->add_option("--focus-measure", focus_measure, "Focus measure (default tenengrad)")
        ->check(CLI::IsMember(Keys(FocusMeasures()), CLI::ignore_case));
    cmd->add_option("--window", window_px, "Focus measure window, odd 3..31 px (default 7)");
    cmd->add_option("--interpolation", interpolation, "Depth interpolation between frames (default gaussian)")
        ->check(CLI::IsMember(Keys(Interpolations()), CLI::ignore_case));
    cmd->add_option("--min-confidence", min_confidence, "Pixels below this confidence get no depth (0..1)");
    cmd->add_option("--export", exports, "Extra export, repeatable: png16, ply, x3p")
        ->check(CLI::IsMember(Keys(Exports()), CLI::ignore_case));
  }

  v1::ReconstructionOptions ToProto() const {
    v1::ReconstructionOptions o;
    if (!focus_measure.empty()) o.set_focus_measure(FocusMeasures().at(Lower(focus_measure)));
    if (window_px) o.set_window_px(*window_px);
    if (!interpolation.empty()) o.set_interpolation(Interpolations().at(Lower(interpolation)));
    if (min_confidence) o.set_min_confidence(*min_confidence);
    for (const auto& e : exports) o.add_extra_exports(Exports().at(Lower(e)));
    return o;
  }
};

std::string ReadToken(const std::string& path, std::string* token) {
  std::ifstream in(path);
  if (!in) return "cannot read token file " + path;
  std::stringstream ss;
  ss << in.rdbuf();
  std::string t = ss.str();
  const auto not_space = [](unsigned char c) { return !std::isspace(c); };
  t.erase(t.begin(), std::find_if(t.begin(), t.end(), not_space));
  t.erase(std::find_if(t.rbegin(), t.rend(), not_space).base(), t.end());
  if (t.empty()) return "token file " + path + " is empty";
  *token = t;
  return "";
}

int Main(int argc, char** argv) {
  CLI::App app{"inspectctl: client of the inspection service (shape from focus on a microscope rig)", "inspectctl"};
  app.require_subcommand(1);
  app.fallthrough();

  ClientOptions client_options;
  const char* env_server = std::getenv("INSPECT_SERVER");
  client_options.target = env_server != nullptr && *env_server != '\0' ? env_server : "127.0.0.1:50051";
  client_options.connect_timeout_seconds = 5.0;
  std::string token_file;
  Output out;
  app.add_option("--server", client_options.target, "Server address HOST:PORT (env INSPECT_SERVER)")
      ->capture_default_str();
  app.add_option("--tls-ca", client_options.tls_ca_file, "PEM file of the CA that signed the server's certificate (enables TLS)")
      ->envname("INSPECT_TLS_CA");
  app.add_option("--token-file", token_file, "File holding a bearer token sent with every call")
      ->envname("INSPECT_TOKEN_FILE");
  app.add_option("--connect-timeout", client_options.connect_timeout_seconds, "Seconds to wait for the server")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_flag("--json", out.json, "Machine-readable output: JSON Lines while following, then one result object");
  app.add_flag("-q,--quiet", out.quiet, "No progress output");

  // status
  auto* status_cmd = app.add_subcommand("status", "Rig state, devices, calibration and queue");

  // scan
  auto* scan_cmd = app.add_subcommand("scan", "Acquire a stack through focus and reconstruct its depth map");
  std::string scan_out;
  std::optional<double> z_start_um, z_end_um, z_step_um, exposure_us;
  std::string label, request_id;
  bool include_stack = false;
  ReconstructionFlags scan_flags;
  scan_cmd->add_option("--out", scan_out, "Folder for the results")->required();
  scan_cmd->add_option("--z-start", z_start_um, "First z position, um (unset: rig default)");
  scan_cmd->add_option("--z-end", z_end_um, "Last z position, um (unset: rig default)");
  scan_cmd->add_option("--z-step", z_step_um, "z step, um > 0 (unset: rig default)");
  scan_cmd->add_option("--exposure-us", exposure_us, "Camera exposure, us (unset: rig default)");
  std::string illumination;
  std::optional<int> hdr_exposures, max_iterations;
  std::optional<double> adapt_lambda, texture_gamma, hf_psi, target_grey;
  scan_cmd->add_option("--illumination", illumination,
                       "std | hdr | adapt-it | adapt | texture | hf+adapt | adapted-hf (unset: server default)")
      ->check(CLI::IsMember({"std", "hdr", "adapt-it", "adapt", "texture", "hf+adapt", "adapted-hf"}));
  scan_cmd->add_option("--hdr-exposures", hdr_exposures, "HDR: exposures per z, 2..5 (thesis Table 6.2)");
  scan_cmd->add_option("--lambda", adapt_lambda, "ADAPT family: prediction scale of eq. 5.12, 0..2");
  scan_cmd->add_option("--gamma", texture_gamma, "TEXTURE: checkerboard weight of eq. 5.16, 0..0.5");
  scan_cmd->add_option("--psi", hf_psi, "HF+ADAPT: added checkerboard weight of eq. 5.17, 0..1");
  scan_cmd->add_option("--max-iterations", max_iterations, "ADAPT-IT: frames per z at most, 1..20");
  scan_cmd->add_option("--target-grey", target_grey, "ADAPT family: desired camera grey, 8-bit units, 0..255");
  scan_flags.Add(scan_cmd);
  scan_cmd->add_option("--label", label, "Free text kept with the job");
  scan_cmd->add_option("--request-id", request_id, "Idempotency key: repeating it returns the same job");
  scan_cmd->add_flag("--include-stack", include_stack, "Also download the raw stack as stack.zip");

  // reconstruct
  auto* recon_cmd = app.add_subcommand("reconstruct", "Depth map from an uploaded stack folder or a stored scan");
  std::string recon_stack, recon_scan_id, recon_out;
  ReconstructionFlags recon_flags;
  // Exactly one source: an uploaded folder or a stored scan.
  auto* source = recon_cmd->add_option_group("source", "Exactly one of");
  source->add_option("--stack", recon_stack, "Stack folder to upload (stack.json + frames)")
      ->check(CLI::ExistingDirectory);
  source->add_option("--scan-id", recon_scan_id, "A stored scan (JobResult.scan_id)");
  source->require_option(1);
  recon_cmd->add_option("--out", recon_out, "Folder for the results")->required();
  recon_flags.Add(recon_cmd);
  recon_cmd->add_option("--label", label, "Free text kept with the job");
  recon_cmd->add_option("--request-id", request_id, "Idempotency key");

  // jobs
  auto* jobs_cmd = app.add_subcommand("jobs", "List jobs, newest first");
  std::string kind_filter, state_filter;
  int limit = 20;
  jobs_cmd->add_option("--kind", kind_filter, "calibrate, scan or reconstruct")
      ->check(CLI::IsMember(Keys(Kinds()), CLI::ignore_case));
  jobs_cmd->add_option("--state", state_filter, "queued, running, succeeded, failed or cancelled")
      ->check(CLI::IsMember(Keys(States()), CLI::ignore_case));
  jobs_cmd->add_option("--limit", limit, "At most this many jobs")->capture_default_str()->check(CLI::Range(1, 100000));

  // watch
  auto* watch_cmd = app.add_subcommand("watch", "Re-attach to a job and follow it to its end");
  std::string job_id;
  std::string watch_out;
  watch_cmd->add_option("job_id", job_id, "Job id")->required();
  watch_cmd->add_option("--out", watch_out, "Also download the results into this folder");
  watch_cmd->add_flag("--include-stack", include_stack, "With --out: also the raw stack as stack.zip");

  // cancel
  auto* cancel_cmd = app.add_subcommand("cancel", "Cancel a queued or running job");
  cancel_cmd->add_option("job_id", job_id, "Job id")->required();

  // download
  auto* download_cmd = app.add_subcommand("download", "Download an artifact to a file, or a job's results to a folder");
  std::string download_id, download_out;
  bool resume = false;
  download_cmd->add_option("id", download_id, "Artifact id or job id")->required();
  download_cmd->add_option("--out", download_out, "Artifact: file (or existing folder); job: folder")->required();
  download_cmd->add_flag("--resume", resume, "Continue a partial download (FILE.part)");
  download_cmd->add_flag("--include-stack", include_stack, "Job id: also the raw stack as stack.zip");

  // calibrate
  auto* calibrate_cmd = app.add_subcommand("calibrate", "Run calibration steps on the rig (all when none given)");
  std::vector<std::string> steps;
  calibrate_cmd->add_option("--step", steps, "Repeatable: " + [] {
    std::string s;
    for (const auto& k : Keys(Steps())) s += (s.empty() ? "" : ", ") + k;
    return s;
  }())->check(CLI::IsMember(Keys(Steps()), CLI::ignore_case));
  calibrate_cmd->add_option("--label", label, "Free text kept with the job");
  calibrate_cmd->add_option("--request-id", request_id, "Idempotency key");

  // calibration show / list
  auto* calibration_cmd = app.add_subcommand("calibration", "Calibration bundles kept by the server");
  calibration_cmd->require_subcommand(1);
  auto* cal_show_cmd = calibration_cmd->add_subcommand("show", "One bundle (default: the active one)");
  std::string calibration_id;
  cal_show_cmd->add_option("id", calibration_id, "Calibration id");
  auto* cal_list_cmd = calibration_cmd->add_subcommand("list", "All bundles");

  // reset
  auto* reset_cmd = app.add_subcommand("reset", "Reconnect the rig's devices after an error");

  // specimen list / set
  auto* specimen_cmd = app.add_subcommand("specimen", "Simulated rig only: the specimen under the objective");
  specimen_cmd->require_subcommand(1);
  auto* spec_list_cmd = specimen_cmd->add_subcommand("list", "Built-in specimens and the current one");
  auto* spec_set_cmd = specimen_cmd->add_subcommand("set", "Load a specimen (name or file:/path/scene.json)");
  std::string specimen;
  spec_set_cmd->add_option("name", specimen, "Specimen")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? kExitOk : kExitUsage;
  }
  out.tty = !out.json && isatty(STDOUT_FILENO) == 1;

  if (!token_file.empty()) {
    if (std::string err = ReadToken(token_file, &client_options.auth_token); !err.empty()) {
      std::cerr << "inspectctl: INVALID_ARGUMENT: " << err << '\n';
      return kExitUsage;
    }
  }
  InspectionClient client(client_options);
  if (grpc::Status s = client.WaitConnected(); !s.ok()) {
    std::cerr << "inspectctl: " << CodeName(s.error_code()) << ": " << s.error_message() << '\n';
    return s.error_code() == grpc::StatusCode::UNAVAILABLE ? kExitUnreachable : kExitUsage;
  }

  ProgressPrinter printer(out);

  if (status_cmd->parsed() || reset_cmd->parsed()) {
    v1::RigStatus rig;
    grpc::Status s = status_cmd->parsed() ? client.GetRigStatus(&rig) : client.ResetRig(&rig);
    if (!s.ok()) return ReportError(s);
    if (out.json) {
      PrintJsonLine(ProtoJson(rig));
      return kExitOk;
    }
    std::cout << "state: " << Lower(Short(v1::RigState_Name(rig.state()), "RIG_STATE_"));
    if (!rig.state_detail().empty()) std::cout << " (" << rig.state_detail() << ")";
    std::cout << '\n';
    for (const auto& d : rig.devices()) {
      std::cout << Format("  %-9s %-12s %s %s %s", d.role().c_str(), d.driver().c_str(), d.model().c_str(),
                          d.serial().c_str(), d.connected() ? "connected" : "DISCONNECTED");
      if (!d.detail().empty()) std::cout << " - " << d.detail();
      std::cout << '\n';
    }
    std::cout << "calibration: " << (rig.active_calibration_id().empty() ? "none" : rig.active_calibration_id())
              << '\n';
    std::cout << "running job: " << (rig.running_job_id().empty() ? "none" : rig.running_job_id()) << ", queue "
              << rig.queued_jobs() << "/" << rig.queue_capacity() << '\n';
    if (rig.simulated()) std::cout << "simulated rig, specimen: " << rig.specimen() << '\n';
    const auto& d = rig.scan_defaults();
    std::cout << Format("pixel size: %.4f um; scan defaults: z %.1f .. %.1f um step %.2f um, exposure %.0f us\n",
                        rig.pixel_size_um(), d.z_start_um(), d.z_end_um(), d.z_step_um(), d.exposure_us());
    std::cout << "server version: " << rig.server_version() << '\n';
    return kExitOk;
  }

  if (scan_cmd->parsed()) {
    v1::ScanRequest request;
    request.set_request_id(request_id);
    request.set_label(label);
    if (z_start_um || z_end_um || z_step_um) {
      // A partial range is completed from the rig's defaults; all unset leaves them to the server.
      v1::ScanDefaults defaults;
      if (!(z_start_um && z_end_um && z_step_um)) {
        v1::RigStatus rig;
        if (grpc::Status s = client.GetRigStatus(&rig); !s.ok()) return ReportError(s);
        defaults = rig.scan_defaults();
      }
      request.set_z_start_um(z_start_um.value_or(defaults.z_start_um()));
      request.set_z_end_um(z_end_um.value_or(defaults.z_end_um()));
      request.set_z_step_um(z_step_um.value_or(defaults.z_step_um()));
    }
    if (exposure_us) request.set_exposure_us(*exposure_us);
    static const std::map<std::string, v1::IlluminationMode> kModes = {
        {"std", v1::ILLUMINATION_MODE_STD},           {"hdr", v1::ILLUMINATION_MODE_HDR},
        {"adapt-it", v1::ILLUMINATION_MODE_ADAPT_IT}, {"adapt", v1::ILLUMINATION_MODE_ADAPT},
        {"texture", v1::ILLUMINATION_MODE_TEXTURE},   {"hf+adapt", v1::ILLUMINATION_MODE_HF_ADAPT},
        {"adapted-hf", v1::ILLUMINATION_MODE_ADAPTED_HF}};
    if (!illumination.empty()) request.set_illumination(kModes.at(illumination));
    v1::IlluminationParameters* ip = request.mutable_illumination_parameters();
    if (hdr_exposures) ip->set_hdr_exposures(*hdr_exposures);
    if (adapt_lambda) ip->set_lambda(*adapt_lambda);
    if (texture_gamma) ip->set_gamma(*texture_gamma);
    if (hf_psi) ip->set_psi(*hf_psi);
    if (max_iterations) ip->set_max_iterations(*max_iterations);
    if (target_grey) ip->set_target_grey(*target_grey);
    *request.mutable_reconstruction() = scan_flags.ToProto();
    FollowOutcome outcome = Follow(printer, [&](const EventCallback& cb, v1::Job* job) {
      return client.Scan(request, cb, job);
    });
    return FinishJob(client, out, printer, outcome, fs::path(scan_out), include_stack);
  }

  if (recon_cmd->parsed()) {
    v1::ReconstructStart start;
    start.set_request_id(request_id);
    start.set_label(label);
    *start.mutable_options() = recon_flags.ToProto();
    FollowOutcome outcome;
    if (!recon_scan_id.empty()) {
      start.set_scan_id(recon_scan_id);
      outcome = Follow(printer, [&](const EventCallback& cb, v1::Job* job) {
        return client.ReconstructStored(start, cb, job);
      });
    } else {
      outcome = Follow(printer, [&](const EventCallback& cb, v1::Job* job) {
        return client.ReconstructUpload(recon_stack, start, cb, job, [&](int64_t done, int64_t total) {
          printer.OnBytes("upload", done, total);
        });
      });
    }
    return FinishJob(client, out, printer, outcome, fs::path(recon_out), false);
  }

  if (watch_cmd->parsed()) {
    FollowOutcome outcome = Follow(printer, [&](const EventCallback& cb, v1::Job* job) {
      return client.Watch(job_id, cb, job);
    });
    std::optional<fs::path> dir;
    if (!watch_out.empty()) dir = fs::path(watch_out);
    return FinishJob(client, out, printer, outcome, dir, include_stack);
  }

  if (calibrate_cmd->parsed()) {
    v1::CalibrateRequest request;
    request.set_request_id(request_id);
    request.set_label(label);
    for (const auto& s : steps) request.add_steps(Steps().at(Lower(s)));
    FollowOutcome outcome = Follow(printer, [&](const EventCallback& cb, v1::Job* job) {
      return client.Calibrate(request, cb, job);
    });
    return FinishJob(client, out, printer, outcome, std::nullopt, false);
  }

  if (jobs_cmd->parsed()) {
    v1::ListJobsRequest request;
    if (!kind_filter.empty()) request.set_kind(Kinds().at(Lower(kind_filter)));
    if (!state_filter.empty()) request.set_state(States().at(Lower(state_filter)));
    v1::ListJobsResponse all;
    do {
      request.set_page_size(std::min(limit - all.jobs_size(), 500));
      v1::ListJobsResponse page;
      if (grpc::Status s = client.ListJobs(request, &page); !s.ok()) return ReportError(s);
      for (auto& j : *page.mutable_jobs()) {
        if (all.jobs_size() < limit) *all.add_jobs() = std::move(j);
      }
      all.set_next_page_token(page.next_page_token());
      request.set_page_token(page.next_page_token());
    } while (!request.page_token().empty() && all.jobs_size() < limit);
    if (out.json) {
      PrintJsonLine(ProtoJson(all));
      return kExitOk;
    }
    for (const auto& j : all.jobs()) std::cout << JobLine(j) << '\n';
    if (all.jobs_size() == 0 && !out.quiet) std::cout << "no jobs\n";
    return kExitOk;
  }

  if (cancel_cmd->parsed()) {
    v1::Job job;
    if (grpc::Status s = client.CancelJob(job_id, &job); !s.ok()) return ReportError(s);
    if (out.json) {
      PrintJsonLine(ProtoJson(job));
    } else {
      std::cout << JobLine(job) << '\n';
    }
    return kExitOk;
  }

  if (download_cmd->parsed()) {
    v1::Job job;
    grpc::Status s = client.GetJob(download_id, &job);
    std::vector<fs::path> written;
    if (s.ok()) {
      if (job.state() != v1::JOB_STATE_SUCCEEDED) {
        return ReportError({grpc::StatusCode::FAILED_PRECONDITION,
                            "job " + download_id + " is " + Lower(Short(v1::JobState_Name(job.state()), "JOB_STATE_")) +
                                "; only a succeeded job has results"});
      }
      s = FetchResults(client, job, download_out, include_stack, resume, printer, &written);
    } else if (s.error_code() == grpc::StatusCode::NOT_FOUND) {
      fs::path dest(download_out);
      std::error_code ec;
      if (fs::is_directory(dest, ec)) dest /= download_id;
      s = client.DownloadArtifact(download_id, dest, resume, [&](int64_t done, int64_t total) {
        printer.OnBytes(download_id, done, total);
      });
      printer.Finish();
      if (s.error_code() == grpc::StatusCode::NOT_FOUND) {
        s = grpc::Status(grpc::StatusCode::NOT_FOUND, "no job or artifact with id " + download_id);
      }
      if (s.ok()) written.push_back(dest);
    }
    if (!s.ok()) return ReportError(s);
    if (out.json) {
      json j = {{"type", "result"}, {"files", json::array()}, {"exit_code", kExitOk}};
      for (const auto& p : written) j["files"].push_back(fs::absolute(p).string());
      PrintJsonLine(j);
    } else {
      for (const auto& p : written) std::cout << fs::absolute(p).string() << '\n';
    }
    return kExitOk;
  }

  if (cal_show_cmd->parsed()) {
    v1::Calibration cal;
    if (grpc::Status s = client.GetCalibration(calibration_id, &cal); !s.ok()) return ReportError(s);
    if (out.json) {
      PrintJsonLine(ProtoJson(cal));
      return kExitOk;
    }
    std::cout << "calibration " << cal.calibration_id() << (cal.active() ? " (active)" : "") << '\n';
    std::cout << "  created " << TimeText(cal.create_time()) << ", format version " << cal.version() << ", job "
              << cal.job_id() << '\n';
    PrintFigures(cal.summary(), "  ");
    return kExitOk;
  }

  if (cal_list_cmd->parsed()) {
    v1::ListCalibrationsResponse list;
    if (grpc::Status s = client.ListCalibrations(&list); !s.ok()) return ReportError(s);
    if (out.json) {
      PrintJsonLine(ProtoJson(list));
      return kExitOk;
    }
    for (const auto& cal : list.calibrations()) {
      std::cout << cal.calibration_id() << (cal.active() ? " (active)" : "") << "  " << TimeText(cal.create_time())
                << "  job " << cal.job_id() << '\n';
      PrintFigures(cal.summary(), "    ");
    }
    if (list.calibrations_size() == 0 && !out.quiet) std::cout << "no calibrations\n";
    return kExitOk;
  }

  if (spec_list_cmd->parsed() || spec_set_cmd->parsed()) {
    v1::ListSpecimensResponse list;
    grpc::Status s = spec_list_cmd->parsed() ? client.ListSpecimens(&list) : client.SetSpecimen(specimen, &list);
    if (!s.ok()) return ReportError(s);
    if (out.json) {
      PrintJsonLine(ProtoJson(list));
      return kExitOk;
    }
    for (const auto& name : list.specimens()) std::cout << (name == list.current() ? "* " : "  ") << name << '\n';
    if (list.current().rfind("file:", 0) == 0) std::cout << "* " << list.current() << '\n';
    return kExitOk;
  }
  return kExitUsage;
}

}  // namespace
}  // namespace inspection::client

int main(int argc, char** argv) { return inspection::client::Main(argc, argv); }
