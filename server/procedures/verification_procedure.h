// Verification of the instrument (ISO 25178-700) on the rig: scans the ISO 25178-70 material
// measures the rig offers (devices/rig.h MaterialMeasure) and determines the ISO 25178-600
// metrological characteristics with core/metrology/verification.h, each with its uncertainty:
// N_M and z_FLT from two repeats of the flat (AFL), alpha_z and l_z from the step heights (PGR),
// alpha_x / alpha_y from the cross grating (ACG), W_R from the sinusoids (ASG). The interim check
// scans the flat (twice) and one step only. The rig's specimen is put back when it ends,
// however it ends.
#pragma once

#include <atomic>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/metrology/verification.h"
#include "core/sff/sff_options.h"
#include "core/util/status.h"
#include "devices/rig.h"
#include "server/procedures/scan_procedure.h"

namespace inspection {

enum class VerificationMode {
  kFull,     // every measure: N_M, z_FLT, alpha_z, l_z, alpha_x, alpha_y, W_R
  kInterim,  // the flat (two repeats) and one step: N_M, z_FLT and that step's alpha_z
};

struct VerificationPlan {
  VerificationMode mode = VerificationMode::kFull;
  double z_step_um = 2.0;  // stage step of every scan (> 0)
  // Every scan covers the measure's heights (the rig's scan defaults for it) and this margin
  // beyond them on each side, so each pixel's focus curve is whole.
  double margin_um = 10.0;
  SffOptions sff;  // window_px is also the correlation length of the depth noise
  // Interim check: the step height it scans (the PGR nearest this certified depth).
  double interim_step_um = 10.0;
  Status Validate() const;  // INVALID_ARGUMENT naming the field
};

// One step height's evaluation: ISO 5436-1 type A1 (see GrooveDepth).
struct VerificationStep {
  std::string specimen;
  ResponsePoint point;
};
struct VerificationSinusoid {
  std::string specimen;
  TransferPoint point;
};

// The verification record; uncertainties are standard (k = 1), reports show U = 2u.
struct VerificationRecord {
  VerificationMode mode = VerificationMode::kFull;
  CharacteristicEstimate noise_um;     // N_M
  CharacteristicEstimate flatness_um;  // z_FLT
  CharacteristicEstimate alpha_z;      // full: slope over the steps; interim: measured / certified of the one step
  CharacteristicEstimate l_z_um;       // full only (0 otherwise)
  CharacteristicEstimate alpha_x, alpha_y;  // full only
  CharacteristicEstimate w_r_um;            // full only
  std::vector<VerificationStep> steps;
  std::vector<VerificationSinusoid> sinusoids;
  int scans = 0;
};

// Progress: a scan's frame events (measure `index` of `count`, its specimen) and, after each
// measure is evaluated, a message.
struct VerificationProgress {
  int index = 0;
  int count = 0;
  std::string specimen;
  std::string message;
};

// FAILED_PRECONDITION naming `material_measures` when the rig offers none (a real rig, or a
// simulated one without them) or lacks one the mode needs (AFL; PGR: two for full, one for interim;
// ACG, two ASG for full). CANCELLED between frames and scans once `cancel` is set. Device errors
// pass through, prefixed with the measure. Scans go into folders below work_dir, removed as each
// is evaluated (work_dir itself when the run ends).
StatusOr<VerificationRecord> RunVerification(
    Rig& rig, const VerificationPlan& plan, const std::filesystem::path& work_dir,
    const std::function<void(const ScanFrameEvent&, const VerificationProgress&)>& on_frame,
    const std::function<void(const VerificationProgress&)>& on_measure, const std::atomic<bool>& cancel);

std::string VerificationModeName(VerificationMode mode);  // "full", "interim"

// The rig's verification state after an interim check (docs/verification.md).
enum class VerificationState {
  kVerified,  // the interim check agrees with the last full verification
  kDue,       // no full verification on record, or the last one is older than its interval
  kFailed,    // an interim characteristic left the limits the last full verification sets
};
std::string VerificationStateName(VerificationState state);  // "verified", "verification due", "verification failed"

struct InterimCheckResult {
  VerificationState state = VerificationState::kVerified;
  std::vector<std::string> findings;  // one line per characteristic out of its limit, or why due
};

// Limits from the last full verification `full` (nullptr: none on record -> kDue): the interim
// check fails when its N_M or z_FLT exceed the full's by more than the combined expanded
// uncertainty 2 sqrt(u_interim^2 + u_full^2), or when its step's measured height differs from the
// full verification's measurement of the same measure by more than that (a z scale or offset
// change). full_age_days > full_interval_days (both days, interval > 0) makes a passing check kDue.
InterimCheckResult EvaluateInterimCheck(const VerificationRecord* full, const VerificationRecord& interim,
                                        double full_age_days, double full_interval_days);

}  // namespace inspection
