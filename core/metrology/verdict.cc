// ISO 14253-1 conformance decisions with coverage and capability checks.
#include "core/metrology/verdict.h"

#include <cmath>
#include <cstdio>
#include <limits>

namespace inspection {
namespace {

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

const char* VerdictName(Verdict v) {
  switch (v) {
    case Verdict::kOk:
      return "OK";
    case Verdict::kNotOk:
      return "NOT_OK";
    case Verdict::kNotDecidable:
      return "NOT_DECIDABLE";
  }
  return "NOT_DECIDABLE";
}

Status Tolerance::Validate(const std::string& field) const {
  if (!std::isfinite(nominal)) return Status::InvalidArgument(field + ".nominal is not a finite number");
  if (lower && !std::isfinite(*lower)) return Status::InvalidArgument(field + ".lower is not a finite number");
  if (upper && !std::isfinite(*upper)) return Status::InvalidArgument(field + ".upper is not a finite number");
  if (!lower && !upper) return Status::InvalidArgument(field + ": needs a lower or an upper tolerance (or both)");
  if (lower && upper && *lower > *upper) {
    return Status::InvalidArgument(field + ": lower tolerance " + Num(*lower) + " exceeds upper tolerance " +
                                   Num(*upper));
  }
  if (!(min_coverage_percent >= 0.0 && min_coverage_percent <= 100.0)) {
    return Status::InvalidArgument(field + ".min_coverage_percent must be in 0..100, got " + Num(min_coverage_percent));
  }
  if (!(coverage_factor > 0.0) || !std::isfinite(coverage_factor)) {
    return Status::InvalidArgument(field + ".coverage_factor must be > 0");
  }
  return Status::Ok();
}

std::optional<double> Tolerance::lower_limit() const {
  if (!lower) return std::nullopt;
  return nominal + *lower;
}

std::optional<double> Tolerance::upper_limit() const {
  if (!upper) return std::nullopt;
  return nominal + *upper;
}

VerdictResult Judge(double value, double standard_uncertainty, double coverage_percent, const Tolerance& tolerance) {
  VerdictResult r;
  const double inf = std::numeric_limits<double>::infinity();
  const double lsl = tolerance.lower_limit().value_or(-inf), usl = tolerance.upper_limit().value_or(inf);
  r.expanded_uncertainty = tolerance.coverage_factor * standard_uncertainty;
  const double u = r.expanded_uncertainty;
  r.conformance_lower = lsl + u;
  r.conformance_upper = usl - u;
  if (!(coverage_percent >= tolerance.min_coverage_percent)) {
    r.verdict = Verdict::kNotDecidable;
    r.reason =
        "coverage " + Num(coverage_percent) + " % is below the minimum " + Num(tolerance.min_coverage_percent) + " %";
    return r;
  }
  if (!std::isfinite(value)) {
    r.reason = "no finite value";
    return r;
  }
  if (!(standard_uncertainty >= 0.0) || !std::isfinite(standard_uncertainty)) {
    r.reason = "no uncertainty for the value";
    return r;
  }
  if (value < lsl - u || value > usl + u) {
    r.verdict = Verdict::kNotOk;
    r.reason = "non-conformance proven: " + Num(value) +
               (value < lsl - u ? " < LSL - U = " + Num(lsl - u) : " > USL + U = " + Num(usl + u));
    return r;
  }
  if (std::isfinite(usl - lsl) && 2.0 * u >= usl - lsl) {
    r.reason = "2U = " + Num(2.0 * u) + " is not below the tolerance band " + Num(usl - lsl) +
               ": conformance cannot be proven";
    return r;
  }
  if (value >= lsl + u && value <= usl - u) {
    r.verdict = Verdict::kOk;
    r.reason = "conformance proven: " + Num(value) + " within [LSL + U, USL - U]";
    return r;
  }
  r.reason = "within U = " + Num(u) + " of a limit: neither conformance nor non-conformance proven";
  return r;
}

VerdictResult NotMeasured(const std::string& reason) {
  VerdictResult r;
  r.verdict = Verdict::kNotDecidable;
  r.reason = "not measured: " + reason;
  r.expanded_uncertainty = std::nan("");
  r.conformance_lower = r.conformance_upper = std::nan("");
  return r;
}

Verdict OverallVerdict(const std::vector<Verdict>& verdicts) {
  if (verdicts.empty()) return Verdict::kNotDecidable;
  bool undecided = false;
  for (Verdict v : verdicts) {
    if (v == Verdict::kNotOk) return Verdict::kNotOk;
    undecided |= v == Verdict::kNotDecidable;
  }
  return undecided ? Verdict::kNotDecidable : Verdict::kOk;
}

}  // namespace inspection
