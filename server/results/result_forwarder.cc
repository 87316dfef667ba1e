// ResultForwarder (server/results/result_forwarder.h): the rig's outbox to the site's store.
#include "server/results/result_forwarder.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <utility>
#include <vector>

namespace inspection {

Status ValidateResultForwardingOptions(const ResultForwardingOptions& o) {
  if (o.rig_id.empty()) return Status::InvalidArgument("rig_id: must be set when site_database is");
  if (o.site.url.rfind("postgresql://", 0) != 0 && o.site.url.rfind("postgres://", 0) != 0 &&
      o.site.url.rfind("host=", 0) != 0) {
    return Status::InvalidArgument("site_database: '" + RedactDatabaseUrl(o.site.url) +
                                   "' is not a postgresql:// URL (a site's store is PostgreSQL)");
  }
  Status s = ValidateDatabaseOptions(o.site);
  if (!s.ok()) return Status::InvalidArgument("site_" + s.message());
  if (o.batch_size < 1) return Status::InvalidArgument("batch_size must be >= 1");
  return Status::Ok();
}

ResultForwarder::ResultForwarder(DataStore* local, ResultForwardingOptions options)
    : local_(local), options_(std::move(options)) {
  const std::string mark = local_->GetSetting(kMarkSetting);
  progress_.forwarded_sequence = mark.empty() ? 0 : std::stoll(mark);
  thread_ = std::thread([this] { Run(); });
}

ResultForwarder::~ResultForwarder() { Stop(); }

void ResultForwarder::Notify() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    notified_ = true;
  }
  cv_.notify_all();
}

void ResultForwarder::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

ResultForwarder::Progress ResultForwarder::progress() const {
  std::lock_guard<std::mutex> lock(mu_);
  return progress_;
}

bool ResultForwarder::WaitForwarded(int64_t sequence, std::chrono::milliseconds timeout) const {
  std::unique_lock<std::mutex> lock(mu_);
  return cv_.wait_for(lock, timeout, [&] { return progress_.forwarded_sequence >= sequence; });
}

Status ResultForwarder::ForwardPending() {
  if (!site_) {
    INSPECT_ASSIGN_OR_RETURN(site_, DataStore::Open(local_->data_dir(), options_.site));
    spdlog::info("result forwarding: connected to the site store {}", RedactDatabaseUrl(options_.site.url));
  }
  for (;;) {
    int64_t mark;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stop_) return Status::Ok();
      mark = progress_.forwarded_sequence;
    }
    INSPECT_ASSIGN_OR_RETURN(std::vector<v1::InspectionResult> batch, local_->ResultsAfter(mark, options_.batch_size));
    if (batch.empty()) return Status::Ok();
    for (v1::InspectionResult& r : batch) {
      const int64_t rig_sequence = r.sequence();
      r.set_rig_id(options_.rig_id);
      r.set_rig_sequence(rig_sequence);
      auto stored = site_->ImportResult(std::move(r));
      if (!stored.ok()) {
        // A dead connection is reopened on the next pass; anything else is logged and retried too.
        if (stored.status().code() == StatusCode::kUnavailable) site_.reset();
        return stored.status();
      }
      // The mark after the site's commit: a crash between the two forwards this result again,
      // which the site's (rig_id, rig_sequence) key turns into a no-op.
      INSPECT_RETURN_IF_ERROR(local_->SetSetting(kMarkSetting, std::to_string(rig_sequence)));
      {
        std::lock_guard<std::mutex> lock(mu_);
        progress_.forwarded_sequence = rig_sequence;
        progress_.site_reachable = true;
        progress_.last_error.clear();
      }
      cv_.notify_all();
    }
  }
}

void ResultForwarder::Run() {
  std::chrono::milliseconds backoff = options_.retry_min;
  for (;;) {
    Status s = ForwardPending();
    std::chrono::milliseconds wait = options_.idle_poll;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stop_) return;
      if (s.ok()) {
        progress_.site_reachable = site_ != nullptr;
        backoff = options_.retry_min;
      } else {
        if (progress_.last_error != s.message()) {
          spdlog::warn("result forwarding to the site store: {}; results stay in the outbox, retrying", s.message());
        }
        progress_.site_reachable = false;
        progress_.last_error = s.message();
        wait = backoff;
        backoff = std::min(backoff * 2, options_.retry_max);
      }
    }
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait_for(lock, wait, [&] { return stop_ || (s.ok() && notified_); });
    notified_ = false;
    if (stop_) return;
  }
}

}  // namespace inspection
