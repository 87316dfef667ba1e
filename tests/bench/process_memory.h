// Resident memory of this process for the benches (Linux /proc/self): the current and peak RSS,
// and resetting the peak so that a phase's own peak can be read.
#pragma once

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

namespace inspection::bench {

// kB from /proc/self/status ("VmRSS" or "VmHWM"); -1 when not found.
inline long ProcStatusKb(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key, 0) == 0) return std::atol(line.c_str() + std::strlen(key) + 1);
  }
  return -1;
}

// Resets the peak RSS (VmHWM) to the current RSS (Linux >= 4.0); false when the kernel refuses.
inline bool ResetPeakRss() {
  std::ofstream out("/proc/self/clear_refs");
  out << "5";
  return bool(out.flush());
}

}  // namespace inspection::bench
