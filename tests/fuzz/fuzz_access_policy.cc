// libFuzzer target: the access policy file and the token file (server/access_control), given as
// one input split at the first NUL byte, then an authentication with a token from the input.
#include <cstddef>
#include <cstdint>
#include <string>

#include "server/security/access_control.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string in(reinterpret_cast<const char*>(data), size);
  const auto nul = in.find('\0');
  const std::string policy = nul == std::string::npos ? in : in.substr(0, nul);
  const std::string tokens = nul == std::string::npos ? std::string() : in.substr(nul + 1);
  for (bool mtls : {false, true}) {
    auto p = inspection::AccessPolicy::Parse(policy, tokens, mtls);
    if (!p.ok()) continue;
    inspection::CallerCredentials c;
    c.bearer_token = tokens.substr(0, tokens.find('\n'));
    c.cert_names = {policy.substr(0, 16)};
    (void)p->Authenticate(c);
  }
  return 0;
}
