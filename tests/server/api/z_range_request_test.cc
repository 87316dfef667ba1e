// Automatic z range through the real server (ScanRequest.z_range_search): bad input is
// INVALID_ARGUMENT naming the field before any job exists; a search on the simulated rig with the
// specimen placed off the rig's default range reports both phases in its events, records the
// search in the result and in stack.json, and its range holds the specimen's true heights.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>

#include "server/procedures/z_range_search.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

class ZRangeRequestTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
  }
};

TEST_F(ZRangeRequestTest, BadInputIsInvalidArgumentNamingTheField) {
  struct Case {
    void (*mutate)(v1::ScanRequest&);
    const char* field;
  };
  const Case cases[] = {
      // A window outside the stage travel (simulated rig: 0 .. 25000 um).
      {[](v1::ScanRequest& r) {
         r.mutable_z_range_search()->set_window_start_um(100);
         r.mutable_z_range_search()->set_window_end_um(30000);
       },
       "z_range_search.window_end_um"},
      {[](v1::ScanRequest& r) {
         r.mutable_z_range_search()->set_window_start_um(-50);
         r.mutable_z_range_search()->set_window_end_um(300);
       },
       "z_range_search.window_start_um"},
      // A coarse step larger than (half) the window: fewer than 3 coarse frames.
      {[](v1::ScanRequest& r) {
         r.mutable_z_range_search()->set_window_start_um(100);
         r.mutable_z_range_search()->set_window_end_um(160);
         r.mutable_z_range_search()->set_coarse_step_um(80);
       },
       "z_range_search.coarse_step_um"},
      {[](v1::ScanRequest& r) { r.mutable_z_range_search()->set_coarse_step_um(-5); }, "z_range_search.coarse_step_um"},
      // More coarse frames than a search may take.
      {[](v1::ScanRequest& r) {
         r.mutable_z_range_search()->set_window_start_um(0);
         r.mutable_z_range_search()->set_window_end_um(25000);
         r.mutable_z_range_search()->set_coarse_step_um(20);
       },
       "z_range_search.coarse_step_um"},
      {[](v1::ScanRequest& r) { r.mutable_z_range_search()->set_window_start_um(100); },
       "z_range_search.window_end_um"},
      {[](v1::ScanRequest& r) { r.mutable_z_range_search()->set_margin_um(-1); }, "z_range_search.margin_um"},
      // An explicit range contradicts a search for one.
      {[](v1::ScanRequest& r) {
         r.set_z_start_um(180);
         r.set_z_end_um(260);
       },
       "z_start_um"},
      {[](v1::ScanRequest& r) { r.set_z_end_um(260); }, "z_end_um"},
  };
  for (const Case& c : cases) {
    v1::ScanRequest r;
    r.mutable_z_range_search()->set_enabled(true);
    c.mutate(r);
    v1::Job job;
    grpc::Status s = client_->Scan(r, nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << c.field << ": " << s.error_message();
    EXPECT_NE(s.error_message().find(c.field), std::string::npos) << c.field << ": " << s.error_message();
  }
  // Fields without enabled: a request that would silently do something else.
  v1::ScanRequest r;
  r.mutable_z_range_search()->set_coarse_step_um(10);
  v1::Job job;
  grpc::Status s = client_->Scan(r, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("z_range_search.enabled"), std::string::npos) << s.error_message();

  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 0) << "bad input must not become a job";
}

