// inspectctl jobs / watch / cancel / delete / pin / download: list jobs, re-attach to one, cancel
// one, delete or pin one (data lifecycle), fetch results or one artifact (docs/inspectctl.md).
#include <algorithm>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "client_cli/commands.h"
#include "client_cli/follow.h"

namespace inspection::client::cli {
namespace {

namespace fs = std::filesystem;

const std::map<std::string, v1::JobKind>& Kinds() {
  static const std::map<std::string, v1::JobKind> m = {
      {"calibrate", v1::JOB_KIND_CALIBRATE}, {"scan", v1::JOB_KIND_SCAN}, {"reconstruct", v1::JOB_KIND_RECONSTRUCT},
      {"study", v1::JOB_KIND_STUDY},         {"verify", v1::JOB_KIND_VERIFY}};
  return m;
}

const std::map<std::string, v1::JobState>& States() {
  static const std::map<std::string, v1::JobState> m = {
      {"queued", v1::JOB_STATE_QUEUED}, {"running", v1::JOB_STATE_RUNNING},     {"succeeded", v1::JOB_STATE_SUCCEEDED},
      {"failed", v1::JOB_STATE_FAILED}, {"cancelled", v1::JOB_STATE_CANCELLED},
  };
  return m;
}

// One job per line: id, kind, state, creation time, then what matters for its state.
std::string JobLine(const v1::Job& job) {
  std::string line = Format(
      "%-24s %-12s %-10s %-20s", job.job_id().c_str(), Lower(Short(v1::JobKind_Name(job.kind()), "JOB_KIND_")).c_str(),
      Lower(Short(v1::JobState_Name(job.state()), "JOB_STATE_")).c_str(), TimeText(job.create_time()).c_str());
  if (job.state() == v1::JOB_STATE_QUEUED && job.queue_position() > 0)
    line += Format(" queue#%d", job.queue_position());
  if (!job.label().empty()) line += " label=" + job.label();
  if (job.pinned()) line += " pinned";
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

struct JobsFlags {
  std::string kind, state;
  int limit = 20;
};

int RunJobs(const JobsFlags& f, Session& session) {
  v1::ListJobsRequest request;
  if (!f.kind.empty()) request.set_kind(Kinds().at(Lower(f.kind)));
  if (!f.state.empty()) request.set_state(States().at(Lower(f.state)));
  v1::ListJobsResponse all;
  do {
    request.set_page_size(std::min(f.limit - all.jobs_size(), 500));
    v1::ListJobsResponse page;
    if (grpc::Status s = session.client.ListJobs(request, &page); !s.ok()) return ReportError(s);
    for (auto& j : *page.mutable_jobs()) {
      if (all.jobs_size() < f.limit) *all.add_jobs() = std::move(j);
    }
    all.set_next_page_token(page.next_page_token());
    request.set_page_token(page.next_page_token());
  } while (!request.page_token().empty() && all.jobs_size() < f.limit);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(all));
    return kExitOk;
  }
  for (const auto& j : all.jobs()) std::cout << JobLine(j) << '\n';
  if (all.jobs_size() == 0 && !session.out.quiet) std::cout << "no jobs\n";
  return kExitOk;
}

struct WatchFlags {
  std::string job_id, out_dir;
  bool include_stack = false;
};

int RunWatch(const WatchFlags& f, Session& session) {
  FollowOutcome outcome = Follow(
      session.printer, [&](const EventCallback& cb, v1::Job* job) { return session.client.Watch(f.job_id, cb, job); });
  std::optional<fs::path> dir;
  if (!f.out_dir.empty()) dir = fs::path(f.out_dir);
  return FinishJob(session.client, session.out, session.printer, outcome, dir, f.include_stack);
}

int RunCancel(const std::string& job_id, Session& session) {
  v1::Job job;
  if (grpc::Status s = session.client.CancelJob(job_id, &job); !s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(job));
  } else {
    std::cout << JobLine(job) << '\n';
  }
  return kExitOk;
}

struct DeleteFlags {
  std::string id;
  bool scan_only = false;
};

int RunDelete(const DeleteFlags& f, Session& session) {
  v1::DeleteResponse deleted;
  const grpc::Status s =
      f.scan_only ? session.client.DeleteScan(f.id, &deleted) : session.client.DeleteJob(f.id, &deleted);
  if (!s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(deleted));
  } else {
    std::cout << (f.scan_only ? "deleted the stack of scan " : "deleted job ") << deleted.id() << ": "
              << deleted.bytes_freed() << " bytes, " << deleted.artifacts_deleted() << " artifacts\n";
  }
  return kExitOk;
}

struct PinFlags {
  std::string id;
  bool unpin = false;
};

int RunPin(const PinFlags& f, Session& session) {
  v1::PinJobResponse pinned;
  if (grpc::Status s = session.client.PinJob(f.id, !f.unpin, &pinned); !s.ok()) return ReportError(s);
  if (session.out.json) {
    PrintJsonLine(ProtoJson(pinned));
  } else {
    std::cout << "job " << pinned.job_id() << (pinned.pinned() ? " pinned" : " unpinned") << '\n';
  }
  return kExitOk;
}

