// ResultFeed (server/results/result_feed.h): stored results plus a wake-up for the watchers.
#include "server/results/result_feed.h"

#include <algorithm>
#include <utility>

namespace inspection {

StatusOr<v1::InspectionResult> ResultFeed::Append(v1::InspectionResult result) {
  INSPECT_ASSIGN_OR_RETURN(v1::InspectionResult stored, store_->AppendResult(std::move(result)));
  {
    std::lock_guard<std::mutex> lock(mu_);
    ++appended_;
  }
  cv_.notify_all();
  if (listener_) listener_();
  return stored;
}

StatusOr<std::vector<v1::InspectionResult>> ResultFeed::Next(int64_t after_sequence, int limit,
                                                             std::chrono::milliseconds wait) {
  uint64_t seen;
  {
    std::lock_guard<std::mutex> lock(mu_);
    seen = appended_;
  }
  // Counter first, then the query: an Append between the two bumps the counter, so the wait
  // below returns at once instead of missing it.
  INSPECT_ASSIGN_OR_RETURN(std::vector<v1::InspectionResult> results, store_->ResultsAfter(after_sequence, limit));
  if (!results.empty()) return results;
  // A shared store (a site's PostgreSQL) also gets results from other processes (the rigs'
  // forwarders, other replicas), which no Append here announces: look again at least this often.
  const auto deadline = std::chrono::steady_clock::now() + wait;
  const std::chrono::milliseconds step = store_->shared() ? kSharedStorePoll : wait;
  std::unique_lock<std::mutex> lock(mu_);
  while (!shut_down_) {
    const auto until = std::min(deadline, std::chrono::steady_clock::now() + step);
    const bool woken = cv_.wait_until(lock, until, [&] { return shut_down_ || appended_ != seen; });
    if (shut_down_) break;
    if (woken || store_->shared()) {
      seen = appended_;
      lock.unlock();
      INSPECT_ASSIGN_OR_RETURN(results, store_->ResultsAfter(after_sequence, limit));
      if (!results.empty() || std::chrono::steady_clock::now() >= deadline) return results;
      lock.lock();
      continue;
    }
    if (std::chrono::steady_clock::now() >= deadline) break;
  }
  return results;
}

void ResultFeed::Shutdown() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    shut_down_ = true;
  }
  cv_.notify_all();
}

bool ResultFeed::shut_down() const {
  std::lock_guard<std::mutex> lock(mu_);
  return shut_down_;
}

}  // namespace inspection
