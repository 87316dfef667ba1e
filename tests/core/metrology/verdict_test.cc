// ISO 14253-1 decisions: conformance and non-conformance zones, the uncertainty range between
// them, coverage and capability (2U vs the tolerance band), one-sided tolerances, the overall verdict.
#include "core/metrology/verdict.h"

#include <gtest/gtest.h>

#include <cmath>

namespace inspection {
namespace {

Tolerance Band(double nominal, double lower, double upper, double min_coverage = 90.0) {
  Tolerance t;
  t.nominal = nominal;
  t.lower = lower;
  t.upper = upper;
  t.min_coverage_percent = min_coverage;
  return t;
}

TEST(VerdictTest, ZonesOfIso14253) {
  const Tolerance t = Band(10.0, -0.5, 0.5);  // LSL 9.5, USL 10.5; u = 0.1 -> U = 0.2
  EXPECT_EQ(Judge(10.0, 0.1, 100, t).verdict, Verdict::kOk);
  EXPECT_EQ(Judge(10.29, 0.1, 100, t).verdict, Verdict::kOk);            // just below USL - U
  EXPECT_EQ(Judge(10.35, 0.1, 100, t).verdict, Verdict::kNotDecidable);  // within U of USL
  EXPECT_EQ(Judge(10.65, 0.1, 100, t).verdict, Verdict::kNotDecidable);  // outside, but within U
  EXPECT_EQ(Judge(10.75, 0.1, 100, t).verdict, Verdict::kNotOk);
  EXPECT_EQ(Judge(9.25, 0.1, 100, t).verdict, Verdict::kNotOk);
  const VerdictResult r = Judge(10.0, 0.1, 100, t);
  EXPECT_DOUBLE_EQ(r.expanded_uncertainty, 0.2);
  EXPECT_DOUBLE_EQ(r.conformance_lower, 9.7);
  EXPECT_DOUBLE_EQ(r.conformance_upper, 10.3);
  EXPECT_NE(Judge(10.35, 0.1, 100, t).reason.find("within U"), std::string::npos);
}

TEST(VerdictTest, CoverageAndCapabilityMakeItUndecidable) {
  const Tolerance t = Band(10.0, -0.5, 0.5, 95.0);
  const VerdictResult low = Judge(10.0, 0.01, 94.9, t);
  EXPECT_EQ(low.verdict, Verdict::kNotDecidable);
  EXPECT_NE(low.reason.find("coverage"), std::string::npos);
  // 2U = 1.2 >= band 1.0: conformance can never be proven...
  const VerdictResult wide = Judge(10.0, 0.3, 100, t);
  EXPECT_EQ(wide.verdict, Verdict::kNotDecidable);
  EXPECT_NE(wide.reason.find("tolerance band"), std::string::npos) << wide.reason;
  // ... but a value beyond USL + U is still a proven defect.
  EXPECT_EQ(Judge(11.2, 0.3, 100, t).verdict, Verdict::kNotOk);
  // No value or no uncertainty: nothing is proven.
  EXPECT_EQ(Judge(std::nan(""), 0.1, 100, t).verdict, Verdict::kNotDecidable);
  EXPECT_EQ(Judge(10.0, std::nan(""), 100, t).verdict, Verdict::kNotDecidable);
  EXPECT_EQ(NotMeasured("fit failed").verdict, Verdict::kNotDecidable);
}

TEST(VerdictTest, OneSidedTolerances) {
  Tolerance upper_only;
  upper_only.nominal = 0.0;
  upper_only.upper = 0.8;  // e.g. Sa <= 0.8 um
  EXPECT_EQ(Judge(0.5, 0.1, 100, upper_only).verdict, Verdict::kOk);
  EXPECT_EQ(Judge(0.7, 0.1, 100, upper_only).verdict, Verdict::kNotDecidable);
  EXPECT_EQ(Judge(1.1, 0.1, 100, upper_only).verdict, Verdict::kNotOk);
  EXPECT_EQ(Judge(-50.0, 0.1, 100, upper_only).verdict, Verdict::kOk);  // no lower limit
  EXPECT_TRUE(std::isinf(Judge(0.5, 0.1, 100, upper_only).conformance_lower));
}

TEST(VerdictTest, ToleranceValidationNamesTheField) {
  Tolerance t = Band(1.0, 0.1, -0.1);
  const Status s = t.Validate("measurements[4].tolerance");
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("measurements[4].tolerance"), std::string::npos);
  EXPECT_NE(s.message().find("exceeds upper"), std::string::npos) << s.message();
  Tolerance none;
  EXPECT_EQ(none.Validate("t").code(), StatusCode::kInvalidArgument);
  Tolerance cov = Band(1.0, -0.1, 0.1, 120.0);
  EXPECT_NE(cov.Validate("t").message().find("min_coverage_percent"), std::string::npos);
  EXPECT_TRUE(Band(1.0, -0.1, 0.1).Validate("t").ok());
}

TEST(VerdictTest, OverallVerdictLetsAProvenDefectDecide) {
  using V = Verdict;
  EXPECT_EQ(OverallVerdict({V::kOk, V::kOk}), V::kOk);
  EXPECT_EQ(OverallVerdict({V::kOk, V::kNotDecidable}), V::kNotDecidable);
  EXPECT_EQ(OverallVerdict({V::kNotDecidable, V::kNotOk, V::kOk}), V::kNotOk);
  EXPECT_EQ(OverallVerdict({}), V::kNotDecidable);
  EXPECT_STREQ(VerdictName(V::kNotDecidable), "NOT_DECIDABLE");
}

}  // namespace
}  // namespace inspection
