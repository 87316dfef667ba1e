#include "server/artifact_files.h"

#include <openssl/evp.h>
#include <zip.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <fstream>
#include <memory>
#include <vector>

#include "server/data_lifecycle.h"

namespace inspection {
namespace fs = std::filesystem;

StatusOr<std::string> Sha256File(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Internal("cannot read " + path.string());
  std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> ctx(EVP_MD_CTX_new(), EVP_MD_CTX_free);
  if (!ctx || EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) != 1) return Status::Internal("sha256 init failed");
  std::vector<char> buf(1 << 20);
  while (in) {
    in.read(buf.data(), std::streamsize(buf.size()));
    if (in.gcount() > 0) EVP_DigestUpdate(ctx.get(), buf.data(), size_t(in.gcount()));
  }
  if (in.bad()) return Status::Internal("read error on " + path.string());
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_DigestFinal_ex(ctx.get(), md, &len);
  static const char* hex = "0123456789abcdef";
  std::string out;
  for (unsigned int i = 0; i < len; ++i) {
    out.push_back(hex[md[i] >> 4]);
    out.push_back(hex[md[i] & 15]);
  }
  return out;
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

Status UnzipToFolder(const fs::path& zip_path, const fs::path& folder,
                     const std::function<void(const std::string&)>& on_file) {
  int err = 0;
  std::unique_ptr<zip_t, decltype(&zip_discard)> za(zip_open(zip_path.c_str(), ZIP_RDONLY, &err), zip_discard);
  if (!za) return Status::DataLoss("cannot open the stored stack " + zip_path.filename().string());
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) return WriteFailure(ec.value(), "cannot create " + folder.string());
  const zip_int64_t n = zip_get_num_entries(za.get(), 0);
  std::vector<char> buf(1 << 20);
  // stack.json first (the archive sorts it after the frames): a reader of the frames needs it.
  std::vector<zip_int64_t> order;
  const zip_int64_t manifest = zip_name_locate(za.get(), "stack.json", 0);
  if (manifest >= 0) order.push_back(manifest);
  for (zip_int64_t i = 0; i < n; ++i) {
    if (i != manifest) order.push_back(i);
  }
  for (const zip_int64_t i : order) {
    zip_stat_t st;
    if (zip_stat_index(za.get(), zip_uint64_t(i), 0, &st) != 0 || (st.valid & ZIP_STAT_NAME) == 0) {
      return Status::DataLoss("stored stack " + zip_path.filename().string() + ": unreadable entry " +
                              std::to_string(i));
    }
    const std::string name = st.name;
    if (!name.empty() && name.back() == '/') continue;  // a directory entry; files create their folders
    if (!SafeEntryName(name)) {
      return Status::DataLoss("stored stack " + zip_path.filename().string() + ": entry '" + name +
                              "' is not a relative path inside the stack");
    }
    const fs::path target = folder / fs::path(name);
    fs::create_directories(target.parent_path(), ec);
    if (ec) return WriteFailure(ec.value(), "cannot create " + target.parent_path().string());
    std::unique_ptr<zip_file_t, decltype(&zip_fclose)> in(zip_fopen_index(za.get(), zip_uint64_t(i), 0), zip_fclose);
    if (!in) return Status::DataLoss("stored stack: cannot read entry '" + name + "'");
    std::unique_ptr<FILE, decltype(&std::fclose)> out(std::fopen(target.c_str(), "wb"), std::fclose);
    if (!out) return WriteFailure(errno, "cannot write " + target.string());
    for (;;) {
      const zip_int64_t got = zip_fread(in.get(), buf.data(), buf.size());
      if (got < 0) return Status::DataLoss("stored stack: entry '" + name + "' is corrupt");
      if (got == 0) break;
      if (std::fwrite(buf.data(), 1, size_t(got), out.get()) != size_t(got)) {
        return WriteFailure(errno, "cannot write " + target.string());
      }
    }
    if (std::fflush(out.get()) != 0) return WriteFailure(errno, "cannot write " + target.string());
    FILE* f = out.release();
    if (std::fclose(f) != 0) return WriteFailure(errno, "cannot write " + target.string());
    if (on_file) on_file(name);
  }
  return Status::Ok();
}

}  // namespace inspection
