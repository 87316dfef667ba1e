// SHA-256 of a file, for the server (artifact hashes it records) and the client (the integrity
// check of a download) alike: one implementation, one error contract. Its own room because the
// client may use only the proto API and this; it depends on OpenSSL's libcrypto alone.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace inspection {

// The file's SHA-256 as 64 lower-case hex digits. nullopt when the file cannot be opened or read
// to its end or an OpenSSL call fails; `error` (if given) then names the file and the step.
std::optional<std::string> Sha256FileHex(const std::filesystem::path& path, std::string* error = nullptr);

}  // namespace inspection
