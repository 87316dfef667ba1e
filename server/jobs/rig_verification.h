// The rig's instrument verification as the server keeps it (docs/verification.md): records of
// RunVerification (server/procedures/verification_procedure.h) as the API's VerificationRecord,
// stored per calibration; the rig's verification state (verified / due / failed) from the newest
// full and interim record under the active calibration; the verified characteristics the
// uncertainty model takes from the last full one (core/metrology/depth_noise_model.h).
#pragma once

#include <chrono>
#include <optional>
#include <string>

#include "core/metrology/depth_noise_model.h"
#include "core/util/status.h"
#include "inspection/v1/inspection.pb.h"
#include "server/procedures/verification_procedure.h"
#include "server/storage/data_store.h"

namespace inspection {

// A full verification is due again after this long unless inspectd's verification_interval_days
// says otherwise (ISO 25178-700 leaves the interval to the user; a month is the usual interval
// between full verifications of an areal instrument in production, the interim check in between).
// Each full record carries its own next_full_due; a record without one (an older inspectd's) is
// valid for this long.
inline constexpr double kFullVerificationIntervalDays = 30.0;

// The validity of `full` in days: next_full_due - finish_time, or kFullVerificationIntervalDays.
double FullIntervalDays(const v1::VerificationRecord& full);

// The characteristics, values and standard uncertainties with U = 2u, the step and sinusoid
// points, the mode and the scan count; ids, time, calibration and state are the caller's.
v1::VerificationRecord VerificationRecordProto(const VerificationRecord& record);
// Back for EvaluateInterimCheck (only what the API record holds).
VerificationRecord VerificationRecordFromProto(const v1::VerificationRecord& record);

// The characteristic named `name` ("alpha_z", ...); nullptr when the record has none.
const v1::VerificationCharacteristic* FindCharacteristic(const v1::VerificationRecord& record,
                                                         const std::string& name);

struct RigVerification {
  v1::VerificationState state = v1::VERIFICATION_STATE_DUE;
  std::string detail;  // why due or failed, one line; empty when verified
  std::optional<v1::VerificationRecord> full;     // the newest full verification under the calibration
  std::optional<v1::VerificationRecord> interim;  // the newest interim check under it
};

// Days between two record times (b - a).
double DaysBetween(const google::protobuf::Timestamp& a, const google::protobuf::Timestamp& b);

// DUE without a full verification under calibration_id, or when it is older than its
// FullIntervalDays at `now`; FAILED (or DUE) as the newest interim check decided
// when it is newer than the full one; VERIFIED otherwise.
StatusOr<RigVerification> ReadRigVerification(DataStore& store, const std::string& calibration_id,
                                              const google::protobuf::Timestamp& now);

// The interim check of `interim` (its state, findings and full_verification_id set) against
// `full` (nullptr: none on record) at `now`.
void JudgeInterim(const v1::VerificationRecord* full, v1::VerificationRecord* interim,
                  const google::protobuf::Timestamp& now);

// What the uncertainty model takes from a full verification (VerifiedCharacteristics): alpha_z
// with its u, l_z as the bound l_z + 2u, N_M and z_FLT carried. Empty when a value is missing or
// out of the model's range (VerifiedCharacteristics::Validate).
VerifiedCharacteristics VerifiedFrom(const v1::VerificationRecord& full);

// The warning a result made in this state carries; empty when VERIFIED.
std::string VerificationWarning(const RigVerification& verification);

google::protobuf::Timestamp CurrentTimestamp();

}  // namespace inspection
