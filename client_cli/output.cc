// inspectctl output: exit codes, error lines, JSON Lines, summaries and the progress display
// (docs/inspectctl.md "Progress display", "Exit codes", "JSON output").
#include "client_cli/output.h"

#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/time_util.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdarg>
#include <cstdio>
#include <iostream>
#include <map>

namespace inspection::client::cli {

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

std::string Short(const std::string& enum_name, const std::string& prefix) {
  return enum_name.rfind(prefix, 0) == 0 ? enum_name.substr(prefix.size()) : enum_name;
}

std::string VerificationStateText(v1::VerificationState state) {
  switch (state) {
    case v1::VERIFICATION_STATE_VERIFIED:
      return "verified";
    case v1::VERIFICATION_STATE_DUE:
      return "verification due";
    case v1::VERIFICATION_STATE_FAILED:
      return "verification failed";
    default:
      return "unknown";
  }
}

const char* CodeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK:
      return "OK";
    case grpc::StatusCode::CANCELLED:
      return "CANCELLED";
    case grpc::StatusCode::UNKNOWN:
      return "UNKNOWN";
    case grpc::StatusCode::INVALID_ARGUMENT:
      return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND:
      return "NOT_FOUND";
    case grpc::StatusCode::ALREADY_EXISTS:
      return "ALREADY_EXISTS";
    case grpc::StatusCode::PERMISSION_DENIED:
      return "PERMISSION_DENIED";
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::FAILED_PRECONDITION:
      return "FAILED_PRECONDITION";
    case grpc::StatusCode::ABORTED:
      return "ABORTED";
    case grpc::StatusCode::OUT_OF_RANGE:
      return "OUT_OF_RANGE";
    case grpc::StatusCode::UNIMPLEMENTED:
      return "UNIMPLEMENTED";
    case grpc::StatusCode::INTERNAL:
      return "INTERNAL";
    case grpc::StatusCode::UNAVAILABLE:
      return "UNAVAILABLE";
    case grpc::StatusCode::DATA_LOSS:
      return "DATA_LOSS";
    case grpc::StatusCode::UNAUTHENTICATED:
      return "UNAUTHENTICATED";
    default:
      return "UNKNOWN";
  }
}

std::string TimeText(const google::protobuf::Timestamp& t) {
  if (t.seconds() == 0 && t.nanos() == 0) return "-";
  google::protobuf::Timestamp whole = t;
  whole.set_nanos(0);  // seconds are enough for people
  return google::protobuf::util::TimeUtil::ToString(whole);
}

void PrintErrorLine(const grpc::Status& status) {
  std::cerr << "inspectctl: " << CodeName(status.error_code()) << ": " << status.error_message() << '\n';
}

int ExitCodeFor(const grpc::Status& status) {
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE) return kExitUnreachable;
  if (status.error_code() == grpc::StatusCode::DATA_LOSS) return kExitIntegrity;
  if (status.error_code() == grpc::StatusCode::CANCELLED) return kExitCancelled;
  return kExitFailed;
}

int ReportError(const grpc::Status& status) {
  PrintErrorLine(status);
  return ExitCodeFor(status);
}

json ProtoJson(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string text;
  if (!google::protobuf::util::MessageToJsonString(message, &text, options).ok()) return json::object();
  return json::parse(text, nullptr, false);
}

void PrintJsonLine(const json& j) { std::cout << j.dump() << '\n' << std::flush; }

