// Reconstruction options of `scan` and `reconstruct`: names accepted on the command line for
// the proto's reconstruction methods (thesis 3.1, 5.4, 6.4), focus measures (thesis 3.1.3),
// depth interpolations (thesis 3.1.4) and exports.
#include "client_cli/reconstruction_flags.h"

#include <map>

#include "client_cli/cli_context.h"
#include "client_cli/output.h"

namespace inspection::client::cli {
namespace {

const std::map<std::string, v1::ReconstructionMethod>& Methods() {
  static const std::map<std::string, v1::ReconstructionMethod> m = {
      {"sff", v1::RECONSTRUCTION_METHOD_SFF},
      {"isff", v1::RECONSTRUCTION_METHOD_ISFF},
      {"isff-gt", v1::RECONSTRUCTION_METHOD_ISFF_GT},
      {"isff-fast", v1::RECONSTRUCTION_METHOD_ISFF_FAST},
  };
  return m;
}

const std::map<std::string, v1::FocusMeasure>& FocusMeasures() {
  static const std::map<std::string, v1::FocusMeasure> m = {
      {"tenengrad", v1::FOCUS_MEASURE_TENENGRAD},
      {"modified-laplacian", v1::FOCUS_MEASURE_MODIFIED_LAPLACIAN},
      {"ml", v1::FOCUS_MEASURE_MODIFIED_LAPLACIAN},
      {"sum-modified-laplacian", v1::FOCUS_MEASURE_SUM_MODIFIED_LAPLACIAN},
      {"sml", v1::FOCUS_MEASURE_SUM_MODIFIED_LAPLACIAN},
      {"grey-level-variance", v1::FOCUS_MEASURE_GREY_LEVEL_VARIANCE},
      {"glv", v1::FOCUS_MEASURE_GREY_LEVEL_VARIANCE},
      {"helmli-mean", v1::FOCUS_MEASURE_HELMLI_MEAN},
      {"chebyshev-moments", v1::FOCUS_MEASURE_CHEBYSHEV_MOMENTS},
      {"grey-level-local-variance", v1::FOCUS_MEASURE_GREY_LEVEL_LOCAL_VARIANCE},
      {"gllv", v1::FOCUS_MEASURE_GREY_LEVEL_LOCAL_VARIANCE},
  };
  return m;
}

const std::map<std::string, v1::DepthInterpolation>& Interpolations() {
  static const std::map<std::string, v1::DepthInterpolation> m = {
      {"maximum", v1::DEPTH_INTERPOLATION_MAXIMUM},
      {"line-fit", v1::DEPTH_INTERPOLATION_LINE_FIT},
      {"gaussian", v1::DEPTH_INTERPOLATION_GAUSSIAN},
      {"defocus-parabola", v1::DEPTH_INTERPOLATION_DEFOCUS_PARABOLA},
  };
  return m;
}

const std::map<std::string, v1::ArtifactKind>& Exports() {
  static const std::map<std::string, v1::ArtifactKind> m = {
      {"png16", v1::ARTIFACT_KIND_DEPTH_PNG16},
      {"ply", v1::ARTIFACT_KIND_DEPTH_PLY},
      {"x3p", v1::ARTIFACT_KIND_DEPTH_X3P},
  };
  return m;
}

const std::map<std::string, v1::FrameAlignment>& Alignments() {
  static const std::map<std::string, v1::FrameAlignment> m = {
      {"none", v1::FRAME_ALIGNMENT_NONE},
      {"estimate", v1::FRAME_ALIGNMENT_ESTIMATE},
      {"calibrated", v1::FRAME_ALIGNMENT_CALIBRATED},
  };
  return m;
}

const std::map<std::string, v1::DepthRefinementMethod>& Refinements() {
  static const std::map<std::string, v1::DepthRefinementMethod> m = {
      {"none", v1::DEPTH_REFINEMENT_METHOD_NONE},
      {"weighted-median", v1::DEPTH_REFINEMENT_METHOD_WEIGHTED_MEDIAN},
      {"guided-filter", v1::DEPTH_REFINEMENT_METHOD_GUIDED_FILTER},
  };
  return m;
}

}  // namespace

void ReconstructionFlags::Add(CLI::App* cmd) {
  cmd->add_option("--method", method,
                  "Reconstruction: sff (default) | isff | isff-gt (simulated rig scans only) | isff-fast; "
                  "the isff methods need the integral-psf calibration step")
      ->check(CLI::IsMember(Keys(Methods()), CLI::ignore_case));
  cmd->add_option("--isff-fast-threshold", isff_fast_threshold,
                  "isff-fast: correlation a local maximum needs to stop the search, (0, 1] (default 0.9)");
  cmd->add_option("--focus-measure", focus_measure, "Focus measure (default tenengrad)")
      ->check(CLI::IsMember(Keys(FocusMeasures()), CLI::ignore_case));
  cmd->add_option("--window", window_px, "Focus measure window, odd 3..31 px (default 7)");
  cmd->add_option("--interpolation", interpolation, "Depth interpolation between frames (default defocus-parabola)")
      ->check(CLI::IsMember(Keys(Interpolations()), CLI::ignore_case));
  cmd->add_option("--min-confidence", min_confidence, "Pixels below this confidence get no depth (0..1)");
  cmd->add_option("--export", exports, "Extra export, repeatable: png16, ply, x3p")
      ->check(CLI::IsMember(Keys(Exports()), CLI::ignore_case));
  cmd->add_option("--alignment", alignment,
                  "Lateral alignment of the frames: none | estimate (from the stack; reconstruct's default) | "
                  "calibrated (the focus-breathing calibration; scan's default when calibrated)")
      ->check(CLI::IsMember(Keys(Alignments()), CLI::ignore_case));
  cmd->add_flag("--no-consistency", no_consistency,
                "Keep pixels whose depth disagrees with their neighbourhood by more than a z step (the default "
                "rejects them: focus windows across depth steps or without texture)");
  cmd->add_option("--refine", refinement,
                  "Edge-aware smoothing of the depth guided by the all-in-focus image: none (default) | "
                  "weighted-median | guided-filter")
      ->check(CLI::IsMember(Keys(Refinements()), CLI::ignore_case));
  cmd->add_flag("--illumination-invariant", illumination_invariant,
                "SFF: focus measure divided by the window's mean grey squared, for frames lit differently "
                "(ADAPT-family scans, flicker); off by default (docs/reconstruction.md)");
  cmd->add_option("--dense", dense,
                  "Depth at every pixel (edge-aware fit of the measured depths; inferred pixels keep "
                  "confidence below the threshold): on | off | auto (default: on for an imported stack "
                  "(--images, a folder whose stack.json records no rig scan), off for a rig scan)")
      ->check(CLI::IsMember({"on", "off", "auto"}));
  cmd->add_flag("--halo-suppression", halo_suppression,
                "SFF: near depth jumps, keep a bright defocused edge's blur from winning over the sharp surface "
                "behind it (depth and all-in-focus); two more passes over the frames, off by default");
  cmd->add_flag("--fill", fill,
                "Fill pixels without depth from measured neighbours (interpolated, not measured; off by default)");
}

v1::ReconstructionOptions ReconstructionFlags::ToProto() const {
  v1::ReconstructionOptions o;
  if (!focus_measure.empty()) o.set_focus_measure(FocusMeasures().at(Lower(focus_measure)));
  if (window_px) o.set_window_px(*window_px);
  if (!interpolation.empty()) o.set_interpolation(Interpolations().at(Lower(interpolation)));
  if (min_confidence) o.set_min_confidence(*min_confidence);
  for (const auto& e : exports) o.add_extra_exports(Exports().at(Lower(e)));
  if (!method.empty()) o.set_method(Methods().at(Lower(method)));
  if (isff_fast_threshold) o.set_isff_fast_threshold(*isff_fast_threshold);
  if (!alignment.empty()) o.set_alignment(Alignments().at(Lower(alignment)));
  if (no_consistency) o.set_depth_consistency(false);
  if (!refinement.empty()) o.set_refinement(Refinements().at(Lower(refinement)));
  if (fill) o.set_fill_low_confidence(true);
  if (dense == "on") o.set_dense_depth(true);
  if (dense == "off") o.set_dense_depth(false);
  if (illumination_invariant) o.set_illumination_invariant(true);
  if (halo_suppression) o.set_halo_suppression(true);
  return o;
}

}  // namespace inspection::client::cli
