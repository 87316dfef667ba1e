// A stack from a plain folder of images: natural-sorted file list, z positions from a regular
// step or a CSV, and the temporary stack folder the upload reads (docs/stack-format.md).
#include "client_cli/image_folder.h"

#include <glob.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <system_error>

namespace inspection::client::cli {
namespace {

namespace fs = std::filesystem;

grpc::Status Invalid(const std::string& message) { return {grpc::StatusCode::INVALID_ARGUMENT, message}; }

std::string LowerExtension(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

// The camera RAW formats the server decodes (LibRaw), as in docs/import-stacks.md.
bool IsRawExtension(const std::string& ext) {
  static const std::set<std::string> kRaw = {".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw",
                                             ".srw", ".raf", ".orf", ".rw2", ".pef", ".3fr", ".iiq"};
  return kRaw.count(ext) > 0;
}

// The format a file's extension names ("" when unknown): a folder mixing formats is refused
// here, naming the file, before anything is uploaded (the server checks stack.json the same way).
std::string FormatOf(const fs::path& p) {
  const std::string ext = LowerExtension(p);
  if (ext == ".png") return "PNG";
  if (ext == ".tif" || ext == ".tiff") return "TIFF";
  if (ext == ".jpg" || ext == ".jpeg") return "JPEG";
  if (IsRawExtension(ext)) {
    std::string upper = ext.substr(1);
    std::transform(upper.begin(), upper.end(), upper.begin(), [](unsigned char c) { return std::toupper(c); });
    return "camera RAW (" + upper + ")";
  }
  return "";
}

bool IsImageFile(const fs::path& p) { return !FormatOf(p).empty(); }

// The image files of a folder (regular files with an image extension), or what a glob matches.
grpc::Status ListImages(const std::string& images, std::vector<fs::path>* out) {
  out->clear();
  std::error_code ec;
  if (fs::is_directory(images, ec)) {
    for (const auto& entry : fs::directory_iterator(images, ec)) {
      if (entry.is_regular_file(ec) && IsImageFile(entry.path())) out->push_back(entry.path());
    }
    if (ec) return Invalid("--images: cannot list " + images + ": " + ec.message());
    if (out->empty()) {
      return Invalid("--images: no .png, .tif, .tiff, .jpg, .jpeg or camera RAW (.dng, .cr2, .nef, .arw, ...) file in " +
                     images);
    }
    return grpc::Status::OK;
  }
  glob_t g{};
  const int rc = glob(images.c_str(), 0, nullptr, &g);
  if (rc == 0) {
    for (size_t i = 0; i < g.gl_pathc; ++i) {
      const fs::path p = g.gl_pathv[i];
      // A pattern picks the files itself, so any extension is the user's choice; folders are not frames.
      if (fs::is_regular_file(p, ec)) out->push_back(p);
    }
  }
  globfree(&g);
  if (rc != 0 && rc != GLOB_NOMATCH) return Invalid("--images: cannot expand " + images);
  if (out->empty()) return Invalid("--images: " + images + " is neither a folder nor a pattern matching image files");
  return grpc::Status::OK;
}

std::string Trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

bool ParseDouble(const std::string& text, double* value) {
  if (text.empty()) return false;
  char* end = nullptr;
  *value = std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size() && std::isfinite(*value);
}

// z per file name from a CSV of `file,z_um`. A first line whose z does not parse is a header;
// blank lines and lines starting with '#' are skipped.
grpc::Status ReadZCsv(const std::string& csv, std::map<std::string, double>* z_by_name) {
  std::ifstream in(csv);
  if (!in) return Invalid("--z-csv: cannot read " + csv);
  std::string line;
  int line_no = 0;
  bool first_row = true;
  while (std::getline(in, line)) {
    ++line_no;
    line = Trim(line);
    if (line.empty() || line[0] == '#') continue;
    const auto comma = line.rfind(',');
    const std::string where = "--z-csv: " + csv + " line " + std::to_string(line_no);
    if (comma == std::string::npos) return Invalid(where + ": expected file,z_um");
    const std::string name = Trim(line.substr(0, comma));
    double z = 0.0;
    if (!ParseDouble(Trim(line.substr(comma + 1)), &z)) {
      if (first_row) {
        first_row = false;
        continue;  // header such as "file,z_um"
      }
      return Invalid(where + ": z_um is not a number");
    }
    first_row = false;
    if (name.empty()) return Invalid(where + ": file name is empty");
    const std::string key = fs::path(name).filename().string();
    if (!z_by_name->emplace(key, z).second) return Invalid(where + ": " + key + " is listed twice");
  }
  if (z_by_name->empty()) return Invalid("--z-csv: " + csv + " lists no file");
  return grpc::Status::OK;
}

}  // namespace

bool NaturalLess(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i])) != 0;
    const bool db = std::isdigit(static_cast<unsigned char>(b[j])) != 0;
    if (da && db) {
      // Compare digit runs by value: skip leading zeros, then longer run is larger, then digits.
      size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      size_t iz = i, jz = j;
      while (iz + 1 < ie && a[iz] == '0') ++iz;
      while (jz + 1 < je && b[jz] == '0') ++jz;
      if (ie - iz != je - jz) return ie - iz < je - jz;
      const int c = a.compare(iz, ie - iz, b, jz, je - jz);
      if (c != 0) return c < 0;
      i = ie;
      j = je;
      continue;
    }
    const int ca = std::tolower(static_cast<unsigned char>(a[i]));
    const int cb = std::tolower(static_cast<unsigned char>(b[j]));
    if (ca != cb) return ca < cb;
    ++i;
    ++j;
  }
  if (i < a.size() || j < b.size()) return j < b.size();  // the shorter remainder first
  return a < b;                                           // "f01" vs "f1", "A" vs "a": still total
}

