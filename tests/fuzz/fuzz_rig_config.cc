// libFuzzer target: the rig configuration file (devices/rig_config ParseRigConfig).
#include <cstddef>
#include <cstdint>
#include <string>

#include "devices/rig_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  (void)inspection::ParseRigConfig(std::string(reinterpret_cast<const char*>(data), size));
  return 0;
}
