#include "server/storage/artifact_files.h"

#include <zip.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <fstream>
#include <functional>
#include <memory>
#include <vector>

#include "common/sha256_file.h"
#include "server/storage/data_lifecycle.h"

namespace inspection {
namespace fs = std::filesystem;

StatusOr<std::string> Sha256File(const fs::path& path) {
  std::string error;
  std::optional<std::string> hex = Sha256FileHex(path, &error);
  if (!hex) return Status::Internal(error);
  return std::move(*hex);
}

Status ZipFolder(const fs::path& folder, const fs::path& zip_path) {
  int err = 0;
  zip_t* za = zip_open(zip_path.c_str(), ZIP_CREATE | ZIP_TRUNCATE, &err);
  if (!za) return Status::Internal("cannot create " + zip_path.string());
  std::error_code ec;
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(folder, ec)) {
    if (e.is_regular_file()) files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  for (const fs::path& f : files) {
    const std::string rel = fs::relative(f, folder).generic_string();
    zip_source_t* src = zip_source_file(za, f.c_str(), 0, -1);
    if (!src) {
      zip_discard(za);
      return Status::Internal("cannot read " + f.string());
    }
    const zip_int64_t idx = zip_file_add(za, rel.c_str(), src, ZIP_FL_ENC_UTF_8 | ZIP_FL_OVERWRITE);
    if (idx < 0) {
      zip_source_free(src);
      zip_discard(za);
      return Status::Internal("cannot add " + rel + " to " + zip_path.string());
    }
    zip_set_file_compression(za, zip_uint64_t(idx), ZIP_CM_STORE, 0);
  }
  if (zip_close(za) != 0) {
    Status s = Status::Internal("cannot write " + zip_path.string() + ": " + zip_strerror(za));
    zip_discard(za);
    return s;
  }
  return Status::Ok();
}

namespace {

// Relative, no "..", no absolute or drive-qualified root: an entry cannot leave the folder.
bool SafeEntryName(const std::string& name) {
  if (name.empty() || name.front() == '/' || name.find('\\') != std::string::npos) return false;
  const fs::path p(name);
  if (p.has_root_path()) return false;
  for (const fs::path& part : p) {
    if (part == ".." || part == ".") return false;
  }
  return true;
}

}  // namespace

StatusOr<std::shared_ptr<ZipReader>> ZipReader::Open(const fs::path& zip_path) {
  int err = 0;
  zip_t* za = zip_open(zip_path.c_str(), ZIP_RDONLY, &err);
  if (!za) return Status::DataLoss("cannot open the stored stack " + zip_path.filename().string());
  std::shared_ptr<ZipReader> reader(new ZipReader(za));
  const zip_int64_t n = zip_get_num_entries(za, 0);
  for (zip_int64_t i = 0; i < n; ++i) {
    zip_stat_t st;
    if (zip_stat_index(za, zip_uint64_t(i), 0, &st) != 0 || (st.valid & ZIP_STAT_NAME) == 0) {
      return Status::DataLoss("stored stack " + zip_path.filename().string() + ": unreadable entry " +
                              std::to_string(i));
    }
    const std::string name = st.name;
    if (!name.empty() && name.back() == '/') continue;  // a directory entry; files create their folders
    if (!SafeEntryName(name)) {
      return Status::DataLoss("stored stack " + zip_path.filename().string() + ": entry '" + name +
                              "' is not a relative path inside the stack");
    }
    reader->files_.push_back(name);
    reader->index_[name] = i;
  }
  return reader;
}

ZipReader::~ZipReader() { zip_discard(archive_); }

bool ZipReader::Contains(const std::string& name) const { return index_.count(name) > 0; }

namespace {

// Streams entry `index` of `za` into `sink` in 1 MiB pieces. libzip checks the entry's CRC when
// the read reaches its end, so the loop reads until end of entry, never just `size` bytes.
Status ReadEntry(zip_t* za, int64_t index, const std::string& name,
                 const std::function<Status(const char*, size_t)>& sink) {
  std::unique_ptr<zip_file_t, decltype(&zip_fclose)> in(zip_fopen_index(za, zip_uint64_t(index), 0), zip_fclose);
  if (!in) return Status::DataLoss("stored stack: cannot read entry '" + name + "'");
  std::vector<char> buf(1 << 20);
  for (;;) {
    const zip_int64_t got = zip_fread(in.get(), buf.data(), buf.size());
    if (got < 0) return Status::DataLoss("stored stack: entry '" + name + "' is corrupt");
    if (got == 0) return Status::Ok();
    INSPECT_RETURN_IF_ERROR(sink(buf.data(), size_t(got)));
  }
}

}  // namespace

StatusOr<std::string> ZipReader::Read(const std::string& name) const {
  const auto it = index_.find(name);
  if (it == index_.end()) return Status::NotFound("stored stack: no entry '" + name + "'");
  std::string out;
  std::lock_guard lock(mu_);
  zip_stat_t st;
  if (zip_stat_index(archive_, zip_uint64_t(it->second), 0, &st) == 0 && (st.valid & ZIP_STAT_SIZE) != 0) {
    out.reserve(size_t(st.size));
  }
  INSPECT_RETURN_IF_ERROR(ReadEntry(archive_, it->second, name, [&](const char* data, size_t n) {
    out.append(data, n);
    return Status::Ok();
  }));
  return out;
}

Status ZipReader::Extract(const std::string& name, const fs::path& target) const {
  const auto it = index_.find(name);
  if (it == index_.end()) return Status::NotFound("stored stack: no entry '" + name + "'");
  std::error_code ec;
  fs::create_directories(target.parent_path(), ec);
  if (ec) return WriteFailure(ec.value(), "cannot create " + target.parent_path().string());
  std::unique_ptr<FILE, decltype(&std::fclose)> out(std::fopen(target.c_str(), "wb"), std::fclose);
  if (!out) return WriteFailure(errno, "cannot write " + target.string());
  std::lock_guard lock(mu_);
  INSPECT_RETURN_IF_ERROR(ReadEntry(archive_, it->second, name, [&](const char* data, size_t n) {
    if (std::fwrite(data, 1, n, out.get()) != n) return WriteFailure(errno, "cannot write " + target.string());
    return Status::Ok();
  }));
  if (std::fflush(out.get()) != 0) return WriteFailure(errno, "cannot write " + target.string());
  FILE* f = out.release();
  if (std::fclose(f) != 0) return WriteFailure(errno, "cannot write " + target.string());
  return Status::Ok();
}

Status UnzipToFolder(const fs::path& zip_path, const fs::path& folder) {
  INSPECT_ASSIGN_OR_RETURN(std::shared_ptr<ZipReader> reader, ZipReader::Open(zip_path));
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) return WriteFailure(ec.value(), "cannot create " + folder.string());
  // stack.json first (the archive sorts it after the frames): a reader of the frames needs it.
  std::vector<std::string> order = reader->files();
  std::stable_partition(order.begin(), order.end(), [](const std::string& n) { return n == "stack.json"; });
  for (const std::string& name : order) INSPECT_RETURN_IF_ERROR(reader->Extract(name, folder / fs::path(name)));
  return Status::Ok();
}

}  // namespace inspection