// skew5 (ground truth 200 .. ~216 um at 320x240) moved 137 um up: the rig's default range
// (around the unmoved specimen) would miss it; the search over 100 .. 500 um finds it.
TEST_F(ZRangeRequestTest, SearchFindsAMovedSpecimenAndReportsBothPhases) {
  ASSERT_TRUE(server_->rig().rig().simulation()->SetSpecimenZOffsetUm(137.0).ok());
  const cv::Mat truth = server_->rig().rig().simulation()->GroundTruthDepthUm();
  double true_lo = 0, true_hi = 0;
  cv::minMaxLoc(truth, &true_lo, &true_hi);

  v1::ScanRequest r;
  r.set_z_step_um(5);
  v1::ZRangeSearch* z = r.mutable_z_range_search();
  z->set_enabled(true);
  z->set_window_start_um(100);
  z->set_window_end_um(500);
  std::vector<v1::JobEvent> frames;
  v1::Job job;
  grpc::Status s = client_->Scan(
      r,
      [&](const v1::JobEvent& e) {
        if (e.has_frame()) frames.push_back(e);
      },
      &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
  const v1::ZRangeSearchResult& res = job.result().depth().z_range_search();
  // 100 .. 500 um at the rig's 20 um search step: 21 coarse frames and up to 4 refinement
  // frames planned. The textured part settles the field two frames past its top's focus
  // (~357 um), so the sweep stops there; then 2-4 frames refine the range's ends.
  const int planned = 21 + 4;
  const int coarse = res.coarse_frame_count();
  const int refine = res.refine_frame_count();
  EXPECT_GE(refine, 2);
  EXPECT_LE(refine, 4);
  EXPECT_DOUBLE_EQ(res.coarse_step_um(), 20.0);
  EXPECT_TRUE(res.stopped_early());
  EXPECT_GE(res.settled_percent(), 98.0);
  EXPECT_LE(100.0 + 20.0 * (coarse - 1), true_hi + 3 * 20.0) << coarse << " coarse frames";
  EXPECT_GE(100.0 + 20.0 * (coarse - 1), true_hi + 20.0) << coarse << " coarse frames";
  EXPECT_DOUBLE_EQ(res.margin_um(), 7.5);
  // The chosen range holds every true height with at most 3 steps beyond it on either side
  // (the part is ~4 steps tall: range + 2 x 1.5 steps of margin, 9 frames).
  EXPECT_LE(res.z_start_um(), true_lo);
  EXPECT_GE(res.z_end_um(), true_hi);
  EXPECT_LE(true_lo - res.z_start_um(), 3 * 5.0);
  EXPECT_LE(res.z_end_um() - true_hi, 3 * 5.0);
  const int fine = int(std::lround((res.z_end_um() - res.z_start_um()) / 5.0)) + 1;
  EXPECT_GE(fine, kMinFineFrames);
  EXPECT_NEAR(0.5 * (res.z_start_um() + res.z_end_um()), 0.5 * (true_lo + true_hi), 5.0);

  // Events: the search (FOCUS_SEARCH, not stack frames, counted within the search: sweep, then
  // refinement), then the scan.
  ASSERT_EQ(int(frames.size()), coarse + refine + fine);
  double last_progress = 0.0;
  for (int k = 0; k < int(frames.size()); ++k) {
    const v1::JobEvent& e = frames[size_t(k)];
    const bool search = k < coarse + refine;
    EXPECT_EQ(e.phase(), search ? v1::JOB_PHASE_FOCUS_SEARCH : v1::JOB_PHASE_ACQUIRING) << k;
    EXPECT_EQ(e.frame().stack_frame(), !search) << k;
    EXPECT_EQ(e.frame().frame_index(), search ? k : k - coarse - refine) << k;
    EXPECT_EQ(e.frame().frame_count(), search ? planned : fine) << k;
    EXPECT_EQ(e.frame().acquisition_index(), k);
    EXPECT_GE(e.progress(), last_progress) << "progress never goes back (event " << k << ")";
    last_progress = e.progress();
  }
  EXPECT_NEAR(frames.front().frame().z_um(), 100.0, 0.2);
  EXPECT_NEAR(frames.back().progress(), 0.9, 1e-9);

  // stack.json records the search; its coarse frames are stored under raw/.
  const std::filesystem::path stack = ExtractStoredStack(data_dir_, job.job_id(), UniqueTempDir("z_range_stack"));
  std::ifstream in(stack / "stack.json");
  ASSERT_TRUE(in.good());
  const nlohmann::json m = nlohmann::json::parse(in);
  ASSERT_TRUE(m.contains("z_range_search"));
  const auto& js = m["z_range_search"];
  EXPECT_EQ(int(js["coarse_frames"].size()), coarse);
  ASSERT_EQ(int(js["refine_frames"].size()), refine);
  for (const auto& f : js["refine_frames"]) {
    // Half-way between two coarse frames of the 20 um grid from 100 um.
    EXPECT_NEAR(std::fmod(f["z_um"].get<double>() - 100.0, 20.0), 10.0, 1e-6);
    EXPECT_TRUE(std::filesystem::exists(stack / f["file"].get<std::string>()));
  }
  EXPECT_TRUE(js["stopped_early"].get<bool>());
  EXPECT_DOUBLE_EQ(js["settled_percent"].get<double>(), res.settled_percent());
  EXPECT_DOUBLE_EQ(js["z_start_um"].get<double>(), res.z_start_um());
  EXPECT_TRUE(std::filesystem::exists(stack / js["coarse_frames"][0]["file"].get<std::string>()));
  EXPECT_EQ(int(m["frames"].size()), fine);
  EXPECT_DOUBLE_EQ(m["frames"][0]["z_um"].get<double>(), res.z_start_um());
  // The fine scan measures the moved specimen (textured skew5 under STD).
  EXPECT_GT(job.result().depth().valid_percent(), 95.0);
  EXPECT_LT(job.result().depth().rmse_um(), 0.5);
}

}  // namespace
}  // namespace inspection::testing
