// Rig: the camera, projector and stage of one microscope, as the server's job worker drives
// them. Built from a rig configuration (devices/rig_config.h) or as the simulated rig.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "devices/camera.h"
#include "devices/projector.h"
#include "devices/stage.h"

namespace inspection {

// ISO 25178-70 material measure with its certificate, as the verification of the instrument
// (ISO 25178-700, server/procedures/verification_procedure.h) scans it.
enum class MaterialMeasureType {
  kAfl,  // optical flat: N_M (two repeats) and z_FLT
  kPgr,  // step height / groove: alpha_z, l_z
  kAsg,  // sinusoid along x: amplitude transfer, W_R
  kAcg,  // cross grating: alpha_x, alpha_y
};
struct MaterialMeasure {
  std::string specimen;  // the name the rig selects it by (SimulationControl::SetSpecimen)
  MaterialMeasureType type = MaterialMeasureType::kAfl;
  double height_um = 0.0;    // PGR depth, ASG / ACG amplitude (certified); 0 for AFL
  double height_u_um = 0.0;  // its standard uncertainty (k = 1)
  double period_um = 0.0;    // ASG period, ACG pitch (certified); 0 otherwise
  double period_u_um = 0.0;
};

// Simulation-only view of a rig: ground truth and specimen choice. Real rigs return nullptr
// from Rig::simulation().
class SimulationControl {
 public:
  virtual ~SimulationControl() = default;
  virtual std::vector<std::string> specimen_names() const = 0;
  virtual std::string specimen() const = 0;
  // Loads a built-in specimen by name or a user scene ("file:/path/scene.json").
  virtual Status SetSpecimen(const std::string& name) = 0;
  // Height map (CV_32FC1, µm) in the depth convention: the stage z at which each camera pixel
  // is in focus.
  virtual cv::Mat GroundTruthDepthUm() const = 0;
  // The same height map in the camera grid with the stage at z_um: moved by the lateral optics
  // (nearest neighbour, so a step edge keeps its two heights); a depth map aligned onto the frame
  // at z compares against it. Without lateral optics, GroundTruthDepthUm().
  virtual cv::Mat GroundTruthInCameraGridUm(double z_um) const = 0;
  // The ground-truth texture (ISFF-GT's template, thesis 6.4.3): the specimen rendered with every
  // point in focus and without noise, under `pattern` (CV_8UC1 of the projector size) at
  // exposure_us and the camera's gain; the frames' type. INVALID_ARGUMENT for a bad pattern.
  virtual StatusOr<cv::Mat> GroundTruthTexture(const cv::Mat& pattern, double exposure_us) const = 0;
  // The z range covering the specimen's heights (including its z offset).
  virtual std::pair<double, double> SpecimenZRangeUm() const = 0;
  // Places the specimen offset_um higher (a part of unknown height, for automatic z range
  // tests); 0 = as built. The rig's scan defaults stay at the unshifted specimen's range, like a
  // real rig's configured range. Kept across SetSpecimen. INVALID_ARGUMENT when the shifted
  // specimen leaves the stage travel.
  virtual Status SetSpecimenZOffsetUm(double offset_um) = 0;
  // The material measures the rig can put under the objective (SetSpecimen by their
  // `specimen`), with their certificates; empty when it has none.
  virtual std::vector<MaterialMeasure> material_measures() const { return {}; }
};

struct ScanDefaults {
  double z_start_um = 0.0;
  double z_end_um = 0.0;
  double z_step_um = 5.0;  // thesis rig: 5.059 µm
  double exposure_us = 10000.0;
  // Coarse step of the automatic z range's sweep, set by the optics
  // (core/sff/z_range_search.h SearchPatternCoarseStepUm); 0 = unknown (4 z steps are used).
  double focus_search_step_um = 0.0;
};

class Rig {
 public:
  virtual ~Rig() = default;

  virtual Camera& camera() = 0;
  virtual Projector& projector() = 0;
  virtual Stage& stage() = 0;
  virtual double pixel_size_um() const = 0;
  virtual ScanDefaults scan_defaults() const = 0;
  // Non-null only on the simulated rig.
  virtual SimulationControl* simulation() { return nullptr; }

  // Checks every device is reachable; UNAVAILABLE naming the device otherwise.
  virtual Status CheckDevices();
  // Reconnects devices after an error (e.g. camera unplugged and plugged back).
  virtual Status Reset() { return CheckDevices(); }
};

}  // namespace inspection
