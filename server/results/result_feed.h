// ResultFeed: the inspection results an MES follows (WatchResults). Results are stored in the
// DataStore under increasing sequence numbers; a watcher asks for everything after the last
// number it received and waits for more, so a client that reconnects after a network break or a
// server restart resumes where it stopped and loses nothing (the store, not this object, is the
// memory of the feed).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <vector>

#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/storage/data_store.h"

namespace inspection {

class ResultFeed {
 public:
  explicit ResultFeed(DataStore* store) : store_(store) {}

  // Stores the result (DataStore::AppendResult) and wakes every watcher. Returns it with its
  // sequence number.
  StatusOr<v1::InspectionResult> Append(v1::InspectionResult result);

  // The stored results after `after_sequence` (oldest first, at most `limit`). When there are
  // none, waits until one is appended, `wait` has passed, or Shutdown: an empty answer then
  // means "ask again" (the caller checks whether its client is still there).
  StatusOr<std::vector<v1::InspectionResult>> Next(int64_t after_sequence, int limit, std::chrono::milliseconds wait);

  // Called after every Append (e.g. the site forwarder's Notify); set before results arrive.
  void SetAppendListener(std::function<void()> listener) { listener_ = std::move(listener); }

  // Wakes every waiting Next and makes later ones return at once.
  void Shutdown();
  bool shut_down() const;

  // How often Next looks at a shared store (server/storage/data_store.h: shared()) while it waits.
  static constexpr std::chrono::milliseconds kSharedStorePoll{250};

 private:
  DataStore* store_;
  std::function<void()> listener_;
  mutable std::mutex mu_;
  std::condition_variable cv_;  // signalled on every Append and on Shutdown
  uint64_t appended_ = 0;       // Appends seen, so a waiter notices one that raced its query
  bool shut_down_ = false;
};

}  // namespace inspection
