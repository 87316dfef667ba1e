// The inspection result feed through the real server on the simulated rig:
// results of recipe scans are stored with part, recipe, job, calibration, timings, profiles and
// the report; ListResults filters and pages them; WatchResults delivers stored then live results
// and resumes from a sequence number without loss or repetition. The specimen is skew5, a
// textured plane tilted by 5.000 deg about the image's y axis.
#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/time_util.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <future>
#include <sstream>
#include <thread>

#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

using google::protobuf::util::TimeUtil;

v1::Recipe RecipeFromJson(const std::string& json) {
  v1::Recipe r;
  const auto s = google::protobuf::util::JsonStringToMessage(json, &r);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return r;
}

// In tolerance on skew5 (true tilt 5 deg), with a profile along x through the middle.
v1::Recipe TiltOk() {
  return RecipeFromJson(R"({
    "recipe_id": "tilt-ok", "scan": {"z_step_um": 5},
    "measurements": [{"name": "tilt", "parameter": "tilt",
                      "tolerance": {"nominal": 5.0, "lower": -0.5, "upper": 0.5, "min_coverage_percent": 90}}],
    "profiles": [{"name": "along_x", "start": {"x": 20, "y": 120}, "end": {"x": 300, "y": 120}, "width": 5}]})");
}

// Out of tolerance on skew5.
v1::Recipe TiltNotOk() {
  return RecipeFromJson(R"({
    "recipe_id": "tilt-not-ok", "scan": {"z_step_um": 5},
    "measurements": [{"name": "tilt", "parameter": "tilt", "tolerance": {"nominal": 3.0, "lower": -0.5, "upper": 0.5}}]})");
}

class ResultFeedTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
    v1::Recipe stored;
    ASSERT_TRUE(client_->CreateRecipe(TiltOk(), &stored).ok());
    ASSERT_TRUE(client_->CreateRecipe(TiltNotOk(), &stored).ok());
  }
  v1::Job ScanPart(const std::string& part, const std::string& recipe) {
    v1::ScanRequest req;
    req.set_part_id(part);
    req.set_station("line-2");
    req.set_recipe_id(recipe);
    v1::Job job;
    const grpc::Status s = client_->Scan(req, {}, &job);
    EXPECT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
    return job;
  }
  std::vector<v1::InspectionResult> List(v1::ListResultsRequest req) {
    v1::ListResultsResponse out;
    const grpc::Status s = client_->ListResults(req, &out);
    EXPECT_TRUE(s.ok()) << s.error_message();
    return {out.results().begin(), out.results().end()};
  }
};

