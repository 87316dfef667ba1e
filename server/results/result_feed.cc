// ResultFeed (server/results/result_feed.h): stored results plus a wake-up for the watchers.
#include "server/results/result_feed.h"

#include <utility>

namespace inspection {

StatusOr<v1::InspectionResult> ResultFeed::Append(v1::InspectionResult result) {
  INSPECT_ASSIGN_OR_RETURN(v1::InspectionResult stored, store_->AppendResult(std::move(result)));
  {
    std::lock_guard<std::mutex> lock(mu_);
    ++appended_;
  }
  cv_.notify_all();
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
  std::unique_lock<std::mutex> lock(mu_);
  if (cv_.wait_for(lock, wait, [&] { return shut_down_ || appended_ != seen; }) && !shut_down_) {
    lock.unlock();
    return store_->ResultsAfter(after_sequence, limit);
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
