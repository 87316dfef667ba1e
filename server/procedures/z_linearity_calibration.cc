// The z-linearity calibration step (server/procedures/z_linearity_calibration.h).
#include "server/procedures/z_linearity_calibration.h"

#include <cmath>

#include "core/sff/sff_engine.h"

namespace inspection {

StatusOr<ZLinearityScan> ScanZLinearity(const std::function<StatusOr<cv::Mat>(double z_um)>& capture_at,
                                        const std::vector<double>& z_um, double pixel_size_um, const SffOptions& sff,
                                        const std::string& source) {
  if (z_um.size() < 3) return Status::InvalidArgument("z linearity scan needs >= 3 frames");
  std::unique_ptr<SffEngine> engine;
  for (double z : z_um) {
    INSPECT_ASSIGN_OR_RETURN(cv::Mat frame, capture_at(z));
    if (!engine) {
      INSPECT_ASSIGN_OR_RETURN(engine, SffEngine::Create(sff, frame.size(), frame.type()));
    }
    INSPECT_RETURN_IF_ERROR(engine->PushFrame(frame, z));
  }
  INSPECT_ASSIGN_OR_RETURN(DepthResult depth, engine->Finish());
  // The window sees the image border within half its side: those depths are not the flat's.
  const int border = sff.window_px / 2 + 1;
  cv::Mat mask = cv::Mat::zeros(depth.depth_um.size(), CV_8UC1);
  int valid = 0;
  for (int y = border; y < depth.depth_um.rows - border; ++y) {
    const float* d = depth.depth_um.ptr<float>(y);
    uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = border; x < depth.depth_um.cols - border; ++x) {
      if (std::isfinite(d[x])) m[x] = 1, ++valid;
    }
  }
  INSPECT_ASSIGN_OR_RETURN(ZGrid grid, ZGrid::Create(z_um));
  INSPECT_ASSIGN_OR_RETURN(ZLinearity linearity, CharacteriseZLinearity(depth.depth_um, mask, pixel_size_um, grid));
  linearity.source = source;
  ZLinearityScan out;
  out.linearity = std::move(linearity);
  out.frames = int(z_um.size());
  out.valid_percent = 100.0 * valid / double(depth.depth_um.total());
  return out;
}

}  // namespace inspection
