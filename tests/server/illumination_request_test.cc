// Scan requests for the illumination modes of thesis 5: parameters out of range name their
// field, and modes whose calibration models are missing fail with FAILED_PRECONDITION naming
// the calibration step, before any job is created.
#include <gtest/gtest.h>

#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

class IlluminationRequestTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
  }
};

TEST_F(IlluminationRequestTest, ParametersOutOfRangeNameTheField) {
  struct Case {
    void (*mutate)(v1::ScanRequest&);
    const char* field;
  };
  const Case cases[] = {
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_hdr_exposures(6); },
       "illumination_parameters.hdr_exposures"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_lambda(-0.1); },
       "illumination_parameters.lambda"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_gamma(0.7); },
       "illumination_parameters.gamma"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_psi(1.5); }, "illumination_parameters.psi"},
      {[](v1::ScanRequest& r) { r.mutable_illumination_parameters()->set_max_iterations(0); },
       "illumination_parameters.max_iterations"},
      {[](v1::ScanRequest& r) { r.set_illumination(static_cast<v1::IlluminationMode>(99)); }, "illumination"},
  };
  for (const Case& c : cases) {
    v1::ScanRequest r;
    c.mutate(r);
    v1::Job job;
    grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field;
    EXPECT_NE(s.error_message().find(c.field), std::string::npos) << c.field << ": " << s.error_message();
  }
}

TEST_F(IlluminationRequestTest, UncalibratedModesNameTheMissingStep) {
  const std::pair<v1::IlluminationMode, const char*> cases[] = {
      {v1::ILLUMINATION_MODE_HDR, "camera_response"},      {v1::ILLUMINATION_MODE_ADAPT, "scatter_matrix"},
      {v1::ILLUMINATION_MODE_ADAPT_IT, "projector_response"}, {v1::ILLUMINATION_MODE_TEXTURE, "psf"},
      {v1::ILLUMINATION_MODE_HF_ADAPT, "geometry"},        {v1::ILLUMINATION_MODE_ADAPTED_HF, "scatter_matrix"},
  };
  for (const auto& [mode, step] : cases) {
    v1::ScanRequest r;
    r.set_illumination(mode);
    v1::Job job;
    grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << v1::IlluminationMode_Name(mode);
    EXPECT_NE(s.error_message().find(step), std::string::npos) << s.error_message();
  }
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 0);
}

}  // namespace
}  // namespace inspection::testing