grpc::Status BuildImageStack(const ImageFolderOptions& options, std::vector<ImageFrame>* frames) {
  frames->clear();
  if (options.pixel_size_um && !(*options.pixel_size_um > 0.0 && std::isfinite(*options.pixel_size_um))) {
    return Invalid("--pixel-size: must be > 0 um");
  }
  if (options.z_csv.empty()) {
    if (!options.z_step_um) return Invalid("--z-step: required with --images (or give --z-csv)");
    if (!(*options.z_step_um > 0.0 && std::isfinite(*options.z_step_um))) return Invalid("--z-step: must be > 0 um");
    if (!std::isfinite(options.z_start_um)) return Invalid("--z-start: must be a finite number of um");
  }
  std::vector<fs::path> images;
  if (grpc::Status s = ListImages(options.images, &images); !s.ok()) return s;
  std::sort(images.begin(), images.end(), [](const fs::path& a, const fs::path& b) {
    return NaturalLess(a.filename().string(), b.filename().string());
  });
  if (images.size() < 3) {
    return Invalid("--images: " + std::to_string(images.size()) + " image(s) in " + options.images +
                   "; a stack needs at least 3");
  }
  std::set<std::string> names;
  for (const auto& p : images) {
    const std::string name = p.filename().string();
    if (!names.insert(name).second) return Invalid("--images: two images are named " + name);
    std::error_code ec;
    if (fs::file_size(p, ec) == 0 || ec) return Invalid("--images: " + p.string() + " is empty or unreadable");
  }

  std::map<std::string, double> z_by_name;
  if (!options.z_csv.empty()) {
    if (grpc::Status s = ReadZCsv(options.z_csv, &z_by_name); !s.ok()) return s;
    for (const auto& [name, z] : z_by_name) {
      if (names.count(name) == 0) return Invalid("--z-csv: " + name + " is not among the images of " + options.images);
    }
  }
  for (size_t i = 0; i < images.size(); ++i) {
    ImageFrame f;
    f.source = images[i];
    f.file = images[i].filename().string();
    if (options.z_csv.empty()) {
      f.z_um = options.z_start_um + static_cast<double>(i) * *options.z_step_um;
    } else {
      const auto it = z_by_name.find(f.file);
      if (it == z_by_name.end()) return Invalid("--z-csv: no z for " + f.file);
      f.z_um = it->second;
    }
    frames->push_back(std::move(f));
  }
  // The server needs z strictly monotonic in frame order (either direction).
  const bool rising = (*frames)[1].z_um > (*frames)[0].z_um;
  for (size_t i = 1; i < frames->size(); ++i) {
    const double dz = (*frames)[i].z_um - (*frames)[i - 1].z_um;
    if (dz == 0.0 || (dz > 0.0) != rising) {
      std::ostringstream msg;
      msg << "--z-csv: z is not strictly monotonic in file-name order: " << (*frames)[i - 1].file << " "
          << (*frames)[i - 1].z_um << " um, " << (*frames)[i].file << " " << (*frames)[i].z_um << " um";
      frames->clear();
      return Invalid(msg.str());
    }
  }
  // One format per stack, checked last so that the flag errors above come first (mixed bit
  // depths and sizes are the server's to find: it decodes).
  const fs::path* first_known = nullptr;
  for (const auto& p : images) {
    const std::string format = FormatOf(p);
    if (format.empty()) continue;
    if (first_known == nullptr) {
      first_known = &p;
    } else if (format != FormatOf(*first_known)) {
      frames->clear();
      return Invalid("--images: " + p.filename().string() + " is " + format + " but " +
                     first_known->filename().string() + " is " + FormatOf(*first_known) +
                     "; the frames of a stack share one format");
    }
  }
  return grpc::Status::OK;
}

