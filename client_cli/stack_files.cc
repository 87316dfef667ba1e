// Stack folder listing for uploads (stack_files.h).
#include "client_cli/stack_files.h"

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <system_error>

namespace inspection::client {

namespace fs = std::filesystem;

bool ReadWholeFile(const fs::path& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return false;
  *out = ss.str();
  return true;
}

grpc::Status ListStackFiles(const fs::path& stack_dir, std::vector<UploadFile>* files) {
  const fs::path manifest_path = stack_dir / "stack.json";
  std::string text;
  if (!ReadWholeFile(manifest_path, &text)) {
    return {grpc::StatusCode::INVALID_ARGUMENT, "stack.json: cannot read " + manifest_path.string()};
  }
  nlohmann::json manifest = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (manifest.is_discarded()) {
    return {grpc::StatusCode::INVALID_ARGUMENT, "stack.json: not valid JSON (" + manifest_path.string() + ")"};
  }
  if (!manifest.is_object() || !manifest.contains("frames") || !manifest["frames"].is_array()) {
    return {grpc::StatusCode::INVALID_ARGUMENT, "stack.json: frames is missing or not an array"};
  }
  files->clear();
  std::error_code ec;
  files->push_back({"stack.json", manifest_path, static_cast<int64_t>(fs::file_size(manifest_path, ec))});
  if (ec) return {grpc::StatusCode::INVALID_ARGUMENT, "stack.json: " + ec.message()};
  const auto& frames = manifest["frames"];
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string at = "stack.json: frames[" + std::to_string(i) + "].file";
    if (!frames[i].is_object() || !frames[i].contains("file") || !frames[i]["file"].is_string()) {
      return {grpc::StatusCode::INVALID_ARGUMENT, at + " is missing or not a string"};
    }
    const std::string rel = frames[i]["file"].get<std::string>();
    const fs::path rel_path(rel);
    if (rel.empty() || rel_path.is_absolute() ||
        std::any_of(rel_path.begin(), rel_path.end(), [](const fs::path& p) { return p == ".."; })) {
      return {grpc::StatusCode::INVALID_ARGUMENT, at + " '" + rel + "' must be a path inside the stack folder"};
    }
    const fs::path path = stack_dir / rel_path;
    const auto size = fs::file_size(path, ec);
    if (ec) {
      return {grpc::StatusCode::INVALID_ARGUMENT,
              "frame " + std::to_string(i) + " (" + rel + "): cannot read " + path.string() + ": " + ec.message()};
    }
    files->push_back({rel, path, static_cast<int64_t>(size)});
  }
  // The simulated rig's ground truth travels with the stack so the server can report the
  // reconstruction's error against it; other files in the folder are not part of the stack.
  const fs::path truth = stack_dir / "ground_truth_depth.tiff";
  if (fs::is_regular_file(truth, ec)) {
    const auto size = fs::file_size(truth, ec);
    if (!ec) files->push_back({"ground_truth_depth.tiff", truth, static_cast<int64_t>(size)});
  }
  return grpc::Status::OK;
}

}  // namespace inspection::client
