// Thread count of the SFF engine's parallel loops (core/util/parallel_for.h).
#include "core/util/parallel_for.h"

namespace inspection {

int ResolveThreads(int threads) {
  if (threads > 0) return threads;
  return int(std::max(1u, std::thread::hardware_concurrency()));
}

}  // namespace inspection
