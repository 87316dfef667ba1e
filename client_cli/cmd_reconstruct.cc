// inspectctl reconstruct: a depth map from an uploaded stack folder, a plain folder of images
// (stack built here, image_folder.h) or a stored scan, followed to its end and downloaded
// (docs/inspectctl.md "reconstruct").
#include <iostream>
#include <memory>
#include <string>

#include "client_cli/commands.h"
#include "client_cli/follow.h"
#include "client_cli/image_folder.h"
#include "client_cli/reconstruction_flags.h"

namespace inspection::client::cli {
namespace {

namespace fs = std::filesystem;

struct ReconstructFlags {
  std::string stack_dir, scan_id, out_dir;
  ImageFolderOptions images;
  std::string keep_stack;  // hidden: build the --images stack here and keep it (tests, debugging)
  ReconstructionFlags reconstruction;
  std::string label, request_id;
};

int RunReconstruct(const ReconstructFlags& f, Session& session) {
  v1::ReconstructStart start;
  start.set_request_id(f.request_id);
  start.set_label(f.label);
  *start.mutable_options() = f.reconstruction.ToProto();
  FollowOutcome outcome;
  if (!f.scan_id.empty()) {
    start.set_scan_id(f.scan_id);
    outcome = Follow(session.printer, [&](const EventCallback& cb, v1::Job* job) {
      return session.client.ReconstructStored(start, cb, job);
    });
    return FinishJob(session.client, session.out, session.printer, outcome, fs::path(f.out_dir), false);
  }
  fs::path stack_dir = f.stack_dir;
  StackFolder built;  // the --images stack; a temporary one is removed when this returns
  if (!f.images.images.empty()) {
    std::vector<ImageFrame> frames;
    grpc::Status s = BuildImageStack(f.images, &frames);
    if (s.ok()) s = built.Create(frames, StackManifestJson(frames, f.images.pixel_size_um), f.keep_stack);
    if (!s.ok()) {
      PrintErrorLine(s);
      return kExitUsage;
    }
    stack_dir = built.path();
    // Without --pixel-size stack.json has no pixel_size_um: the server reports pixel_size_um 0
    // and its lateral outputs say "unknown scale".
    if (!f.images.pixel_size_um && !session.out.quiet) {
      std::cerr << "inspectctl: note: no --pixel-size; lateral outputs are in pixels (unknown scale)\n";
    }
  }
  outcome = Follow(session.printer, [&](const EventCallback& cb, v1::Job* job) {
    return session.client.ReconstructUpload(stack_dir, start, cb, job, [&](int64_t done, int64_t total) {
      session.printer.OnBytes("upload", done, total);
      // Every byte is read once the last chunk is sent (no image is empty): drop the links now,
      // so that detaching with Ctrl-C (which exits at once) leaves no temporary folder behind.
      if (done >= total) built.Remove();
    });
  });
  return FinishJob(session.client, session.out, session.printer, outcome, fs::path(f.out_dir), false);
}

}  // namespace

void RegisterReconstructCommand(CLI::App& app, CliContext& context) {
  auto* cmd =
      app.add_subcommand("reconstruct", "Depth map from an uploaded stack folder, a folder of images or a stored scan");
  auto f = std::make_shared<ReconstructFlags>();
  // Exactly one source: a stack folder, a plain folder (or glob) of images, or a stored scan.
  auto* source = cmd->add_option_group("source", "Exactly one of");
  source->add_option("--stack", f->stack_dir, "Stack folder to upload (stack.json + frames)")
      ->check(CLI::ExistingDirectory);
  auto* images = source->add_option("--images", f->images.images,
                                    "Folder of .png/.tif/.tiff/.jpg/.jpeg or camera RAW (.dng/.cr2/.nef/.arw/...) images, or a quoted glob ('dir/*.png'); "
                                    "natural file-name order is the z order");
  source->add_option("--scan-id", f->scan_id, "A stored scan (JobResult.scan_id)");
  source->require_option(1);
  auto* z_step = cmd->add_option("--z-step", f->images.z_step_um, "With --images: z step between frames, um (> 0)");
  auto* z_start =
      cmd->add_option("--z-start", f->images.z_start_um, "With --images: z of the first frame, um (default 0)");
  auto* z_csv =
      cmd->add_option("--z-csv", f->images.z_csv, "With --images: CSV of file,z_um lines instead of --z-step");
  auto* pixel =
      cmd->add_option("--pixel-size", f->images.pixel_size_um, "With --images: pixel size on the specimen, um");
  auto* keep = cmd->add_option("--keep-stack", f->keep_stack)->group("");  // hidden
  for (auto* o : {z_step, z_start, z_csv, pixel, keep}) o->needs(images);
  z_csv->excludes(z_step)->excludes(z_start);
  cmd->add_option("--out", f->out_dir, "Folder for the results")->required();
  f->reconstruction.Add(cmd);
  cmd->add_option("--label", f->label, "Free text kept with the job");
  cmd->add_option("--request-id", f->request_id, "Idempotency key");
  context.AddCommand(cmd, [f](Session& session) { return RunReconstruct(*f, session); });
}

}  // namespace inspection::client::cli