TEST_F(ResultFeedTest, ResultsCarryIdsTimingsProfilesAndTheReport) {
  const v1::Job job = ScanPart("P-1", "tilt-ok");
  const v1::InspectionResult& r = job.result().inspection();
  EXPECT_EQ(r.verdict(), v1::VERDICT_OK);
  EXPECT_EQ(r.job_id(), job.job_id());
  EXPECT_EQ(r.calibration_id(), job.result().calibration_id());
  EXPECT_EQ(r.sequence(), 1);
  EXPECT_TRUE(r.has_finish_time());
  EXPECT_GE(TimeUtil::TimestampToSeconds(r.finish_time()), TimeUtil::TimestampToSeconds(job.create_time()));
  EXPECT_GT(r.timings().scan_seconds(), 0.0);
  EXPECT_GE(r.timings().queue_seconds(), 0.0);
  EXPECT_GT(r.timings().measure_seconds(), 0.0);
  EXPECT_GE(r.timings().engine_seconds(), 0.0);

  // The profile along x on a plane tilted 5 deg about y: height rises by tan(5 deg) per um.
  ASSERT_EQ(r.profiles_size(), 1);
  const v1::ProfileResult& p = r.profiles(0);
  EXPECT_EQ(p.name(), "along_x");
  ASSERT_GT(p.position_um_size(), 200);
  ASSERT_EQ(p.height_um_size(), p.position_um_size());
  ASSERT_EQ(p.standard_uncertainty_um_size(), p.position_um_size());
  EXPECT_GT(p.coverage_percent(), 95.0);
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (int i = 0; i < p.position_um_size(); ++i) {
    if (!std::isfinite(p.height_um(i))) continue;
    sx += p.position_um(i), sy += p.height_um(i), sxx += p.position_um(i) * p.position_um(i);
    sxy += p.position_um(i) * p.height_um(i), ++n;
  }
  const double slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
  EXPECT_NEAR(std::abs(slope), std::tan(5.0 * M_PI / 180.0), 0.02 * std::tan(5.0 * M_PI / 180.0));

  // The report is an artifact of the job, named by the result, and shows the verdict.
  ASSERT_FALSE(r.report_artifact_id().empty());
  const v1::Artifact* report = nullptr;
  for (const v1::Artifact& a : job.result().artifacts()) {
    if (a.artifact_id() == r.report_artifact_id()) report = &a;
  }
  ASSERT_NE(report, nullptr);
  EXPECT_EQ(report->kind(), v1::ARTIFACT_KIND_REPORT_HTML);
  EXPECT_EQ(report->media_type(), "text/html; charset=utf-8");
  const std::filesystem::path file = data_dir_ / "artifacts" / job.job_id() / "report.html";
  std::ifstream in(file);
  std::stringstream html;
  html << in.rdbuf();
  EXPECT_EQ(int64_t(html.str().size()), report->size_bytes());
  EXPECT_NE(html.str().find("id=\"verdict\""), std::string::npos);

  // A scan without a recipe has no inspection and adds nothing to the feed.
  v1::Job plain;
  ASSERT_TRUE(client_->Scan(v1::ScanRequest(), {}, &plain).ok());
  EXPECT_FALSE(plain.result().has_inspection());
  EXPECT_EQ(List({}).size(), 1u);
}

TEST_F(ResultFeedTest, ListFiltersByPartRecipeVerdictAndTimeInPages) {
  ScanPart("A-1", "tilt-ok");
  ScanPart("A-2", "tilt-ok");
  ScanPart("B-1", "tilt-not-ok");
  const std::vector<v1::InspectionResult> all = List({});
  ASSERT_EQ(all.size(), 3u);
  EXPECT_EQ(all[0].part_id(), "B-1");  // newest first
  EXPECT_EQ(all[2].part_id(), "A-1");
  EXPECT_GT(all[0].sequence(), all[1].sequence());
  EXPECT_GT(all[1].sequence(), all[2].sequence());

  v1::ListResultsRequest q;
  q.set_part_id("A-2");
  ASSERT_EQ(List(q).size(), 1u);
  EXPECT_EQ(List(q)[0].recipe_id(), "tilt-ok");
  q = {};
  q.set_recipe_id("tilt-not-ok");
  ASSERT_EQ(List(q).size(), 1u);
  EXPECT_EQ(List(q)[0].verdict(), v1::VERDICT_NOT_OK);
  q = {};
  q.set_verdict(v1::VERDICT_OK);
  EXPECT_EQ(List(q).size(), 2u);
  q.set_part_id("B-1");
  EXPECT_EQ(List(q).size(), 0u);

  // Time range: [finish of A-2, ...) holds A-2 and B-1; before it only A-1.
  q = {};
  *q.mutable_finished_after() = all[1].finish_time();
  std::vector<v1::InspectionResult> late = List(q);
  ASSERT_EQ(late.size(), 2u);
  EXPECT_EQ(late[1].part_id(), "A-2");
  q = {};
  *q.mutable_finished_before() = all[1].finish_time();
  ASSERT_EQ(List(q).size(), 1u);
  EXPECT_EQ(List(q)[0].part_id(), "A-1");

  // Pages of 2: two, then one, then no token.
  q = {};
  q.set_page_size(2);
  v1::ListResultsResponse page;
  ASSERT_TRUE(client_->ListResults(q, &page).ok());
  ASSERT_EQ(page.results_size(), 2);
  ASSERT_FALSE(page.next_page_token().empty());
  q.set_page_token(page.next_page_token());
  ASSERT_TRUE(client_->ListResults(q, &page).ok());
  ASSERT_EQ(page.results_size(), 1);
  EXPECT_EQ(page.results(0).part_id(), "A-1");
  EXPECT_TRUE(page.next_page_token().empty());

  // Bad queries name the field.
  auto refused = [&](const v1::ListResultsRequest& bad, const std::string& field) {
    v1::ListResultsResponse out;
    const grpc::Status s = client_->ListResults(bad, &out);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << field;
    EXPECT_NE(s.error_message().find(field), std::string::npos) << s.error_message();
  };
  q = {};
  q.set_page_token("12x");
  refused(q, "page_token");
  q = {};
  q.set_verdict(v1::Verdict(42));
  refused(q, "verdict");
  q = {};
  q.set_page_size(-1);
  refused(q, "page_size");
  q = {};
  *q.mutable_finished_after() = all[0].finish_time();
  *q.mutable_finished_before() = all[2].finish_time();
  refused(q, "finished_before");
}

