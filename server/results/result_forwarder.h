// ResultForwarder: a rig's inspection results, store-and-forward to its site's database, so one
// result feed (WatchResults / ListResults on any site replica) covers every rig. The rig's own
// store is the outbox: results are forwarded in their order from a mark persisted beside them
// (setting "site_forwarded_sequence"), and the site stores each (rig_id, rig's sequence) once
// (DataStore::ImportResult), so a forward retried after a lost answer or a crash between the
// site's commit and the mark's is not stored twice. While the site database is unreachable the
// rig keeps scanning and keeping its results; the forwarder retries with backoff and catches up.
// Thread-safe; one background thread.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "core/util/status.h"
#include "server/storage/data_store.h"

namespace inspection {

struct ResultForwardingOptions {
  std::string rig_id;     // must not be empty
  DatabaseOptions site;   // a postgresql:// URL (the site's store)
  int batch_size = 100;   // results read from the outbox at a time
  std::chrono::milliseconds retry_min{500};
  std::chrono::milliseconds retry_max{30000};
  std::chrono::milliseconds idle_poll{1000};  // looks at the outbox at least this often
};

// INVALID_ARGUMENT naming rig_id / site_database when forwarding cannot work as configured.
Status ValidateResultForwardingOptions(const ResultForwardingOptions& options);

class ResultForwarder {
 public:
  static constexpr const char* kMarkSetting = "site_forwarded_sequence";

  // Starts forwarding `local`'s results (which must outlive this object) to the site store.
  ResultForwarder(DataStore* local, ResultForwardingOptions options);
  ~ResultForwarder();  // Stop()
  ResultForwarder(const ResultForwarder&) = delete;
  ResultForwarder& operator=(const ResultForwarder&) = delete;

  // A result was stored locally: forward it now rather than at the next poll.
  void Notify();
  // Ends the thread (a forward in flight completes or fails first).
  void Stop();

  struct Progress {
    int64_t forwarded_sequence = 0;  // the rig's last result the site has
    bool site_reachable = false;
    std::string last_error;          // empty while forwarding works
  };
  Progress progress() const;
  // Until the site has the rig's results through `sequence`, or `timeout`. For tests and drains.
  bool WaitForwarded(int64_t sequence, std::chrono::milliseconds timeout) const;

 private:
  void Run();
  // One pass: forwards what the outbox holds after the mark. Ok when it is empty.
  Status ForwardPending();

  DataStore* const local_;
  const ResultForwardingOptions options_;
  std::unique_ptr<DataStore> site_;  // only the thread touches it

  mutable std::mutex mu_;                // guards the members below
  mutable std::condition_variable cv_;   // Notify, Stop, progress
  bool stop_ = false;
  bool notified_ = false;
  Progress progress_;
  std::thread thread_;
};

}  // namespace inspection
