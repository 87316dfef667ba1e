// Scan procedure: drives the rig through focus (thesis 3.1.2, Fig. 3.3) and streams every frame
// into the SFF engine while writing the stack folder, so the depth map is ready when the last
// frame arrives. Illumination modes of thesis 5 and 6.2 (IlluminationMode below): STD, HDR-n,
// ADAPT-IT, ADAPT, TEXTURE, HF+ADAPT, ADAPTED-HF, each a strategy (illumination_strategy.h).
// Frames that are not stack frames (HDR exposures, ADAPT initialisation and iteration frames) are
// stored under raw/ in the stack. The integral methods (thesis 5.4, 6.4; reconstruction_method.h)
// replace the SFF engine: ISFF-GT correlates the frames with the simulated rig's ground-truth
// texture as they arrive; ISFF and ISFF-FAST run over the stored stack once it is complete.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/calibration/calibration_bundle.h"
#include "core/illumination/compensation.h"
#include "core/sff/depth_postprocess.h"
#include "core/sff/halo_suppression.h"
#include "core/sff/z_range_search.h"
#include "core/io/frame_statistics.h"
#include "core/sff/sff_engine.h"
#include "core/io/stack.h"
#include "core/registration/stack_alignment.h"
#include "core/util/status.h"
#include "devices/rig.h"
#include "server/procedures/reconstruction_method.h"

