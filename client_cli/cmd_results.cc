// inspectctl results list|watch: the inspection results of recipe scans (docs/inspectctl.md "Results").
// `list` queries the stored results (filters, newest first, every page unless --limit);
// `watch` follows the result feed, one line (or JSON object) per finished inspection, and
// resumes after a reconnect with --after SEQUENCE (the last one printed).
#include <google/protobuf/util/time_util.h>

#include <iostream>

#include "client_cli/commands.h"

namespace inspection::client::cli {
namespace {

using google::protobuf::util::TimeUtil;

struct ResultListFlags {
  std::string part_id;
  std::string recipe_id;
  std::string verdict;  // ok | not-ok | not-decidable
  std::string since;    // RFC 3339
  std::string until;
  int limit = 0;  // 0 = every matching result
};

// One line per result: "42 2026-11-26T05:01:02Z part P-7 recipe pad-check v3: NOT_OK (job ...)"
void PrintResultLine(const v1::InspectionResult& r, const Output& out) {
  if (out.json) {
    PrintJsonLine(ProtoJson(r));
    return;
  }
  std::cout << r.sequence() << ' ' << TimeText(r.finish_time()) << " part " << (r.part_id().empty() ? "-" : r.part_id())
            << " recipe " << r.recipe_id() << " v" << r.recipe_version() << ": "
            << v1::Verdict_Name(r.verdict()).substr(8) << " (job " << r.job_id() << ')' << '\n';
}

int UsageError(const std::string& message) {
  PrintErrorLine(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, message));
  return kExitUsage;
}

bool ParseTime(const std::string& text, google::protobuf::Timestamp* t) {
  return !text.empty() && TimeUtil::FromString(text, t);
}

int RunList(const ResultListFlags& f, Session& session) {
  v1::ListResultsRequest request;
  request.set_part_id(f.part_id);
  request.set_recipe_id(f.recipe_id);
  if (f.verdict == "ok") request.set_verdict(v1::VERDICT_OK);
  if (f.verdict == "not-ok") request.set_verdict(v1::VERDICT_NOT_OK);
  if (f.verdict == "not-decidable") request.set_verdict(v1::VERDICT_NOT_DECIDABLE);
  if (!f.since.empty() && !ParseTime(f.since, request.mutable_finished_after())) {
    return UsageError("--since '" + f.since + "' is not an RFC 3339 time (e.g. 2026-11-26T05:00:00Z)");
  }
  if (!f.until.empty() && !ParseTime(f.until, request.mutable_finished_before())) {
    return UsageError("--until '" + f.until + "' is not an RFC 3339 time (e.g. 2026-11-26T06:00:00Z)");
  }
  int printed = 0;
  for (;;) {
    if (f.limit > 0) request.set_page_size(std::min(500, f.limit - printed));
    v1::ListResultsResponse page;
    if (grpc::Status s = session.client.ListResults(request, &page); !s.ok()) return ReportError(s);
    for (const v1::InspectionResult& r : page.results()) {
      PrintResultLine(r, session.out);
      ++printed;
    }
    if (page.next_page_token().empty() || (f.limit > 0 && printed >= f.limit)) break;
    request.set_page_token(page.next_page_token());
  }
  return kExitOk;
}

struct ResultWatchFlags {
  int64_t after = 0;
  int count = 0;  // 0 = until interrupted
  bool details = false;
};

int RunWatch(const ResultWatchFlags& f, Session& session) {
  int seen = 0;
  const grpc::Status s = session.client.WatchResults(f.after, [&](const v1::InspectionResult& r) {
    PrintResultLine(r, session.out);
    if (f.details && !session.out.json) PrintInspection(r);
    std::cout.flush();  // a pipe reader (an MES script) sees each result as it comes
    return f.count == 0 || ++seen < f.count;
  });
  if (!s.ok()) return ReportError(s);
  return kExitOk;
}

}  // namespace

void RegisterResultCommands(CLI::App& app, CliContext& context) {
  auto* results = app.add_subcommand("results", "Inspection results of recipe scans");
  results->require_subcommand(1);

  auto* list_cmd = results->add_subcommand("list", "Stored results, newest first (operator)");
  auto list = std::make_shared<ResultListFlags>();
  list_cmd->add_option("--part-id", list->part_id, "Only this part");
  list_cmd->add_option("--recipe", list->recipe_id, "Only this recipe id");
  list_cmd->add_option("--verdict", list->verdict, "Only this overall verdict")
      ->check(CLI::IsMember({"ok", "not-ok", "not-decidable"}));
  list_cmd->add_option("--since", list->since, "Finished at or after this time (RFC 3339)");
  list_cmd->add_option("--until", list->until, "Finished before this time (RFC 3339)");
  list_cmd->add_option("--limit", list->limit, "At most this many (default: all)")->check(CLI::Range(1, 1 << 30));
  context.AddCommand(list_cmd, [list](Session& session) { return RunList(*list, session); });

  auto* watch_cmd = results->add_subcommand("watch", "Follow the result feed (operator)");
  auto watch = std::make_shared<ResultWatchFlags>();
  watch_cmd->add_option("--after", watch->after, "Resume after this sequence number (default: from the first)")
      ->check(CLI::Range(int64_t(0), int64_t(1) << 62));
  watch_cmd->add_option("--count", watch->count, "Stop after this many results (default: run until Ctrl-C)")
      ->check(CLI::Range(1, 1 << 30));
  watch_cmd->add_flag("--details", watch->details, "Also print every measurement");
  context.AddCommand(watch_cmd, [watch](Session& session) { return RunWatch(*watch, session); });
}

}  // namespace inspection::client::cli