struct DownloadFlags {
  std::string id, out;
  bool resume = false;
  bool include_stack = false;
};

// The id names a job (all its results into a folder) or else an artifact (one file).
int RunDownload(const DownloadFlags& f, Session& session) {
  v1::Job job;
  grpc::Status s = session.client.GetJob(f.id, &job);
  std::vector<fs::path> written;
  if (s.ok()) {
    if (job.state() != v1::JOB_STATE_SUCCEEDED) {
      return ReportError({grpc::StatusCode::FAILED_PRECONDITION,
                          "job " + f.id + " is " + Lower(Short(v1::JobState_Name(job.state()), "JOB_STATE_")) +
                              "; only a succeeded job has results"});
    }
    s = FetchResults(session.client, job, f.out, f.include_stack, f.resume, session.printer, &written);
  } else if (s.error_code() == grpc::StatusCode::NOT_FOUND) {
    fs::path dest(f.out);
    std::error_code ec;
    if (fs::is_directory(dest, ec)) dest /= f.id;
    s = session.client.DownloadArtifact(
        f.id, dest, f.resume, [&](int64_t done, int64_t total) { session.printer.OnBytes(f.id, done, total); });
    session.printer.Finish();
    if (s.error_code() == grpc::StatusCode::NOT_FOUND) {
      s = grpc::Status(grpc::StatusCode::NOT_FOUND, "no job or artifact with id " + f.id);
    }
    if (s.ok()) written.push_back(dest);
  }
  if (!s.ok()) return ReportError(s);
  if (session.out.json) {
    json j = {{"type", "result"}, {"files", json::array()}, {"exit_code", kExitOk}};
    for (const auto& p : written) j["files"].push_back(fs::absolute(p).string());
    PrintJsonLine(j);
  } else {
    for (const auto& p : written) std::cout << fs::absolute(p).string() << '\n';
  }
  return kExitOk;
}

}  // namespace

void RegisterJobCommands(CLI::App& app, CliContext& context) {
  auto* jobs_cmd = app.add_subcommand("jobs", "List jobs, newest first");
  auto jobs = std::make_shared<JobsFlags>();
  jobs_cmd->add_option("--kind", jobs->kind, "calibrate, scan or reconstruct")
      ->check(CLI::IsMember(Keys(Kinds()), CLI::ignore_case));
  jobs_cmd->add_option("--state", jobs->state, "queued, running, succeeded, failed or cancelled")
      ->check(CLI::IsMember(Keys(States()), CLI::ignore_case));
  jobs_cmd->add_option("--limit", jobs->limit, "At most this many jobs")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  context.AddCommand(jobs_cmd, [jobs](Session& session) { return RunJobs(*jobs, session); });

  auto* watch_cmd = app.add_subcommand("watch", "Re-attach to a job and follow it to its end");
  auto watch = std::make_shared<WatchFlags>();
  watch_cmd->add_option("job_id", watch->job_id, "Job id")->required();
  watch_cmd->add_option("--out", watch->out_dir, "Also download the results into this folder");
  watch_cmd->add_flag("--include-stack", watch->include_stack, "With --out: also the raw stack as stack.zip");
  context.AddCommand(watch_cmd, [watch](Session& session) { return RunWatch(*watch, session); });

  auto* cancel_cmd = app.add_subcommand("cancel", "Cancel a queued or running job");
  auto cancel_job_id = std::make_shared<std::string>();
  cancel_cmd->add_option("job_id", *cancel_job_id, "Job id")->required();
  context.AddCommand(cancel_cmd, [cancel_job_id](Session& session) { return RunCancel(*cancel_job_id, session); });

  auto* delete_cmd = app.add_subcommand("delete", "Delete a finished job, its artifacts and stored stack (admin)");
  auto del = std::make_shared<DeleteFlags>();
  delete_cmd->add_option("job_id", del->id, "Job id (with --scan-only: the scan id)")->required();
  delete_cmd->add_flag("--scan-only", del->scan_only,
                       "delete only the scan's raw stack; keep the job and depth results");
  context.AddCommand(delete_cmd, [del](Session& session) { return RunDelete(*del, session); });

  auto* pin_cmd = app.add_subcommand("pin", "Pin a job so retention never deletes it (admin)");
  auto pin = std::make_shared<PinFlags>();
  pin_cmd->add_option("job_id", pin->id, "Job id")->required();
  pin_cmd->add_flag("--unpin", pin->unpin, "remove the pin");
  context.AddCommand(pin_cmd, [pin](Session& session) { return RunPin(*pin, session); });

  auto* download_cmd = app.add_subcommand("download", "Download an artifact to a file, or a job's results to a folder");
  auto download = std::make_shared<DownloadFlags>();
  download_cmd->add_option("id", download->id, "Artifact id or job id")->required();
  download_cmd->add_option("--out", download->out, "Artifact: file (or existing folder); job: folder")->required();
  download_cmd->add_flag("--resume", download->resume, "Continue a partial download (FILE.part)");
  download_cmd->add_flag("--include-stack", download->include_stack, "Job id: also the raw stack as stack.zip");
  context.AddCommand(download_cmd, [download](Session& session) { return RunDownload(*download, session); });
}

}  // namespace inspection::client::cli
