// Runs independent tasks (tiles, row bands of a frame) on a few threads: the SFF engine's only
// threading. No pool outlives a call: each call starts its threads and joins them.
#pragma once

#include <algorithm>
#include <atomic>
#include <system_error>
#include <thread>
#include <vector>

namespace inspection {

// threads > 0 as given; 0 = all hardware threads (at least 1).
int ResolveThreads(int threads);

// Runs fn(task, worker) for task = 0..n_tasks-1 on up to `threads` threads (the caller's
// included); worker (0..threads-1) identifies the thread, so fn can use per-worker scratch.
// Tasks are handed out dynamically. Returns when all tasks are done.
template <typename F>
void ParallelFor(int n_tasks, int threads, F&& fn) {
  threads = std::max(1, std::min(threads, n_tasks));
  std::atomic<int> next{0};
  auto worker = [&](int id) {
    for (int i = next.fetch_add(1); i < n_tasks; i = next.fetch_add(1)) fn(i, id);
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) {
    try {
      pool.emplace_back(worker, t);
    } catch (const std::system_error&) {
      break;  // fewer threads; the tasks are shared out dynamically anyway
    }
  }
  worker(0);
  for (auto& t : pool) t.join();
}

}  // namespace inspection
