// Gauge capability from a Type-1 study (VDA 5, Bosch booklet 10, AIAG MSA "Type 1 gauge study"):
// one reference part of known value measured n times by the gauge as it is used in production
// (the part re-positioned between repeats), judged against the tolerance T = USL - LSL of the
// characteristic it will decide:
//   Cg  = 0.2 T / (6 s)                      spread alone, 20 % of T against 6 s
//   Cgk = (0.1 T - |mean - reference|) / (3 s)   spread and bias together
// with s the sample standard deviation (n - 1). The gauge is capable when both are >= 1.33.
// The bias mean - reference is tested against 0 with Student's t (n - 1 degrees of freedom,
// two-sided, alpha 5 %): a significant bias is a systematic error a correction could remove.
// U/T relates the measurement's own expanded uncertainty to the tolerance (VDA 5 asks for it to be
// small: a capable gauge whose claimed U is a large share of T still decides few parts).
#pragma once

#include <limits>
#include <string>
#include <vector>

#include "core/util/status.h"

namespace inspection {

inline constexpr double kMinGaugeCapability = 1.33;  // Cg and Cgk, VDA 5 / Bosch booklet 10
inline constexpr int kMinType1Repeats = 10;          // fewer: s and the t-test say too little
inline constexpr int kMaxType1Repeats = 1000;

struct Type1StudyInput {
  std::vector<double> values;  // the repeats' values, all finite
  double reference = 0.0;      // the reference part's (certified) value
  double tolerance = 0.0;      // T = USL - LSL, > 0
  // The measurements' mean expanded uncertainty U (k = 2); NaN = not known (u_over_t NaN).
  double expanded_uncertainty = std::numeric_limits<double>::quiet_NaN();
  double alpha = 0.05;  // significance level of the bias test (two-sided)
};

struct GaugeCapability {
  int n = 0;
  double mean = 0.0;
  double stddev = 0.0;  // sample standard deviation (n - 1)
  double bias = 0.0;    // mean - reference
  // +infinity when s = 0 (and, for Cgk, the bias is within 0.1 T).
  double cg = 0.0;
  double cgk = 0.0;
  // Student's t of the bias: t = bias / (s / sqrt n); t_critical the two-sided quantile
  // t(1 - alpha/2, n - 1); p_value two-sided. s = 0: t is +-infinity (0 without bias), p 0 (1).
  double t_statistic = 0.0;
  double t_critical = 0.0;
  double p_value = 1.0;
  bool bias_significant = false;
  double u_over_t_percent = std::numeric_limits<double>::quiet_NaN();  // 100 U / T
  bool capable = false;  // Cg >= 1.33 and Cgk >= 1.33
  std::string reason;    // one line: what decided `capable`
};

// INVALID_ARGUMENT naming the field: fewer than kMinType1Repeats values ("repeats"), a
// non-finite value ("values[i]"), tolerance <= 0 or non-finite ("tolerance"), a non-finite
// reference ("reference"), alpha outside (0, 0.5] ("alpha").
StatusOr<GaugeCapability> ComputeType1Capability(const Type1StudyInput& input);

// Two-sided Student t quantile t(1 - alpha/2, dof) and the two-sided p-value of |t| (Boost.Math).
double StudentTTwoSidedQuantile(double alpha, int dof);
double StudentTTwoSidedPValue(double t, int dof);

}  // namespace inspection
