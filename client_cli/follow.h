// Following a job to its end (scan, reconstruct, calibrate, watch): progress, Ctrl-C detaching
// (the job keeps running), the exit code of its outcome, then the result download and summary.
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "client_cli/inspection_client.h"
#include "client_cli/output.h"

namespace inspection::client::cli {

struct FollowOutcome {
  grpc::Status status;  // the stream's status
  v1::Job job;          // the final job, when the server reported one
  bool have_job = false;
};

// One InspectionClient call that starts or re-attaches to a job and follows its events.
using FollowCall = std::function<grpc::Status(const EventCallback& on_event, v1::Job* job)>;

// Runs `call` with its events shown by `printer`. While it runs, Ctrl-C stops following (exit
// 130 with the `inspectctl watch ID` hint) instead of cancelling the job.
FollowOutcome Follow(ProgressPrinter& printer, const FollowCall& call);

// Downloads a succeeded job's results into dir, with progress; *written receives the paths.
grpc::Status FetchResults(InspectionClient& client, const v1::Job& job, const std::filesystem::path& dir,
                          bool include_stack, bool resume, ProgressPrinter& printer,
                          std::vector<std::filesystem::path>* written);

// Common ending of scan / reconstruct / calibrate / watch: the error line and exit code of a
// job that did not succeed; else the results downloaded into out_dir (when given) and the
// summary (plain text, the folder alone with --quiet, or the JSON result object).
int FinishJob(InspectionClient& client, const Output& out, ProgressPrinter& printer, const FollowOutcome& outcome,
              const std::optional<std::filesystem::path>& out_dir, bool include_stack);

}  // namespace inspection::client::cli
