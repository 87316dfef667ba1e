// The files of a stack folder as an upload sends them: stack.json, every frame file it names
// and the simulated rig's ground truth, with sizes.
#pragma once

#include <grpcpp/support/status.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace inspection::client {

// One file of an upload: its name as sent (relative to the stack folder) and where it is read.
struct UploadFile {
  std::string relative;
  std::filesystem::path path;
  int64_t size_bytes = 0;
};

// Lists stack.json, every frame file it names and ground_truth_depth.tiff if present, with sizes. Only reads the
// manifest's file list; the server validates the rest (z monotonic, image formats).
grpc::Status ListStackFiles(const std::filesystem::path& stack_dir, std::vector<UploadFile>* files);

// The whole file into *out; false when it cannot be opened or read.
bool ReadWholeFile(const std::filesystem::path& path, std::string* out);

}  // namespace inspection::client
