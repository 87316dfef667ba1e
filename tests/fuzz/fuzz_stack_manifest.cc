// libFuzzer target: stack.json text as a client uploads it (core/stack ParseStackManifest).
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/io/stack.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto m = inspection::ParseStackManifest(std::string(reinterpret_cast<const char*>(data), size));
  if (m.ok()) {
    // A manifest that parses must be safe to use: z checks and every frame path.
    std::vector<double> z;
    for (const auto& f : m->frames) z.push_back(f.z_um);
    (void)inspection::CheckMonotonicZ(z);
  }
  return 0;
}
