// Type-1 gauge studies through the real server on the simulated rig (specimen step1um: a 1.000 um
// step at the image's centre column on a textured plane): the study job scans the reference part
// again and again with the simulated re-positioning, its figures follow from its own values by
// the VDA 5 formulas, it is stored and listed, its report is an artifact, later verdicts of the
// recipe carry a warning where the study found the gauge not capable, and bad requests or a
// cancelled study store nothing.
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {

// The step measured twice: against +-0.5 um (the issue's MES tolerance) with the certified value
// given, and against +-0.01 um (far tighter than any optical gauge repeats) against its nominal.
v1::Recipe StepRecipe(const std::string& id, const std::string& tight_tolerance = R"("lower": -0.01, "upper": 0.01)") {
  v1::Recipe r;
  const std::string json = R"({
    "recipe_id": ")" + id + R"(",
    "description": "1 um step standard <type A>",
    "scan": {"z_step_um": 5},
    "measurements": [
      {"name": "step", "parameter": "step_height",
       "roi": {"shape": "SHAPE_RECTANGLE", "x": 190, "y": 40, "width": 100, "height": 160},
       "reference_roi": {"shape": "SHAPE_RECTANGLE", "x": 30, "y": 40, "width": 100, "height": 160},
       "tolerance": {"nominal": 1.0, "lower": -0.5, "upper": 0.5}},
      {"name": "step_tight", "parameter": "step_height",
       "roi": {"shape": "SHAPE_RECTANGLE", "x": 190, "y": 40, "width": 100, "height": 160},
       "reference_roi": {"shape": "SHAPE_RECTANGLE", "x": 30, "y": 40, "width": 100, "height": 160},
       "tolerance": {"nominal": 1.0, )" + tight_tolerance + R"(}}
    ]})";
  auto s = google::protobuf::util::JsonStringToMessage(json, &r);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return r;
}

class StudyApiTest : public ServerTest {
 protected:
  SimulatedRigOptions SimOptions() override {
    SimulatedRigOptions o = ServerTest::SimOptions();
    o.specimen = "step1um";
    return o;
  }
  void SetUp() override {
    ServerTest::SetUp();
    StartServer();
    v1::Recipe stored;
    ASSERT_TRUE(client_->CreateRecipe(StepRecipe("step-std"), &stored).ok());
  }
  static v1::StartStudyRequest Type1(int repeats) {
    v1::StartStudyRequest req;
    req.set_recipe_id("step-std");
    req.set_repeats(repeats);
    req.set_part_id("PGR-1um-0815");
    (*req.mutable_reference_values())["step"] = 1.0;  // the simulator's truth, as a certificate states it
    return req;
  }
  int StudyCount() {
    v1::ListStudiesResponse list;
    EXPECT_TRUE(client_->ListStudies(v1::ListStudiesRequest(), &list).ok());
    return list.studies_size();
  }
};

double Mean(const google::protobuf::RepeatedField<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return s / v.size();
}

double SampleStddev(const google::protobuf::RepeatedField<double>& v) {
  const double m = Mean(v);
  double ss = 0;
  for (double x : v) ss += (x - m) * (x - m);
  return std::sqrt(ss / (v.size() - 1));
}

