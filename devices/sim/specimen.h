// Specimen library of the simulated rig: height map (the ground truth), reflectance R and
// surface texture (thesis eq. 5.2) on the camera pixel grid. Built-ins model the thesis's
// specimens (6.1.1, 6.2.1); user scenes come from a scene.json.
//
// Built-in ids (all heights are above a 200 um base, so scans stay at positive stage z):
//   plane    PLANE-NORM: textured plane normal to the optical axis.
//   skew5    SKEW5: textured plane tilted 5 degrees about the camera y axis.
//   skew10   SKEW10: the same tilted 10 degrees.
//   step1um  textured plane with a 1 um step along the vertical centre line.
//   wedge    tungsten-carbide roof: two ground planes meeting at a 120 degree ridge.
//   chamfer  top plane P1, 60 degree chamfer P2, bottom plane P3 (thesis Fig. 6.2 b).
//   cutter   cutter blade: ground rake face rising to the cutting edge, polished land and glints
//            whose reflectance is ~20x the ground metal (saturates under uniform light), flank.
//   lens     HF-LENS: plano-convex cylindrical lens, glass, no texture.
//   mirror   HF-MIRROR: nearly flat mirror, no texture.
//   coin     HF-COIN: polished coin region: mirror-like flats (saturate) with a weak scratch
//            texture and a raised relief whose flanks are dark.
// ISO 25178-70 material measures (certified values: SimulatedMaterialMeasures), textured, matt:
//   afl      AFL optical flat.
//   pgr2, pgr5, pgr10, pgr20   PGR groove (ISO 5436-1 A1) of depth 2/5/10/20 um, a third of the
//            field wide, centred, running along y.
//   asg4 .. asg40   ASG sinusoid along x, period 4, 6, 8, 10, 12, 16, 24, 40 um, amplitude 1 um
//            (bracketing the rig's topographic spatial resolution W_R).
//   acg      ACG cross grating: sinusoids along x and y, pitch 20 um, amplitude 1 um each.
// User scene: "file:/path/scene.json", see LoadSceneFile.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "devices/rig.h"

namespace inspection {

struct Specimen {
  std::string name;
  cv::Mat height_um;    // CV_32FC1: stage z at which each camera pixel is in focus
  cv::Mat reflectance;  // CV_32FC1 >= 0: linear reflectance R (diffuse ~0.1-0.6, specular > 1)
  cv::Mat texture;      // CV_32FC1 > 0, mean ~1: fine surface texture multiplying R
};

struct SpecimenGrid {
  cv::Size camera_size{1024, 768};
  double pixel_size_um = 0.74;
  uint64_t seed = 1;  // texture and glints derive from it
};

// The thesis's specimens above (benchmarks and evaluations iterate these).
std::vector<std::string> BuiltinSpecimenNames();
// The material measures' ids (afl, pgr*, asg*, acg); MakeSpecimen builds them too.
std::vector<std::string> MaterialMeasureSpecimenNames();

// The material measures among the built-ins with their certificates (devices/rig.h).
std::vector<MaterialMeasure> SimulatedMaterialMeasures();

// A built-in id or "file:/path/scene.json". NOT_FOUND for unknown ids (the message lists them).
StatusOr<Specimen> MakeSpecimen(const std::string& name, const SpecimenGrid& grid);

// scene.json (paths relative to the json's folder):
//   {
//     "height": "height.tif",        required; single-channel image (8/16-bit or float)
//     "height_scale_um": 0.1,        um per stored height unit (default 1)
//     "height_offset_um": 200,       added after scaling (default 0)
//     "reflectance": "refl.png",     optional (default uniform 0.5); single-channel image
//     "reflectance_scale": 0.004,    reflectance per stored unit (default 1/255 for 8-bit,
//                                    1/65535 for 16-bit, 1 for float)
//     "texture": "texture.png",      optional; normalised to mean 1
//     "texture_contrast": 1.0        optional scale of the texture's deviation from 1
//   }
// Images are resampled to the camera size. Errors are INVALID_ARGUMENT / NOT_FOUND naming the key.
StatusOr<Specimen> LoadSceneFile(const std::string& path, const SpecimenGrid& grid);

}  // namespace inspection
