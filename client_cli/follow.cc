// Following a job to its end: Ctrl-C detaching, the outcome's exit code, results and summary
// (docs/inspectctl.md "Progress display", "Exit codes", "JSON output").
#include "client_cli/follow.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstring>
#include <iostream>

namespace inspection::client::cli {
namespace {

namespace fs = std::filesystem;

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
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;

 private:
  struct sigaction previous_ {};
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
    *error = outcome.status.ok() ? grpc::Status(static_cast<grpc::StatusCode>(job.error_code()), job.error_message())
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
  PrintErrorLine(*error);
  return code;
}

}  // namespace

FollowOutcome Follow(ProgressPrinter& printer, const FollowCall& call) {
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

grpc::Status FetchResults(InspectionClient& client, const v1::Job& job, const fs::path& dir, bool include_stack,
                          bool resume, ProgressPrinter& printer, std::vector<fs::path>* written) {
  grpc::Status s = client.DownloadResults(
      job, dir, include_stack, written, resume,
      [&](const std::string& name, int64_t done, int64_t total) { printer.OnBytes(name, done, total); });
  printer.Finish();
  return s;
}

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
  if (job.result().has_inspection()) PrintInspection(job.result().inspection());
  if (job.kind() == v1::JOB_KIND_CALIBRATE) {
    std::cout << "calibration: " << job.result().calibration_id() << '\n';
    PrintFigures(job.result().calibration(), "  ");
  }
  return kExitOk;
}

}  // namespace inspection::client::cli
