// Evaluation of integral shape from focus (thesis 6.4) on the simulated rig: Table 6.8, Table
// 6.9, Fig. 6.17 and the calibration and reconstruction times (tests/bench/isff_tables.h).
// Usage: isff-evaluate [--camera WxH] [--seed N] [--repeats N]   (default 512x384, seed 5, 7)
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "tests/bench/isff_tables.h"

namespace inspection {
namespace {

bool ParseSize(const char* s, cv::Size* size) {
  int w = 0, h = 0;
  if (std::sscanf(s, "%dx%d", &w, &h) != 2 || w <= 0 || h <= 0) return false;
  *size = {w, h};
  return true;
}

int Main(int argc, char** argv) {
  IsffTablesOptions o;
  const char* usage = "usage: isff-evaluate [--camera WxH] [--seed N] [--repeats N]\n";
  for (int i = 1; i < argc; i += 2) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      std::fprintf(stderr, "%s", usage);
      return 2;
    }
    if (a == "--camera") {
      if (!ParseSize(argv[i + 1], &o.camera_size)) {
        std::fprintf(stderr, "--camera: bad size %s (want WxH)\n", argv[i + 1]);
        return 2;
      }
    } else if (a == "--seed") {
      o.seed = std::strtoull(argv[i + 1], nullptr, 10);
    } else if (a == "--repeats") {
      o.repeats = std::max(1, std::atoi(argv[i + 1]));
    } else {
      std::fprintf(stderr, "%s", usage);
      return 2;
    }
  }
  return PrintIsffTables(o) ? 0 : 1;
}

}  // namespace
}  // namespace inspection

int main(int argc, char** argv) { return inspection::Main(argc, argv); }
