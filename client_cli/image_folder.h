// A stack from a plain folder of images (`reconstruct --images`): lists the images, orders them
// by natural sort of their names, gives each its z (regular step or a CSV) and writes the stack
// folder the upload reads (docs/stack-format.md; thesis 3.2: one frame per z position).
// Client side only: speaks the stack format, never reads pixels (channels, bit depth and size are
// the server's to check; the format is told by the file extension).
#pragma once

#include <grpcpp/grpcpp.h>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace inspection::client::cli {

// What the user gave. Either z_step_um (with z_start_um) or z_csv sets the z positions.
struct ImageFolderOptions {
  std::string images;                   // --images: a folder or a glob(3) pattern
  std::optional<double> z_step_um;      // --z-step
  double z_start_um = 0.0;              // --z-start
  std::string z_csv;                    // --z-csv: lines `file,z_um`
  std::optional<double> pixel_size_um;  // --pixel-size
};

// One frame of the built stack: the user's file, the name it gets in the stack folder (its own
// file name) and its z.
struct ImageFrame {
  std::filesystem::path source;
  std::string file;
  double z_um = 0.0;
};

// "img2" < "img10": digit runs compare by value, the rest byte by byte, case-insensitively
// (ties broken by the plain byte order so the order is total).
bool NaturalLess(const std::string& a, const std::string& b);

// The frames in stack order. Every error is INVALID_ARGUMENT whose message starts with the flag
// it concerns (--images, --z-step, --z-csv, --pixel-size): no image matched, fewer than 3
// images, images of different formats (by extension: PNG, TIFF, JPEG, one camera RAW format),
// an empty image file, two images with the same file name, a CSV line that does not
// parse or names a file that is not among the images, an image without a CSV z, z not strictly
// monotonic, --z-step <= 0, --pixel-size <= 0.
grpc::Status BuildImageStack(const ImageFolderOptions& options, std::vector<ImageFrame>* frames);

// The stack.json text for the frames. Without pixel_size_um the field is left out (unknown
// scale: the server's lateral outputs then count pixels).
std::string StackManifestJson(const std::vector<ImageFrame>& frames, std::optional<double> pixel_size_um);

// A stack folder built from frames: stack.json plus one hard link (else symlink, else copy) per
// image; the user's files are never modified. A temporary folder (dir empty) is removed by
// Remove() or the destructor; a folder given as dir (`--keep-stack`) must not exist yet and is
// kept. Creating a temporary one first removes those of this user's inspectctl processes that
// died without removing theirs (image_folder.cc: RemoveStaleStackFolders).
class StackFolder {
 public:
  StackFolder() = default;
  ~StackFolder() { Remove(); }
  StackFolder(const StackFolder&) = delete;
  StackFolder& operator=(const StackFolder&) = delete;

  grpc::Status Create(const std::vector<ImageFrame>& frames, const std::string& manifest_json,
                      const std::filesystem::path& dir = {});
  const std::filesystem::path& path() const { return path_; }
  // Removes a temporary folder (no-op for a kept one or when already removed).
  void Remove();

 private:
  std::filesystem::path path_;
  bool temporary_ = false;
};

}  // namespace inspection::client::cli
