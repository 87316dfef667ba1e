// Type-1 gauge capability against figures computed independently (Python statistics module for
// mean and s, a numerical integration of Student's t density for the p-value) and the t table.
#include "core/metrology/capability.h"

#include <gtest/gtest.h>

#include <cmath>

namespace inspection {
namespace {

// Ten repeats of a 10.000 mm gauge block certified at 9.9995, tolerance T = 0.1.
Type1StudyInput GaugeBlock() {
  Type1StudyInput in;
  in.values = {10.002, 9.998, 10.001, 10.003, 9.997, 10.000, 10.002, 9.999, 10.001, 10.004};
  in.reference = 9.9995;
  in.tolerance = 0.1;
  in.expanded_uncertainty = 0.004;
  return in;
}

TEST(CapabilityTest, CgCgkAndTheBiasTestMatchIndependentFigures) {
  auto c = ComputeType1Capability(GaugeBlock());
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(c->n, 10);
  EXPECT_NEAR(c->mean, 10.0007, 1e-12);
  EXPECT_NEAR(c->stddev, 0.0022135943621179404, 1e-12);
  EXPECT_NEAR(c->bias, 0.0012, 1e-12);
  EXPECT_NEAR(c->cg, 1.5058465048420349, 1e-9);   // 0.2 T / 6 s
  EXPECT_NEAR(c->cgk, 1.3251449242608768, 1e-9);  // (0.1 T - |bias|) / 3 s
  EXPECT_NEAR(c->t_statistic, 1.7142857142867365, 1e-9);
  EXPECT_NEAR(c->t_critical, 2.262157, 1e-6);  // t(0.975, 9), the table's value
  EXPECT_NEAR(c->p_value, 0.1206207, 1e-6);
  EXPECT_FALSE(c->bias_significant);
  EXPECT_NEAR(c->u_over_t_percent, 4.0, 1e-12);
  // Cg passes, Cgk misses 1.33 by a hair: not capable, and the reason says which.
  EXPECT_FALSE(c->capable);
  EXPECT_NE(c->reason.find("Cgk 1.325 < 1.33"), std::string::npos) << c->reason;
}

TEST(CapabilityTest, ASignificantBiasIsFlaggedAndACapableGaugePasses) {
  Type1StudyInput in = GaugeBlock();
  in.reference = 9.9985;  // bias 0.0022: t = 3.14 > 2.262
  auto biased = ComputeType1Capability(in);
  ASSERT_TRUE(biased.ok());
  EXPECT_TRUE(biased->bias_significant);
  EXPECT_LT(biased->p_value, 0.05);
  EXPECT_FALSE(biased->capable);

  in = GaugeBlock();
  in.tolerance = 0.2;  // Cg 3.01, Cgk (0.02 - 0.0012) / 3 s = 2.83
  auto wide = ComputeType1Capability(in);
  ASSERT_TRUE(wide.ok());
  EXPECT_NEAR(wide->cg, 2 * 1.5058465048420349, 1e-9);
  EXPECT_NEAR(wide->cgk, (0.02 - 0.0012) / (3 * 0.0022135943621179404), 1e-9);
  EXPECT_TRUE(wide->capable);
  EXPECT_EQ(wide->reason.rfind("capable", 0), 0u) << wide->reason;
}

TEST(CapabilityTest, StudentTQuantilesAgreeWithTheTable) {
  EXPECT_NEAR(StudentTTwoSidedQuantile(0.05, 24), 2.063899, 1e-6);
  EXPECT_NEAR(StudentTTwoSidedQuantile(0.05, 49), 2.009575, 1e-6);
  EXPECT_NEAR(StudentTTwoSidedPValue(2.063899, 24), 0.05, 1e-6);
}

TEST(CapabilityTest, BadInputNamesTheField) {
  Type1StudyInput in = GaugeBlock();
  in.values.resize(9);
  auto few = ComputeType1Capability(in);
  ASSERT_EQ(few.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(few.status().message().find("repeats"), std::string::npos);
  in = GaugeBlock();
  in.values[3] = std::nan("");
  EXPECT_NE(ComputeType1Capability(in).status().message().find("values[3]"), std::string::npos);
  in = GaugeBlock();
  in.tolerance = 0.0;
  EXPECT_NE(ComputeType1Capability(in).status().message().find("tolerance"), std::string::npos);
}

TEST(CapabilityTest, ZeroSpreadIsInfinitelyCapableUnlessTheBiasEatsTheMargin) {
  Type1StudyInput in;
  in.values.assign(10, 1.0);
  in.reference = 1.0;
  in.tolerance = 0.1;
  auto c = ComputeType1Capability(in);
  ASSERT_TRUE(c.ok());
  EXPECT_TRUE(std::isinf(c->cg));
  EXPECT_TRUE(c->capable);
  EXPECT_EQ(c->t_statistic, 0.0);
  in.reference = 0.98;  // bias 0.02 > 0.1 T
  c = ComputeType1Capability(in);
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(c->capable);
  EXPECT_TRUE(c->bias_significant);
}

}  // namespace
}  // namespace inspection