std::string StackManifestJson(const std::vector<ImageFrame>& frames, std::optional<double> pixel_size_um) {
  nlohmann::ordered_json j;
  j["format"] = "inspection-stack";
  j["version"] = 1;
  // Without --pixel-size the scale is unknown: left out, the server's lateral outputs count pixels.
  if (pixel_size_um) j["pixel_size_um"] = *pixel_size_um;
  j["frames"] = nlohmann::ordered_json::array();
  for (const auto& f : frames) j["frames"].push_back({{"file", f.file}, {"z_um", f.z_um}});
  return j.dump(2) + "\n";
}

namespace {

// A temporary stack folder names the inspectctl that made it (its pid in kOwnerFile), so that a
// folder whose inspectctl was killed before it could remove it (SIGKILL, a crash: its destructor
// never ran) is removed by the next `reconstruct --images` of the same user. Left alone, its hard
// links become a full second copy of the stack once the user deletes the originals. A folder
// without the file (an older inspectctl's, or one being created) and one whose process lives (or
// whose pid was reused) are kept.
constexpr char kOwnerFile[] = ".inspectctl-owner";

void RemoveStaleStackFolders(const fs::path& tmp) {
  std::error_code ec;
  for (auto it = fs::directory_iterator(tmp, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const fs::path dir = it->path();
    if (dir.filename().string().rfind("inspectctl-stack-", 0) != 0) continue;
    struct stat st {};
    if (::lstat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode) || st.st_uid != ::geteuid()) continue;
    long pid = 0;
    std::ifstream owner(dir / kOwnerFile);
    if (!(owner >> pid) || pid <= 0) continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive, or not ours to ask
    std::error_code removed;
    fs::remove_all(dir, removed);  // links and stack.json only, never what they point to
  }
}

}  // namespace

grpc::Status StackFolder::Create(const std::vector<ImageFrame>& frames, const std::string& manifest_json,
                                 const fs::path& dir) {
  Remove();
  std::error_code ec;
  if (dir.empty()) {
    const fs::path tmp = fs::temp_directory_path(ec);
    if (!ec) RemoveStaleStackFolders(tmp);
    std::string pattern = (tmp / "inspectctl-stack-XXXXXX").string();
    if (ec || mkdtemp(pattern.data()) == nullptr) return Invalid("--images: cannot create a temporary stack folder");
    path_ = pattern;
    temporary_ = true;
    std::ofstream(path_ / kOwnerFile) << ::getpid() << "\n";
  } else {
    if (fs::exists(dir, ec)) return Invalid("--keep-stack: " + dir.string() + " already exists");
    if (!fs::create_directories(dir, ec)) return Invalid("--keep-stack: cannot create " + dir.string());
    path_ = dir;
    temporary_ = false;
  }
  for (const auto& f : frames) {
    const fs::path link = path_ / f.file;
    const fs::path target = fs::absolute(f.source, ec);
    // A hard link costs nothing and survives the user renaming the file mid-upload; across
    // file systems a symlink; a copy only where neither is allowed.
    fs::create_hard_link(target, link, ec);
    if (ec) fs::create_symlink(target, link, ec);
    if (ec) fs::copy_file(target, link, ec);
    if (ec)
      return Invalid("--images: cannot place " + f.source.string() + " in " + path_.string() + ": " + ec.message());
  }
  std::ofstream out(path_ / "stack.json", std::ios::binary);
  out << manifest_json;
  out.close();
  if (!out) return Invalid("--images: cannot write " + (path_ / "stack.json").string());
  return grpc::Status::OK;
}

void StackFolder::Remove() {
  if (!temporary_ || path_.empty()) return;
  std::error_code ec;
  fs::remove_all(path_, ec);  // removes the links, never what they point to
  path_.clear();
  temporary_ = false;
}

}  // namespace inspection::client::cli