void PrintAlignment(const v1::DepthSummary& d) {
  // Never silent: whatever ran (also none, and why the default fell back to it), how the
  // transforms were found and each frame's transform, applied or (still stack) not.
  if (d.alignment() == v1::FRAME_ALIGNMENT_UNSPECIFIED) return;
  const v1::AlignmentDetail& a = d.alignment_detail();
  if (d.alignment() == v1::FRAME_ALIGNMENT_NONE) {
    std::cout << "alignment: none";
    if (!a.fallback_reason().empty()) std::cout << " (the default fell back to none: " << a.fallback_reason() << ')';
    std::cout << '\n';
    return;
  }
  const char* name = d.alignment() == v1::FRAME_ALIGNMENT_ESTIMATE ? "estimate" : "calibrated";
  const std::string method = a.method().empty() ? std::string() : ", method " + a.method();
  if (a.still()) {
    std::cout << Format("alignment: %s%s, still: frames used as captured (measured scale change up to %.3f %%, "
                        "shift up to %.2f px",
                        name, method.c_str(), d.alignment_max_scale_change_percent(), d.alignment_max_shift_px());
    if (a.still_threshold() > 0.0) {
      std::cout << Format(", corner motion %.2f px, still statistic %.2f against %.2f", a.max_corner_displacement_px(),
                          a.still_statistic(), a.still_threshold());
    }
    std::cout << ")\n";
  } else {
    std::cout << Format("alignment: %s, scale change up to %.2f %%, shift up to %.2f px, seen by every frame %.1f %%%s\n",
                        name, d.alignment_max_scale_change_percent(), d.alignment_max_shift_px(),
                        d.alignment_seen_percent(), method.c_str());
  }
  if (!a.decision().empty()) std::cout << "  why: " << a.decision() << '\n';
  for (const v1::FrameTransform& f : a.frames()) {
    std::cout << Format("  frame %d%s: scale %.5f, rotation %.4f deg, shift %.2f, %.2f px\n", f.frame(),
                        f.frame() == a.reference_frame() ? " (reference)" : "", f.scale(), f.rotation_deg(),
                        f.shift_x_px(), f.shift_y_px());
  }
}

void PrintDepthSummary(const v1::DepthSummary& d) {
  // pixel_size_um 0: the stack had no scale (an image folder without --pixel-size).
  const std::string scale =
      d.pixel_size_um() > 0.0 ? Format("%.3f um/px", d.pixel_size_um()) : std::string("lateral scale unknown");
  std::cout << Format("depth: %dx%d px (%s), %d frames, valid %.1f %%, z %.2f .. %.2f um", d.width(), d.height(),
                      scale.c_str(), d.frame_count(), d.valid_percent(), d.z_min_um(), d.z_max_um());
  if (d.engine_seconds() > 0.0) std::cout << Format(", engine %.3f s", d.engine_seconds());
  std::cout << '\n';
  // Scans: the mode that ran and, for AUTO, why; the integral methods with their figures.
  if (!d.illumination().empty()) {
    std::cout << "illumination: " << d.illumination();
    if (!d.illumination_decision().empty()) std::cout << " (" << d.illumination_decision() << ')';
    std::cout << '\n';
  }
  if (d.has_z_range_search()) {  // automatic z range: the range chosen and what it cost
    const v1::ZRangeSearchResult& z = d.z_range_search();
    std::cout << Format(
        "z range: automatic, %.2f .. %.2f um (focus found at %.2f .. %.2f um, margin %.2f um); "
        "%d coarse frames over %.2f .. %.2f um at %.2f um%s%s, %.2f s\n",
        z.z_start_um(), z.z_end_um(), z.focus_low_um(), z.focus_high_um(), z.margin_um(), z.coarse_frame_count(),
        z.window_start_um(), z.window_end_um(), z.coarse_step_um(),
        z.stopped_early() ? Format(" (stopped early: %.1f %% of the field past focus)", z.settled_percent()).c_str()
                          : "",
        z.refine_frame_count() > 0 ? Format(", %d refining its ends", z.refine_frame_count()).c_str() : "",
        z.search_seconds());
  }
  if (d.method() != v1::RECONSTRUCTION_METHOD_UNSPECIFIED && d.method() != v1::RECONSTRUCTION_METHOD_SFF) {
    std::cout << "method: "
              << v1::ReconstructionMethod_Name(d.method()).substr(std::string("RECONSTRUCTION_METHOD_").size());
    if (d.method() == v1::RECONSTRUCTION_METHOD_ISFF_FAST)
      std::cout << Format(", threshold %.2f", d.isff_fast_threshold());
    std::cout << Format(", frames searched %.0f %%", 100.0 * d.frames_searched_fraction()) << '\n';
  }
  PrintAlignment(d);
  if (d.consistency_rejected_percent() > 0.0 || d.filled_percent() > 0.0) {
    std::cout << Format("post-processing: %.1f %% rejected by the depth consistency check, %.1f %% filled\n",
                        d.consistency_rejected_percent(), d.filled_percent());
  }
  if (d.halo_candidate_percent() > 0.0 || d.halo_reassigned_percent() > 0.0) {
    std::cout << Format("halo suppression: %.1f %% of the pixels re-examined near depth jumps, %.1f %% moved to the "
                        "surface behind\n",
                        d.halo_candidate_percent(), d.halo_reassigned_percent());
  }
  // Which depth the files hold, and why: inferred depth must not pass for measured.
  if (d.dense_depth()) {
    std::cout << Format("depth: dense (%s): %.1f %% of the pixels inferred (confidence below the threshold, hatched "
                        "in depth_preview.png), the rest measured; --dense off for measured pixels only\n",
                        d.dense_depth_decision().c_str(), d.filled_percent());
  } else if (!d.dense_depth_decision().empty()) {
    std::cout << "depth: measured pixels only (" << d.dense_depth_decision()
              << "); --dense on for a value at every pixel\n";
  }
  if (d.has_ground_truth()) {
    std::cout << Format("vs ground truth: RMSE %.3f um, mean |error| %.3f um\n", d.rmse_um(), d.mean_abs_error_um());
  }
}

