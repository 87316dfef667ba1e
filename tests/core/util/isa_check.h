// Which instruction-set variants of a kernel a test must check on this CPU: every listed level
// /proc/cpuinfo reports. A level the CPU reports but core/util/cpu_features.h denies fails the
// test (it would otherwise check nothing there and pass).
#pragma once

#include <gtest/gtest.h>

#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "core/util/cpu_features.h"

namespace inspection::testing_isa {

// The flags of the first processor in /proc/cpuinfo (empty where there is none).
inline std::set<std::string> CpuInfoFlags() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("flags", 0) != 0) continue;
    std::istringstream words(line.substr(line.find(':') + 1));
    std::set<std::string> flags;
    for (std::string w; words >> w;) flags.insert(w);
    return flags;
  }
  return {};
}

// True when /proc/cpuinfo says the CPU runs code of that level.
inline bool CpuInfoHas(Isa isa) {
  static const std::set<std::string> f = CpuInfoFlags();
  switch (isa) {
    case Isa::kPortable:
      return true;
    case Isa::kSse2:
      return f.count("sse2") > 0;
    case Isa::kAvx2:
      return f.count("avx2") > 0 && f.count("fma") > 0;
    case Isa::kAvx512:
      return f.count("avx2") > 0 && f.count("fma") > 0 && f.count("avx512f") > 0;
  }
  return false;
}

// The levels among `compiled` (the kernel's non-portable variants) to check here.
inline std::vector<Isa> IsasToCheck(std::initializer_list<Isa> compiled) {
  std::vector<Isa> out;
  for (Isa isa : compiled) {
    if (!CpuInfoHas(isa)) continue;
    EXPECT_TRUE(CpuHas(isa)) << "/proc/cpuinfo lists " << IsaName(isa) << " but CpuHas denies it";
    out.push_back(isa);
  }
  return out;
}

}  // namespace inspection::testing_isa
