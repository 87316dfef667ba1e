// The reconstruction options shared by `scan` and `reconstruct` (--method, --isff-fast-threshold,
// --focus-measure, --window, --interpolation, --min-confidence, --export, --alignment,
// --no-consistency, --refine, --fill) and their
// mapping to ReconstructionOptions.
#pragma once

#include <CLI/CLI.hpp>
#include <optional>
#include <string>
#include <vector>

#include "client_cli/inspection_client.h"

namespace inspection::client::cli {

// Unset flags stay unset in the proto, so the server's defaults apply (docs/reconstruction.md
// "Reconstruction options and defaults").
struct ReconstructionFlags {
  std::string focus_measure;
  std::optional<int> window_px;
  std::string interpolation;
  std::optional<double> min_confidence;
  std::vector<std::string> exports;
  std::string method;                         // sff | isff | isff-gt | isff-fast (thesis 5.4, 6.4)
  std::optional<double> isff_fast_threshold;  // ISFF-FAST, (0, 1]; the server checks the range
  std::string alignment;                      // none | estimate | calibrated; empty = server default
  bool no_consistency = false;                // depth_consistency = false (the server's default is true)
  std::string refinement;                     // none | weighted-median | guided-filter; empty = none
  bool illumination_invariant = false;        // illumination_invariant
  bool halo_suppression = false;              // halo_suppression
  bool fill = false;                          // fill_low_confidence
  std::string dense = "auto";                 // dense_depth: on | off | auto (unset)

  // Adds the options to `cmd`, writing into this object (which must outlive the parse).
  void Add(CLI::App* cmd);
  v1::ReconstructionOptions ToProto() const;
};

}  // namespace inspection::client::cli