TEST_F(ResultFeedTest, WatchDeliversStoredThenLiveResultsAndResumesWithoutLoss) {
  ScanPart("W-1", "tilt-ok");
  // The watcher starts after the first result exists and stops at the third: the first comes
  // from the store, the others live (or from the store, if the scans beat the connection: the
  // feed gives the same answer either way).
  std::vector<v1::InspectionResult> seen;
  grpc::Status watch_status;
  auto watcher_client = NewClient();
  std::thread watcher([&] {
    watch_status = watcher_client->WatchResults(0, [&](const v1::InspectionResult& r) {
      seen.push_back(r);
      return seen.size() < 3;
    });
  });
  ScanPart("W-2", "tilt-not-ok");
  ScanPart("W-3", "tilt-ok");
  watcher.join();
  ASSERT_TRUE(watch_status.ok()) << watch_status.error_message();
  ASSERT_EQ(seen.size(), 3u);
  EXPECT_EQ(seen[0].part_id(), "W-1");
  EXPECT_EQ(seen[1].part_id(), "W-2");
  EXPECT_EQ(seen[1].verdict(), v1::VERDICT_NOT_OK);
  EXPECT_EQ(seen[2].part_id(), "W-3");
  EXPECT_EQ(seen[0].sequence() + 1, seen[1].sequence());
  EXPECT_EQ(seen[1].sequence() + 1, seen[2].sequence());

  // A client that reconnects with the last sequence it processed gets exactly what followed.
  std::vector<v1::InspectionResult> resumed;
  ASSERT_TRUE(client_
                  ->WatchResults(seen[1].sequence(),
                                 [&](const v1::InspectionResult& r) {
                                   resumed.push_back(r);
                                   return false;
                                 })
                  .ok());
  ASSERT_EQ(resumed.size(), 1u);
  EXPECT_EQ(resumed[0].part_id(), "W-3");
  EXPECT_EQ(resumed[0].SerializeAsString(), seen[2].SerializeAsString());

  // Negative sequence numbers are refused.
  const grpc::Status bad = client_->WatchResults(-1, [](const v1::InspectionResult&) { return false; });
  EXPECT_EQ(bad.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(bad.error_message().find("after_sequence"), std::string::npos);
}

TEST_F(ResultFeedTest, SequenceNumbersSurviveARestartAndShutdownEndsTheFeed) {
  ScanPart("R-1", "tilt-ok");
  // An open feed ends UNAVAILABLE when the server shuts down (the client reconnects and resumes).
  grpc::Status watch_status;
  std::atomic<int> received{0};
  std::promise<void> first;
  auto watcher_client = NewClient();
  std::thread watcher([&] {
    watch_status = watcher_client->WatchResults(0, [&](const v1::InspectionResult&) {
      if (received.fetch_add(1) == 0) first.set_value();
      return true;
    });
  });
  first.get_future().wait();  // the watcher is connected and has caught up
  StopServer();
  watcher.join();
  EXPECT_EQ(received, 1);
  EXPECT_EQ(watch_status.error_code(), grpc::StatusCode::UNAVAILABLE) << watch_status.error_message();

  StartServer();
  const v1::Job job = ScanPart("R-2", "tilt-ok");
  EXPECT_EQ(job.result().inspection().sequence(), 2);
  const std::vector<v1::InspectionResult> all = List({});
  ASSERT_EQ(all.size(), 2u);
  EXPECT_EQ(all[1].part_id(), "R-1");
}

}  // namespace
}  // namespace inspection::testing
