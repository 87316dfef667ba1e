// inspectctl scan: acquire a stack through focus with the chosen illumination mode (thesis 5),
// reconstruct it, follow the job and download the results (docs/inspectctl.md "scan").
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "client_cli/commands.h"
#include "client_cli/follow.h"
#include "client_cli/reconstruction_flags.h"

namespace inspection::client::cli {
namespace {

namespace fs = std::filesystem;

const std::map<std::string, v1::IlluminationMode>& IlluminationModes() {
  static const std::map<std::string, v1::IlluminationMode> m = {{"std", v1::ILLUMINATION_MODE_STD},
                                                                {"hdr", v1::ILLUMINATION_MODE_HDR},
                                                                {"adapt-it", v1::ILLUMINATION_MODE_ADAPT_IT},
                                                                {"adapt", v1::ILLUMINATION_MODE_ADAPT},
                                                                {"texture", v1::ILLUMINATION_MODE_TEXTURE},
                                                                {"hf+adapt", v1::ILLUMINATION_MODE_HF_ADAPT},
                                                                {"adapted-hf", v1::ILLUMINATION_MODE_ADAPTED_HF},
                                                                {"auto", v1::ILLUMINATION_MODE_AUTO}};
  return m;
}

// Unset optionals stay unset in the request, so the rig's and the server's defaults apply.
struct ScanFlags {
  std::string out_dir;
  std::optional<double> z_start_um, z_end_um, z_step_um, exposure_us;
  std::string illumination;
  std::optional<int> hdr_exposures, max_iterations;
  std::optional<double> lambda, gamma, psi, target_grey;
  ReconstructionFlags reconstruction;
  std::string label, request_id;
  std::string part_id, station, recipe_id;
  int recipe_version = 0;
  bool include_stack = false;
  bool auto_range = false;    // automatic z range (ScanRequest.z_range_search)
  std::string search_window;  // "A:B" um
  std::optional<double> coarse_step_um, margin_um;
};

// "A:B" -> (A, B); false when it does not parse.
bool ParseWindow(const std::string& text, double* a, double* b) {
  const size_t colon = text.find(':');
  if (colon == std::string::npos) return false;
  try {
    size_t used_a = 0, used_b = 0;
    *a = std::stod(text.substr(0, colon), &used_a);
    *b = std::stod(text.substr(colon + 1), &used_b);
    return used_a == colon && used_b == text.size() - colon - 1;
  } catch (const std::exception&) {
    return false;
  }
}

int RunScan(const ScanFlags& f, Session& session) {
  v1::ScanRequest request;
  request.set_request_id(f.request_id);
  request.set_label(f.label);
  request.set_part_id(f.part_id);
  request.set_station(f.station);
  request.set_recipe_id(f.recipe_id);
  request.set_recipe_version(f.recipe_version);
  if (f.auto_range) {
    // The range comes from the search; only the step is the user's (unset: rig default).
    v1::ZRangeSearch* z = request.mutable_z_range_search();
    z->set_enabled(true);
    double a = 0.0, b = 0.0;
    if (!f.search_window.empty()) {
      ParseWindow(f.search_window, &a, &b);  // checked when parsing the flags
      z->set_window_start_um(a);
      z->set_window_end_um(b);
    }
    if (f.coarse_step_um) z->set_coarse_step_um(*f.coarse_step_um);
    if (f.margin_um) z->set_margin_um(*f.margin_um);
    if (f.z_step_um) request.set_z_step_um(*f.z_step_um);
  } else if (f.z_start_um || f.z_end_um || f.z_step_um) {
    // A partial range is completed from the rig's defaults; all unset leaves them to the server.
    v1::ScanDefaults defaults;
    if (!(f.z_start_um && f.z_end_um && f.z_step_um)) {
      v1::RigStatus rig;
      if (grpc::Status s = session.client.GetRigStatus(&rig); !s.ok()) return ReportError(s);
      defaults = rig.scan_defaults();
    }
    request.set_z_start_um(f.z_start_um.value_or(defaults.z_start_um()));
    request.set_z_end_um(f.z_end_um.value_or(defaults.z_end_um()));
    request.set_z_step_um(f.z_step_um.value_or(defaults.z_step_um()));
  }
  if (f.exposure_us) request.set_exposure_us(*f.exposure_us);
  if (!f.illumination.empty()) request.set_illumination(IlluminationModes().at(f.illumination));
  v1::IlluminationParameters* ip = request.mutable_illumination_parameters();
  if (f.hdr_exposures) ip->set_hdr_exposures(*f.hdr_exposures);
  if (f.lambda) ip->set_lambda(*f.lambda);
  if (f.gamma) ip->set_gamma(*f.gamma);
  if (f.psi) ip->set_psi(*f.psi);
  if (f.max_iterations) ip->set_max_iterations(*f.max_iterations);
  if (f.target_grey) ip->set_target_grey(*f.target_grey);
  *request.mutable_reconstruction() = f.reconstruction.ToProto();
  if (request.illumination_parameters().ByteSizeLong() == 0) request.clear_illumination_parameters();
  if (request.reconstruction().ByteSizeLong() == 0) request.clear_reconstruction();
  FollowOutcome outcome = Follow(
      session.printer, [&](const EventCallback& cb, v1::Job* job) { return session.client.Scan(request, cb, job); });
  return FinishJob(session.client, session.out, session.printer, outcome, fs::path(f.out_dir), f.include_stack);
}

}  // namespace

void RegisterScanCommand(CLI::App& app, CliContext& context) {
  auto* cmd = app.add_subcommand("scan", "Acquire a stack through focus and reconstruct its depth map");
  auto f = std::make_shared<ScanFlags>();
  cmd->add_option("--out", f->out_dir, "Folder for the results")->required();
  auto* z_start = cmd->add_option("--z-start", f->z_start_um, "First z position, um (unset: rig default)");
  auto* z_end = cmd->add_option("--z-end", f->z_end_um, "Last z position, um (unset: rig default)");
  cmd->add_option("--z-step", f->z_step_um, "z step, um > 0 (unset: rig default)");
  cmd->add_option("--exposure-us", f->exposure_us, "Camera exposure, us (unset: rig default)");
  auto* auto_range = cmd->add_flag("--auto-range", f->auto_range,
                                   "Find the z range with a coarse sweep first, then scan it at --z-step");
  auto_range->excludes(z_start)->excludes(z_end);
  cmd->add_option("--search-window", f->search_window,
                  "--auto-range: search window A:B, um (unset: the rig's default range)")
      ->needs(auto_range)
      ->check([](const std::string& v) {
        double a = 0.0, b = 0.0;
        return ParseWindow(v, &a, &b) ? std::string() : std::string("expected A:B in um, e.g. 100:600");
      });
  cmd->add_option("--coarse-step", f->coarse_step_um, "--auto-range: coarse sweep step, um (unset: the rig's, from its optics)")
      ->needs(auto_range);
  cmd->add_option("--margin", f->margin_um, "--auto-range: margin added each side, um (unset: 1.5 z steps, >= 1/8 coarse step)")
      ->needs(auto_range);
  cmd->add_option("--illumination", f->illumination,
                  "std | hdr | adapt-it | adapt | texture | hf+adapt | adapted-hf | auto (unset: server default)")
      ->check(CLI::IsMember({"std", "hdr", "adapt-it", "adapt", "texture", "hf+adapt", "adapted-hf", "auto"}));
  cmd->add_option("--hdr-exposures", f->hdr_exposures, "HDR: exposures per z, 2..5 (thesis Table 6.2)");
  cmd->add_option("--lambda", f->lambda, "ADAPT family: prediction scale of eq. 5.12, 0..2");
  cmd->add_option("--gamma", f->gamma, "TEXTURE: checkerboard weight of eq. 5.16, 0..0.5");
  cmd->add_option("--psi", f->psi, "HF+ADAPT: added checkerboard weight of eq. 5.17, 0..1");
  cmd->add_option("--max-iterations", f->max_iterations, "ADAPT-IT: frames per z at most, 1..20");
  cmd->add_option("--target-grey", f->target_grey, "ADAPT family: desired camera grey, 8-bit units, 0..255");
  f->reconstruction.Add(cmd);
  cmd->add_option("--label", f->label, "Free text kept with the job");
  cmd->add_option("--recipe", f->recipe_id, "Run this stored recipe: its scan, then its measurements and verdicts");
  cmd->add_option("--recipe-version", f->recipe_version, "With --recipe: this version (default: the current one)")
      ->check(CLI::Range(1, 1 << 30));
  cmd->add_option("--part-id", f->part_id, "Part id kept with the job and its inspection result");
  cmd->add_option("--station", f->station, "Station or operator kept with the job and its inspection result");
  cmd->add_option("--request-id", f->request_id, "Idempotency key: repeating it returns the same job");
  cmd->add_flag("--include-stack", f->include_stack, "Also download the raw stack as stack.zip");
  context.AddCommand(cmd, [f](Session& session) { return RunScan(*f, session); });
}

}  // namespace inspection::client::cli