void PrintInspection(const v1::InspectionResult& r) {
  auto verdict = [](v1::Verdict v) { return Short(v1::Verdict_Name(v), "VERDICT_"); };
  std::cout << "inspection: recipe " << r.recipe_id() << " v" << r.recipe_version();
  if (!r.part_id().empty()) std::cout << ", part " << r.part_id();
  if (!r.station().empty()) std::cout << ", station " << r.station();
  std::cout << ": " << verdict(r.verdict()) << '\n';
  for (const v1::MeasurementResult& m : r.measurements()) {
    std::cout << Format("  %-16s %-12s ", m.name().c_str(), m.parameter().c_str());
    if (m.measured()) {
      std::cout << Format("%.4g %s  U %.2g  coverage %.1f %%  ", m.value(), m.unit().c_str(), m.expanded_uncertainty(),
                          m.coverage_percent());
    } else {
      std::cout << "not measured  ";
    }
    std::cout << verdict(m.verdict());
    if (m.verdict() != v1::VERDICT_OK) std::cout << " (" << m.reason() << ')';
    std::cout << '\n';
    if (!m.capability_warning().empty()) std::cout << "    warning: " << m.capability_warning() << '\n';
  }
  if (!r.verification_warning().empty()) std::cout << "  warning: " << r.verification_warning() << '\n';
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

// ---------------------------------------------------------------------------------------------
// Progress display

namespace {

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

}  // namespace

void ProgressPrinter::OnEvent(const v1::JobEvent& event) {
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

void ProgressPrinter::OnBytes(const std::string& what, int64_t done, int64_t total) {
  std::lock_guard<std::mutex> lock(mu_);
  if (out_.json || out_.quiet) return;
  const double fraction = total > 0 ? static_cast<double>(done) / static_cast<double>(total) : 0.0;
  // Only on a terminal: in logs the list of written files says enough.
  if (out_.tty) Redraw(Bar(fraction) + " " + what + " " + Megabytes(done) + " / " + Megabytes(total));
}

void ProgressPrinter::Finish() {
  std::lock_guard<std::mutex> lock(mu_);
  EndLine();
}

std::string ProgressPrinter::EventText(const v1::JobEvent& e, bool terminal) {
  std::string text;
  const bool frame = e.has_frame() && e.frame().frame_count() > 0;
  // On a terminal a frame line leaves out the phase to fit 80 columns when it is acquiring (the
  // automatic z range's FOCUS_SEARCH frames keep it).
  if (e.state() >= v1::JOB_STATE_SUCCEEDED) {
    text = Short(v1::JobState_Name(e.state()), "JOB_STATE_");
  } else if (!(frame && terminal) || e.phase() == v1::JOB_PHASE_FOCUS_SEARCH) {
    text = Short(v1::JobPhase_Name(e.phase()), "JOB_PHASE_");
  }
  if (frame) {
    const auto& f = e.frame();
    const auto& s = f.statistics();
    if (!text.empty()) text += ' ';
    text += Format("%d/%d z=%.1fum mean=%.0f sd=%.0f sat=%.1f%% under=%.1f%%", f.frame_index() + 1, f.frame_count(),
                   f.z_um(), s.mean_grey(), s.stddev_grey(), s.saturated_percent(), s.underexposed_percent());
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

void ProgressPrinter::Redraw(std::string line) {
  const size_t width = static_cast<size_t>(TerminalWidth() - 1);
  if (line.size() > width) line.resize(width);
  std::cout << '\r' << line << "\x1b[K" << std::flush;
  line_open_ = true;
}

void ProgressPrinter::EndLine() {
  if (line_open_) std::cout << '\n' << std::flush;
  line_open_ = false;
}

}  // namespace inspection::client::cli
