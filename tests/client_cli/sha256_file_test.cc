// The one SHA-256 file hasher of server and client (common/sha256_file.h): the standard's test
// vectors, and a failure that names the file instead of a digest.
#include "common/sha256_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <string>

namespace inspection {
namespace {
namespace fs = std::filesystem;

fs::path WriteTemp(const std::string& name, const std::string& bytes) {
  const fs::path p = fs::temp_directory_path() / (name + "-" + std::to_string(::getpid()));
  std::ofstream(p, std::ios::binary) << bytes;
  return p;
}

TEST(Sha256FileTest, KnownVectorsIncludingEmptyAndMultiBuffer) {
  const fs::path empty = WriteTemp("sha-empty", "");
  const fs::path abc = WriteTemp("sha-abc", "abc");
  // Larger than the 1 MiB read buffer: the digest spans several EVP_DigestUpdate calls.
  const fs::path big = WriteTemp("sha-big", std::string(1000000 * 3, 'a'));
  EXPECT_EQ(Sha256FileHex(empty), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256FileHex(abc), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  // sha256 of 3 000 000 'a' (sha256sum).
  EXPECT_EQ(Sha256FileHex(big), "2a152c894398719c0570f83fac34ac03a0f6e8e474b995c2403aa5434f7b9dd4");
  fs::remove(empty);
  fs::remove(abc);
  fs::remove(big);
}

TEST(Sha256FileTest, UnreadableFileIsAnErrorNamingIt) {
  std::string error;
  EXPECT_EQ(Sha256FileHex("/nonexistent/dir/file.bin", &error), std::nullopt);
  EXPECT_EQ(error, "cannot read /nonexistent/dir/file.bin");
}

}  // namespace
}  // namespace inspection
