// Inspection result RPCs of InspectionService: ListResults (a query with paging) and
// WatchResults (the feed an MES keeps open; server/results/result_feed.h).
#include <google/protobuf/util/time_util.h>

#include <string>

#include "server/api/grpc_status.h"
#include "server/api/inspection_service.h"
#include "server/security/call_authorization.h"
#include "server/api/request_mapping.h"

namespace inspection {
namespace {

using google::protobuf::util::TimeUtil;

constexpr int kWatchBatch = 100;
// How often a waiting WatchResults looks whether its client is still there.
constexpr std::chrono::milliseconds kWatchPoll{250};

int64_t Nanos(const google::protobuf::Timestamp& t) { return TimeUtil::TimestampToNanoseconds(t); }

grpc::Status Grpc(const Status& s) { return ToGrpcStatus(s); }

// Within google.protobuf.Timestamp's range (years 1..9999) and nanos 0..999999999.
bool ValidTimestamp(const google::protobuf::Timestamp& t) {
  return t.seconds() >= TimeUtil::kTimestampMinSeconds && t.seconds() <= TimeUtil::kTimestampMaxSeconds &&
         t.nanos() >= 0 && t.nanos() <= 999999999;
}

StatusOr<ResultQuery> MapListResultsRequest(const v1::ListResultsRequest& req) {
  if (req.page_size() < 0) return Status::InvalidArgument("page_size must be >= 0");
  if (!v1::Verdict_IsValid(req.verdict())) {
    return Status::InvalidArgument("verdict " + std::to_string(req.verdict()) + " is not a Verdict");
  }
  ResultQuery q;
  q.part_id = req.part_id();
  q.recipe_id = req.recipe_id();
  q.verdict = req.verdict();
  q.limit = req.page_size() == 0 ? 50 : std::min(req.page_size(), 500);
  if (req.has_finished_after()) {
    if (!ValidTimestamp(req.finished_after())) return Status::InvalidArgument("finished_after is invalid");
    q.finished_from_ns = Nanos(req.finished_after());
  }
  if (req.has_finished_before()) {
    if (!ValidTimestamp(req.finished_before())) {
      return Status::InvalidArgument("finished_before is invalid");
    }
    q.finished_before_ns = Nanos(req.finished_before());
    if (q.finished_before_ns <= q.finished_from_ns) {
      return Status::InvalidArgument("finished_before must be later than finished_after");
    }
  }
  if (!req.page_token().empty()) {
    // The token is the sequence number of the last result of the previous page.
    size_t used = 0;
    try {
      q.before_sequence = std::stoll(req.page_token(), &used);
    } catch (...) {
      used = 0;
    }
    if (used != req.page_token().size() || q.before_sequence <= 0) {
      return Status::InvalidArgument("page_token is malformed");
    }
  }
  return q;
}

}  // namespace

grpc::Status InspectionServiceImpl::ListResults(grpc::ServerContext* ctx, const v1::ListResultsRequest* req,
                                                v1::ListResultsResponse* out) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (Status s = CheckRequestTextLimits(*req); !s.ok()) return Grpc(s);
  auto query = MapListResultsRequest(*req);
  if (!query.ok()) return Grpc(query.status());
  const int limit = query->limit;
  query->limit = limit + 1;  // one more tells whether another page follows
  auto results = store_->ListResults(*query);
  if (!results.ok()) return Grpc(results.status());
  for (int i = 0; i < int(results->size()) && i < limit; ++i) *out->add_results() = std::move((*results)[i]);
  if (int(results->size()) > limit) out->set_next_page_token(std::to_string(out->results(limit - 1).sequence()));
  return grpc::Status::OK;
}

grpc::Status InspectionServiceImpl::WatchResults(grpc::ServerContext* ctx, const v1::WatchResultsRequest* req,
                                                 grpc::ServerWriter<v1::InspectionResult>* writer) {
  auto who = CallerOf(ctx);
  if (!who.ok()) return Grpc(who.status());
  if (req->after_sequence() < 0) return Grpc(Status::InvalidArgument("after_sequence must be >= 0"));
  if (options_.results == nullptr) return Grpc(Status::FailedPrecondition("this server keeps no result feed"));
  int64_t after = req->after_sequence();
  for (;;) {
    auto batch = options_.results->Next(after, kWatchBatch, kWatchPoll);
    if (!batch.ok()) return Grpc(batch.status());
    for (const v1::InspectionResult& r : *batch) {
      if (!writer->Write(r)) return grpc::Status(grpc::StatusCode::CANCELLED, "client stopped reading");
      after = r.sequence();
    }
    if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client went away");
    if (batch->empty() && options_.results->shut_down()) {
      return grpc::Status(grpc::StatusCode::UNAVAILABLE,
                          "server shutting down; resume with after_sequence " + std::to_string(after));
    }
  }
}

}  // namespace inspection
