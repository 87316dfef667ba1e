// SFF post-processing through the real server: ReconstructionOptions
// depth_consistency (default on), refinement, fill_low_confidence (and halo_suppression's refusal
// with an integral method) on scans and on stored
// stacks, the DepthSummary figures, and bad input naming the field.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>

#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

class DepthPostProcessApiTest : public ServerTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o;
    o.specimen = "cutter";  // steep flanks and glints: where focus windows straddle depth steps
    o.seed = 3;
    o.camera_size = {256, 192};
    return o;
  }
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
  }

  int JobCount() {
    v1::ListJobsResponse jobs;
    EXPECT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
    return jobs.jobs_size();
  }

  v1::DepthSummary Reconstruct(const std::string& scan_id, const v1::ReconstructionOptions& options) {
    v1::ReconstructStart start;
    start.set_scan_id(scan_id);
    *start.mutable_options() = options;
    start.mutable_options()->set_alignment(v1::FRAME_ALIGNMENT_NONE);  // the same pixels every time
    v1::Job job;
    const grpc::Status s = client_->ReconstructStored(start, nullptr, &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
    return job.result().depth();
  }
};

TEST_F(DepthPostProcessApiTest, BadOptionsNameTheFieldAndQueueNothing) {
  const int before = JobCount();
  struct Case {
    std::function<void(v1::ReconstructionOptions*)> set;
    const char* field;
  };
  const Case cases[] = {
      {[](v1::ReconstructionOptions* o) {
         o->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
         o->set_depth_consistency(false);
       },
       "reconstruction.depth_consistency"},
      {[](v1::ReconstructionOptions* o) {
         o->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
         o->set_fill_low_confidence(true);
       },
       "reconstruction.fill_low_confidence"},
      {[](v1::ReconstructionOptions* o) {
         o->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
         o->set_refinement(v1::DEPTH_REFINEMENT_METHOD_GUIDED_FILTER);
       },
       "reconstruction.refinement"},
      {[](v1::ReconstructionOptions* o) { o->set_refinement(static_cast<v1::DepthRefinementMethod>(42)); },
       "reconstruction.refinement"},
      {[](v1::ReconstructionOptions* o) {
         o->set_method(v1::RECONSTRUCTION_METHOD_ISFF_GT);
         o->set_halo_suppression(true);
       },
       "reconstruction.halo_suppression"},
  };
  for (const Case& c : cases) {
    v1::ScanRequest r;
    c.set(r.mutable_reconstruction());
    v1::Job job;
    const grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field;
    EXPECT_NE(s.error_message().find(c.field), std::string::npos) << s.error_message();
  }
  EXPECT_EQ(JobCount(), before);
}

TEST_F(DepthPostProcessApiTest, ConsistencyRejectsWrongDepthsAndFillCompletesTheMap) {
  v1::Job scan;
  ASSERT_TRUE(client_->Scan(v1::ScanRequest(), nullptr, &scan).ok());
  ASSERT_EQ(scan.state(), v1::JOB_STATE_SUCCEEDED) << scan.error_message();
  const v1::DepthSummary& scanned = scan.result().depth();
  EXPECT_GT(scanned.consistency_rejected_percent(), 0.0);  // on by default
  EXPECT_EQ(scanned.filled_percent(), 0.0);

  // The same stored stack three ways: the differences are the post-processing alone.
  const std::string id = scan.result().scan_id();
  v1::ReconstructionOptions plain;
  plain.set_depth_consistency(false);
  const v1::DepthSummary off = Reconstruct(id, plain);
  const v1::DepthSummary on = Reconstruct(id, v1::ReconstructionOptions());
  v1::ReconstructionOptions filled;
  filled.set_fill_low_confidence(true);
  const v1::DepthSummary full = Reconstruct(id, filled);
  std::printf(
      "cutter: without consistency valid %.2f %% RMSE %.3f um; with it valid %.2f %% (rejected %.2f %%) RMSE %.3f "
      "um; filled: valid %.2f %% (filled %.2f %%) RMSE %.3f um\n",
      off.valid_percent(), off.rmse_um(), on.valid_percent(), on.consistency_rejected_percent(), on.rmse_um(),
      full.valid_percent(), full.filled_percent(), full.rmse_um());
  EXPECT_EQ(off.consistency_rejected_percent(), 0.0);
  ASSERT_GT(on.consistency_rejected_percent(), 0.5);
  // Exactly the rejected pixels are missing.
  EXPECT_NEAR(on.valid_percent() + on.consistency_rejected_percent(), off.valid_percent(), 1e-6);
  // They were the wrong ones: the kept depth is closer to the truth.
  ASSERT_TRUE(off.has_ground_truth() && on.has_ground_truth());
  EXPECT_LT(on.rmse_um(), 0.8 * off.rmse_um());
  // Fill: every pixel gets a depth and the summary says how many were interpolated.
  EXPECT_DOUBLE_EQ(full.valid_percent(), 100.0);
  EXPECT_NEAR(full.filled_percent(), 100.0 - on.valid_percent(), 1e-6);
  EXPECT_NEAR(full.consistency_rejected_percent(), on.consistency_rejected_percent(), 1e-9);
  // Refinement keeps the pixels it was given.
  v1::ReconstructionOptions refined;
  refined.set_refinement(v1::DEPTH_REFINEMENT_METHOD_WEIGHTED_MEDIAN);
  const v1::DepthSummary wm = Reconstruct(id, refined);
  EXPECT_DOUBLE_EQ(wm.valid_percent(), on.valid_percent());
}

}  // namespace
}  // namespace inspection::testing
