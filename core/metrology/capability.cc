// Type-1 gauge capability (Cg, Cgk, bias t-test) with Boost.Math's Student t distribution.
#include "core/metrology/capability.h"

#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <cstdio>

namespace inspection {

double StudentTTwoSidedQuantile(double alpha, int dof) {
  boost::math::students_t dist(dof);
  return boost::math::quantile(boost::math::complement(dist, alpha / 2.0));
}

double StudentTTwoSidedPValue(double t, int dof) {
  if (std::isinf(t)) return 0.0;
  boost::math::students_t dist(dof);
  return 2.0 * boost::math::cdf(boost::math::complement(dist, std::abs(t)));
}

StatusOr<GaugeCapability> ComputeType1Capability(const Type1StudyInput& in) {
  const int n = int(in.values.size());
  if (n < kMinType1Repeats) {
    return Status::InvalidArgument("repeats: a Type-1 study needs at least " + std::to_string(kMinType1Repeats) +
                                   " measured values, got " + std::to_string(n));
  }
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(in.values[i])) return Status::InvalidArgument("values[" + std::to_string(i) + "] is not finite");
  }
  if (!std::isfinite(in.tolerance) || in.tolerance <= 0.0) {
    return Status::InvalidArgument("tolerance: T = USL - LSL must be > 0 (a two-sided tolerance)");
  }
  if (!std::isfinite(in.reference)) return Status::InvalidArgument("reference must be finite");
  if (!(in.alpha > 0.0 && in.alpha <= 0.5)) return Status::InvalidArgument("alpha must be in (0, 0.5]");

  GaugeCapability c;
  c.n = n;
  double sum = 0.0;
  for (double v : in.values) sum += v;
  c.mean = sum / n;
  double ss = 0.0;
  for (double v : in.values) ss += (v - c.mean) * (v - c.mean);
  c.stddev = std::sqrt(ss / (n - 1));
  c.bias = c.mean - in.reference;
  const double inf = std::numeric_limits<double>::infinity();
  const double margin = 0.1 * in.tolerance - std::abs(c.bias);
  if (c.stddev > 0.0) {
    c.cg = 0.2 * in.tolerance / (6.0 * c.stddev);
    c.cgk = margin / (3.0 * c.stddev);
    c.t_statistic = c.bias / (c.stddev / std::sqrt(double(n)));
  } else {
    c.cg = inf;
    c.cgk = margin >= 0.0 ? inf : -inf;
    c.t_statistic = c.bias == 0.0 ? 0.0 : std::copysign(inf, c.bias);
  }
  c.t_critical = StudentTTwoSidedQuantile(in.alpha, n - 1);
  c.p_value = StudentTTwoSidedPValue(c.t_statistic, n - 1);
  c.bias_significant = std::abs(c.t_statistic) > c.t_critical;
  if (std::isfinite(in.expanded_uncertainty)) c.u_over_t_percent = 100.0 * in.expanded_uncertainty / in.tolerance;
  c.capable = c.cg >= kMinGaugeCapability && c.cgk >= kMinGaugeCapability;
  char line[256];
  if (c.capable) {
    std::snprintf(line, sizeof line, "capable: Cg %.3f and Cgk %.3f >= %.2f", c.cg, c.cgk, kMinGaugeCapability);
  } else if (c.cg < kMinGaugeCapability) {
    std::snprintf(line, sizeof line, "not capable: Cg %.3f < %.2f (spread 6s = %.4g against 0.2 T = %.4g)", c.cg,
                  kMinGaugeCapability, 6.0 * c.stddev, 0.2 * in.tolerance);
  } else {
    std::snprintf(line, sizeof line, "not capable: Cgk %.3f < %.2f (bias %.4g%s)", c.cgk, kMinGaugeCapability, c.bias,
                  c.bias_significant ? ", significant" : ", not significant");
  }
  c.reason = line;
  return c;
}

}  // namespace inspection