namespace inspection {

// Thesis 5-6.2. Names as in the thesis's tables: "STD", "HDR<n>", "ADAPT-IT", "ADAPT",
// "TEXTURE", "HF+ADAPT", "ADAPTED-HF".
enum class IlluminationMode {
  kStd,             // uniform grey 128 (uniform_grey), one frame per z
  kHdr,             // hdr_exposures frames per z at the relative exposures of Table 6.2, merged (eq. 3.44)
  kAdaptIterative,  // per z: compensate (eq. 5.5-5.6, 5.11) until the stop criterion
  kAdapt,           // predictive (eq. 5.12): one frame per z after 2 initialisation frames
  kTexture,         // checkerboard of eq. 5.16, period from eq. 5.15, exposure for STD's mean irradiance
  kHfAdapt,         // ADAPT with the modified checkerboard added (eq. 5.17-5.18)
  kAdaptedHf,       // ADAPT towards a 25 %/75 % checkerboard camera image (5.3.2)
  // One probe capture, then one of STD, TEXTURE, ADAPT, HF+ADAPT (illumination_auto.h); the
  // outcome records the mode that ran and why.
  kAuto,
};

struct IlluminationParams {
  int hdr_exposures = 3;          // 2..5: HDR2..HDR5 of Table 6.2
  double lambda = 0.25;           // prediction scale of eq. 5.12, [0, 2]
  double gamma = 0.0;             // checkerboard weight of eq. 5.16, [0, 0.5]
  double psi = 0.25;              // added checkerboard weight of eq. 5.17, [0, 1] (thesis 0.25-0.3)
  int max_iterations = 4;         // ADAPT-IT frames per z at most, 1..20
  double tolerance_grey = 6.0;    // ADAPT-IT: stop when mean |Z_c - 128| (8-bit units) is below,
  double min_improvement = 0.15;  // or improves by less than this share over the last iteration
  double target_grey = 140.0;     // desired camera grey (8-bit units), ADAPT family
  CompensationOptions compensation;
  Status Validate() const;
};

// "STD", "HDR3", ... as in the thesis.
std::string IlluminationModeName(IlluminationMode mode, int hdr_exposures = 3);

// The relative exposures (share of exposure_us) of Table 6.2 for HDR<n>, n = 2..5.
StatusOr<std::vector<double>> HdrRelativeExposures(int n);

// FAILED_PRECONDITION naming the missing calibration step(s) when `bundle` lacks a model the
// mode needs (HDR: camera_response; ADAPT family: camera_response, projector_response,
// scatter_matrix; TEXTURE: projector_response, geometry, psf; the combinations all five).
Status CheckCalibrationFor(IlluminationMode mode, const CalibrationBundle* bundle);

struct ScanPlan {
  std::vector<double> z_um;  // stage positions in acquisition order
  double exposure_us = 0.0;
  int uniform_grey = 128;  // STD projector pattern
  IlluminationMode mode = IlluminationMode::kStd;
  IlluminationParams params;
  SffOptions sff;
  ReconstructionMethodSettings reconstruction;  // SFF (sff above) or an integral method
  std::string calibration_id;                   // recorded in stack.json
  // Automatic z range (z_range_search.h): z_um is empty until the coarse sweep chose the range;
  // run the plan with RunScanWithZRangeSearch.
  std::optional<ZRangeSearchSettings> z_range_search;
  double z_step_um = 0.0;  // the fine step of an automatic z range (z_um is built from it)
  // Lateral alignment (scan_alignment.h): kNone or kCalibrated; nullopt = kCalibrated when the
  // bundle holds the focus_breathing model, else kNone.
  std::optional<FrameAlignment> alignment;
  // SFF: the engine runs with min_confidence 0 and this makes the map (core/sff/depth_postprocess.h),
  // thresholding at sff.min_confidence (postprocess.min_confidence is not used).
  DepthPostProcessOptions postprocess;
  // SFF: halo suppression on the stored frames before the post-processing (core/sff/stack_halo.h).
  std::optional<HaloSuppressionOptions> halo;
};

// Builds the z positions from start to end (inclusive when end falls on the grid) with step
// > 0, in the direction of end. Errors name the request field: z_step_um, z_start_um, ...
// The range must lie within the stage's travel and give 3..5000 frames.
StatusOr<ScanPlan> MakeScanPlan(double z_start_um, double z_end_um, double z_step_um, double exposure_us,
                                const Stage& stage);

struct ScanFrameEvent {
  int index = 0;
  int count = 0;
  double z_um = 0.0;  // position reported by the stage
  double exposure_us = 0.0;
  FrameStatistics statistics;
  int acquisition = 0;  // 0-based number of this capture in the scan (all captures)
  // false for HDR exposures, ADAPT initialisation frames and ADAPT-IT iterations that are not
  // kept. ADAPT-IT reports each iteration after its stop test, so the kept one says true.
  bool stack_frame = true;
  // A frame of the automatic z range's coarse sweep (z_range_search.h): index / count and
  // acquisition count within the sweep; the fine scan's events count from 0 again.
  bool z_range_search = false;
};

struct ScanOutcome {
  StackManifest manifest;
  DepthResult depth;
  cv::Mat ground_truth_um;  // simulated rig only; empty otherwise
  double acquisition_seconds = 0.0;
  double engine_finish_seconds = 0.0;               // time from the last frame to the depth map
  IntegralSffFigures isff;                          // integral methods only
  int images_acquired = 0;                          // every capture (thesis Table 6.3 #imgs)
  std::vector<FrameStatistics> capture_statistics;  // per capture, in order (Fig. 6.3)
  std::vector<bool> capture_is_stack_frame;
  // The mode that ran (AUTO: the one it chose) and, for AUTO, the decision and its reasons.
  IlluminationMode illumination = IlluminationMode::kStd;
  std::string illumination_decision;
  // The lateral alignment that ran. With alignment the depth map is in the middle frame's grid
  // (and so is ground_truth_um); the stack folder keeps the frames as captured.
  AlignmentFigures alignment;
  DepthPostProcessFigures postprocess;  // SFF only
  std::optional<HaloSuppressionFigures> halo;  // SFF with ScanPlan::halo
};

// Acquires into stack_dir (created; the caller owns clean-up on failure) and reconstructs.
// Returns CANCELLED as soon as `cancel` is seen between frames; device errors pass through
// (UNAVAILABLE, DEADLINE_EXCEEDED, OUT_OF_RANGE).
// Modes other than STD need `bundle` (see CheckCalibrationFor); it must outlive the call and
// match the rig's camera and projector size. The integral methods need illumination STD, ISFF
// and ISFF-FAST the bundle's IPSF, ISFF-GT the simulated rig (FAILED_PRECONDITION otherwise,
// before the first capture).
StatusOr<ScanOutcome> RunScan(Rig& rig, const ScanPlan& plan, const std::filesystem::path& stack_dir,
                              const std::function<void(const ScanFrameEvent&)>& on_frame,
                              const std::atomic<bool>& cancel, const CalibrationBundle* bundle);
// STD only (no calibration).
StatusOr<ScanOutcome> RunScan(Rig& rig, const ScanPlan& plan, const std::filesystem::path& stack_dir,
                              const std::function<void(const ScanFrameEvent&)>& on_frame,
                              const std::atomic<bool>& cancel);

}  // namespace inspection