TEST_F(StudyApiTest, AStudyIsStoredListedReportedAndWarnsLaterVerdicts) {
  v1::Job job;
  int repeat_events = 0;
  grpc::Status s = client_->StartStudy(
      Type1(10),
      [&](const v1::JobEvent& e) {
        if (e.phase() == v1::JOB_PHASE_RECONSTRUCTING) ++repeat_events;
      },
      &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(job.kind(), v1::JOB_KIND_STUDY);
  EXPECT_EQ(job.recipe_id(), "step-std");
  EXPECT_EQ(job.part_id(), "PGR-1um-0815");
  EXPECT_EQ(repeat_events, 10);  // one per measured repeat
  const v1::Study& study = job.result().study();
  EXPECT_EQ(study.study_id(), job.job_id());
  EXPECT_EQ(study.repeats(), 10);
  EXPECT_EQ(study.recipe_version(), 1);
  EXPECT_EQ(study.owner(), "anonymous");
  // The request set no re-positioning: the default ran, and the study says so.
  EXPECT_NE(study.repositioning().find("sigma 5 um xy, 2 um z"), std::string::npos) << study.repositioning();
  EXPECT_NE(study.repositioning().find("default"), std::string::npos) << study.repositioning();
  ASSERT_EQ(study.measurements_size(), 2);

  for (const v1::MeasurementCapability& c : study.measurements()) {
    std::printf("%-10s n %d mean %.4f s %.4f ref %.3f (%s) T %.3f Cg %.3f Cgk %.3f bias %.4f t %.3f p %.3g U/T %.1f %%"
                " capable %d\n",
                c.name().c_str(), c.n(), c.mean(), c.stddev(), c.reference(), c.reference_source().c_str(),
                c.tolerance(), c.cg(), c.cgk(), c.bias(), c.t_statistic(), c.p_value(), c.u_over_t_percent(),
                c.capable());
    ASSERT_EQ(c.values_size(), 10);
    ASSERT_EQ(c.expanded_uncertainties_size(), 10);
    EXPECT_EQ(c.unit(), "um");
    // The figures are the VDA 5 formulas applied to the study's own values.
    EXPECT_NEAR(c.mean(), Mean(c.values()), 1e-12);
    EXPECT_NEAR(c.stddev(), SampleStddev(c.values()), 1e-12);
    EXPECT_GT(c.stddev(), 0.0);  // re-positioning and noise: the repeats differ
    EXPECT_NEAR(c.bias(), c.mean() - c.reference(), 1e-12);
    EXPECT_NEAR(c.cg(), 0.2 * c.tolerance() / (6 * c.stddev()), 1e-9);
    EXPECT_NEAR(c.cgk(), (0.1 * c.tolerance() - std::abs(c.bias())) / (3 * c.stddev()), 1e-9);
    EXPECT_NEAR(c.t_statistic(), c.bias() / (c.stddev() / std::sqrt(10.0)), 1e-9);
    EXPECT_NEAR(c.t_critical(), 2.262157, 1e-6);  // t(0.975, 9)
    EXPECT_EQ(c.bias_significant(), std::abs(c.t_statistic()) > c.t_critical());
    EXPECT_NEAR(c.mean_expanded_uncertainty(), Mean(c.expanded_uncertainties()), 1e-12);
    EXPECT_NEAR(c.u_over_t_percent(), 100 * c.mean_expanded_uncertainty() / c.tolerance(), 1e-9);
    EXPECT_EQ(c.capable(), c.cg() >= 1.33 && c.cgk() >= 1.33);
    // Every repeat measured the 1.000 um step (the simulator's truth) within its own U.
    for (int i = 0; i < 10; ++i) EXPECT_NEAR(c.values(i), 1.0, std::max(0.1, c.expanded_uncertainties(i))) << i;
  }
  const v1::MeasurementCapability& step = study.measurements(0);
  const v1::MeasurementCapability& tight = study.measurements(1);
  EXPECT_EQ(step.reference_source(), "reference_values");
  EXPECT_DOUBLE_EQ(step.tolerance(), 1.0);
  EXPECT_EQ(tight.reference_source(), "nominal (no reference value given)");
  EXPECT_NEAR(tight.tolerance(), 0.02, 1e-12);
  // Both judge the same values: only the tolerance differs, so Cg scales with T exactly.
  EXPECT_NEAR(tight.cg(), step.cg() * 0.02, 1e-9);
  EXPECT_FALSE(tight.capable());  // 6 s would have to stay below 4 nm
  EXPECT_FALSE(study.capable());

  // Stored and listed, the report downloadable.
  v1::Study stored;
  ASSERT_TRUE(client_->GetStudy(job.job_id(), &stored).ok());
  EXPECT_EQ(stored.SerializeAsString(), study.SerializeAsString());
  v1::ListStudiesRequest by_recipe;
  by_recipe.set_recipe_id("step-std");
  v1::ListStudiesResponse list;
  ASSERT_TRUE(client_->ListStudies(by_recipe, &list).ok());
  ASSERT_EQ(list.studies_size(), 1);
  EXPECT_EQ(list.studies(0).study_id(), job.job_id());
  by_recipe.set_recipe_id("other");
  ASSERT_TRUE(client_->ListStudies(by_recipe, &list).ok());
  EXPECT_EQ(list.studies_size(), 0);
  ASSERT_FALSE(study.report_artifact_id().empty());
  const std::filesystem::path report = UniqueTempDir("study") / "study_report.html";
  ASSERT_TRUE(client_->DownloadArtifact(study.report_artifact_id(), report, false).ok());
  std::stringstream html;
  html << std::ifstream(report).rdbuf();
  EXPECT_NE(html.str().find("id=\"capability\" class=\"c-nok\">NOT CAPABLE<"), std::string::npos);
  EXPECT_NE(html.str().find("1 um step standard &lt;type A&gt;"), std::string::npos);
  EXPECT_EQ(html.str().find("<script"), std::string::npos);
  // The rig was never verified: the study says so, in the record and the report, as its scans' results do.
  EXPECT_EQ(study.verification_warning().rfind("verification due: no full verification under ", 0), 0u)
      << study.verification_warning();
  EXPECT_NE(html.str().find("<p id=\"verification\">instrument verification: <strong class=\"c-nok\">" +
                            study.verification_warning() + "</strong></p>"),
            std::string::npos);

  // A later scan of the recipe: the verdicts stand, the not-capable measurement warns.
  v1::ScanRequest scan;
  scan.set_recipe_id("step-std");
  scan.set_part_id("part-1");
  v1::Job part;
  ASSERT_TRUE(client_->Scan(scan, {}, &part).ok());
  const v1::InspectionResult& ins = part.result().inspection();
  ASSERT_EQ(ins.measurements_size(), 2);
  EXPECT_EQ(ins.verification_warning(), study.verification_warning());
  EXPECT_EQ(ins.measurements(0).capability_warning().empty(), step.capable()) << ins.measurements(0).capability_warning();
  EXPECT_NE(ins.measurements(1).capability_warning().find("gauge not capable (Type-1 study " + job.job_id()),
            std::string::npos)
      << ins.measurements(1).capability_warning();
  // The stored result (the MES's feed) carries it too.
  v1::ListResultsResponse results;
  ASSERT_TRUE(client_->ListResults(v1::ListResultsRequest(), &results).ok());
  ASSERT_EQ(results.results_size(), 1);
  EXPECT_EQ(results.results(0).measurements(1).capability_warning(), ins.measurements(1).capability_warning());
}

TEST_F(StudyApiTest, BadRequestsNameTheFieldAndStoreNothing) {
  v1::ListJobsResponse before;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &before).ok());
  v1::Job job;
  grpc::Status s = client_->StartStudy(Type1(9), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("repeats must be 10..1000"), std::string::npos) << s.error_message();

  v1::StartStudyRequest req = Type1(10);
  req.clear_recipe_id();
  s = client_->StartStudy(req, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("recipe_id"), std::string::npos) << s.error_message();

  req = Type1(10);
  req.set_recipe_id("no-such-recipe");
  EXPECT_EQ(client_->StartStudy(req, nullptr, &job).error_code(), grpc::StatusCode::NOT_FOUND);

  req = Type1(10);
  (*req.mutable_reference_values())["nope"] = 1.0;
  s = client_->StartStudy(req, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("reference_values['nope']"), std::string::npos) << s.error_message();

  req = Type1(10);
  req.set_reposition_xy_um(-1);
  s = client_->StartStudy(req, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("reposition_xy_um"), std::string::npos) << s.error_message();

  // A one-sided tolerance has no T = USL - LSL: no Cg.
  v1::Recipe stored;
  ASSERT_TRUE(client_->CreateRecipe(StepRecipe("step-upper", R"("upper": 0.5)"), &stored).ok());
  req = Type1(10);
  req.set_recipe_id("step-upper");
  s = client_->StartStudy(req, nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("measurements[1] ('step_tight').tolerance: a Type-1 study needs both lower and upper"),
            std::string::npos)
      << s.error_message();

  v1::ListJobsResponse after;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &after).ok());
  EXPECT_EQ(after.jobs_size(), before.jobs_size());  // refused requests queue nothing
  EXPECT_EQ(StudyCount(), 0);
  v1::Study study;
  EXPECT_EQ(client_->GetStudy("study-doesnotexist", &study).error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(StudyApiTest, ACancelledStudyStoresNothingAndPutsThePartBack) {
  const cv::Mat truth_before = GroundTruthInCameraGrid(server_->rig().rig(), 0.0);
  control_->hold_at_frame = 14;  // in the second repeat (10 frames each)
  v1::Job job;
  grpc::Status s;
  std::thread study([&] {
    auto c = NewClient();
    s = c->StartStudy(Type1(10), nullptr, &job);
  });
  ASSERT_TRUE(control_->WaitUntilHolding());
  v1::RigStatus rig;
  ASSERT_TRUE(client_->GetRigStatus(&rig).ok());
  ASSERT_EQ(rig.running_job_id().rfind("study-", 0), 0u) << rig.running_job_id();
  v1::Job cancelled;
  ASSERT_TRUE(client_->CancelJob(rig.running_job_id(), &cancelled).ok());
  control_->Release();
  study.join();
  EXPECT_EQ(s.error_code(), grpc::StatusCode::CANCELLED) << s.error_message();
  EXPECT_EQ(job.state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(StudyCount(), 0);
  EXPECT_FALSE(std::filesystem::exists(data_dir_ / "artifacts" / job.job_id()));
  EXPECT_FALSE(std::filesystem::exists(data_dir_ / "tmp" / (job.job_id() + ".study")));
  // The simulated part is back where it was loaded.
  EXPECT_EQ(cv::norm(GroundTruthInCameraGrid(server_->rig().rig(), 0.0), truth_before, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace inspection::testing
