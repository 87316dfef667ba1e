// Conformance decision per ISO 14253-1 (decision rules for proving conformity or
// non-conformity with specifications): a measured value with expanded uncertainty U = k u
// (k = 2) against a tolerance, plus the region's coverage, gives OK, NOT_OK or NOT_DECIDABLE;
// an inspection's overall verdict follows from its measurements.
//
// Rule (ISO 14253-1:2017 5.2/5.3, the uncertainty counted against whoever proves):
//   conformance zone     [LSL + U, USL - U]  -> OK (conformance proven)
//   non-conformance zone  value < LSL - U or value > USL + U -> NOT_OK (non-conformance proven)
//   uncertainty range     anything between  -> NOT_DECIDABLE
// and before that: NOT_DECIDABLE when the coverage is below the minimum (the value does not
// represent the region), when there is no finite value or uncertainty, or when 2U is at least
// the tolerance band (USL - LSL: the conformance zone is empty, the measurement is not capable of
// proving conformance) and non-conformance is not proven either. A proven non-conformance stays
// NOT_OK even when the measurement is not capable: a part far outside its limits is rejected.
// One-sided tolerances have only the limit they state.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

enum class Verdict {
  kOk,            // conformance proven
  kNotOk,         // non-conformance proven
  kNotDecidable,  // neither (uncertainty range, coverage, or not measured)
};

const char* VerdictName(Verdict v);  // "OK", "NOT_OK", "NOT_DECIDABLE"

struct Tolerance {
  double nominal = 0.0;
  // Tolerances relative to the nominal (e.g. -0.05 / +0.05): limits LSL = nominal + lower,
  // USL = nominal + upper. Either may be absent (one-sided), not both.
  std::optional<double> lower;
  std::optional<double> upper;
  double min_coverage_percent = 0.0;  // 0..100: measured share of the region needed for a decision
  double coverage_factor = 2.0;       // k of U = k u (ISO 14253-1 works with U at k = 2)

  // INVALID_ARGUMENT naming `field`.lower/.upper/...: non-finite numbers, lower > upper, no limit
  // at all, coverage outside 0..100, k <= 0.
  Status Validate(const std::string& field) const;
  std::optional<double> lower_limit() const;  // LSL
  std::optional<double> upper_limit() const;  // USL
};

struct VerdictResult {
  Verdict verdict = Verdict::kNotDecidable;
  std::string reason;                 // one line, for the report: why this verdict
  double expanded_uncertainty = 0.0;  // U = k u
  // The conformance zone actually used ([LSL + U, USL - U]); absent sides are +-infinity.
  double conformance_lower = 0.0;
  double conformance_upper = 0.0;
};

// value and standard_uncertainty (k = 1) of one measurement, coverage_percent of its region(s).
VerdictResult Judge(double value, double standard_uncertainty, double coverage_percent, const Tolerance& tolerance);

// A measurement that could not be made (fit failed, no pixels): NOT_DECIDABLE with the reason.
VerdictResult NotMeasured(const std::string& reason);

// Overall verdict of an inspection: NOT_OK if any measurement is NOT_OK (a proven defect decides),
// else NOT_DECIDABLE if any is NOT_DECIDABLE (or there are none), else OK.
Verdict OverallVerdict(const std::vector<Verdict>& verdicts);

}  // namespace inspection
