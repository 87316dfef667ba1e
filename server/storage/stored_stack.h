// A stored scan's stack, opened for one reconstruction. The server keeps each scan's raw stack
// once, as the stack.zip artifact users download (a folder beside its own archive would double
// every scan's footprint). A reconstruction reads the frames' bytes from that archive
// and decodes them in memory: the frames are never written to disk a second time.
// Only the small files a job reads by path (stack.json, the ground truth) go to a private folder
// that goes with the job.
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "core/io/stack.h"
#include "core/io/stack_frame_decoder.h"
#include "core/util/status.h"
#include "server/storage/data_store.h"
#include "server/storage/owned_folder.h"

namespace inspection {

struct StoredStack {
  // stack.json and the ground truth (kInMemory), the whole stack (kExtracted), or the scan folder
  // of the pre-archive layout (scans/<scan_id>/, frames included, read in place).
  std::filesystem::path dir;
  // Set when `dir` is a private folder: removed when the last holder lets go.
  std::shared_ptr<OwnedFolder> extraction;
  StackManifest manifest;  // checked: every frame is in the archive (or the folder)
  // Frame i decoded from its archive entry, read again at each call (a frame the decoder dropped
  // is read again from the archive, never from a file); holds the archive open. Empty when the
  // frames are files in `dir`.
  StackFrameDecodeFn decode;
};

enum class StoredFrames {
  kInMemory,  // frames read from the archive by `decode`
  // The whole archive extracted to `dir`: the sequential path (ReconstructPipelineOptions), the
  // end-to-end benchmark's baseline, reads the stack from extracted files.
  kExtracted,
};

// NOT_FOUND naming scan_id when no succeeded scan job has that id or its stack was deleted;
// DATA_LOSS naming the scan when the archive is missing or unreadable on the server (a corrupt
// frame entry: when `decode` reads it); INVALID_ARGUMENT as ReadStackManifest for its stack.json
// or a frame missing from it; RESOURCE_EXHAUSTED "data disk full" when the extraction (under the
// store's uploads/) runs out of space. Nothing is left on any error.
StatusOr<StoredStack> OpenStoredStack(DataStore& store, const std::string& scan_id,
                                      StoredFrames frames = StoredFrames::kInMemory);

}  // namespace inspection
