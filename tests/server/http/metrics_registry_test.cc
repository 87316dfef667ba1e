// MetricsRegistry: the exact bytes of the Prometheus text exposition, and ServerMetrics' job
// accounting from a synthetic event stream.
#include "server/http/metrics_registry.h"

#include <google/protobuf/util/time_util.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <thread>

#include "server/http/server_metrics.h"

namespace inspection {
namespace {

using google::protobuf::util::TimeUtil;

TEST(MetricsRegistryTest, CounterGaugeAndHistogramRenderExactly) {
  MetricsRegistry r;
  Counter jobs = r.AddCounter("t_jobs_total", "Jobs.", {"kind", "state"});
  Gauge free = r.AddGauge("t_free_bytes", "Free\\space\nnow.");
  Histogram wait = r.AddHistogram("t_wait_seconds", "Wait.", {0.5, 1, 2.5}, {"kind"});
  jobs.Add({"scan", "succeeded"});
  jobs.Add({"scan", "succeeded"}, 2);
  jobs.Add({"reconstruct", "failed"});
  jobs.Add({"scan", "failed"}, -5);  // counters never go down: ignored (no series either)
  free.Set({}, 123456789012.0);
  wait.Observe({"scan"}, 0.5);  // on a bound: counts in that bucket (le is <=)
  wait.Observe({"scan"}, 0.75);
  wait.Observe({"scan"}, 7);  // only in +Inf
  EXPECT_EQ(r.Render(),
            "# HELP t_jobs_total Jobs.\n"
            "# TYPE t_jobs_total counter\n"
            "t_jobs_total{kind=\"reconstruct\",state=\"failed\"} 1\n"
            "t_jobs_total{kind=\"scan\",state=\"succeeded\"} 3\n"
            "# HELP t_free_bytes Free\\\\space\\nnow.\n"
            "# TYPE t_free_bytes gauge\n"
            "t_free_bytes 123456789012\n"
            "# HELP t_wait_seconds Wait.\n"
            "# TYPE t_wait_seconds histogram\n"
            "t_wait_seconds_bucket{kind=\"scan\",le=\"0.5\"} 1\n"
            "t_wait_seconds_bucket{kind=\"scan\",le=\"1\"} 2\n"
            "t_wait_seconds_bucket{kind=\"scan\",le=\"2.5\"} 2\n"
            "t_wait_seconds_bucket{kind=\"scan\",le=\"+Inf\"} 3\n"
            "t_wait_seconds_sum{kind=\"scan\"} 8.25\n"
            "t_wait_seconds_count{kind=\"scan\"} 3\n");
}

TEST(MetricsRegistryTest, UnlabelledFamiliesShowZeroBeforeTheFirstUpdate) {
  MetricsRegistry r;
  r.AddCounter("t_frames_total", "Frames.");
  r.AddHistogram("t_d_seconds", "D.", {1});
  r.AddGauge("t_state", "State.", {"state"});  // labelled: no series until one is set
  EXPECT_EQ(
      r.Render(),
      "# HELP t_frames_total Frames.\n# TYPE t_frames_total counter\nt_frames_total 0\n"
      "# HELP t_d_seconds D.\n# TYPE t_d_seconds histogram\n"
      "t_d_seconds_bucket{le=\"1\"} 0\nt_d_seconds_bucket{le=\"+Inf\"} 0\nt_d_seconds_sum 0\nt_d_seconds_count 0\n"
      "# HELP t_state State.\n# TYPE t_state gauge\n");
}

TEST(MetricsRegistryTest, LabelValuesAreEscaped) {
  MetricsRegistry r;
  Counter c = r.AddCounter("t_total", "T.", {"method"});
  c.Add({"a\"b\\c\nd"});
  EXPECT_NE(r.Render().find("t_total{method=\"a\\\"b\\\\c\\nd\"} 1\n"), std::string::npos) << r.Render();
}

TEST(MetricsRegistryTest, ValuesFormatShortestAndSpecials) {
  EXPECT_EQ(FormatMetricValue(0), "0");
  EXPECT_EQ(FormatMetricValue(-3), "-3");
  EXPECT_EQ(FormatMetricValue(0.1), "0.1");
  EXPECT_EQ(FormatMetricValue(2.5e-7), "2.5e-07");
  EXPECT_EQ(FormatMetricValue(1.0 / 3.0), "0.3333333333333333");
  EXPECT_EQ(FormatMetricValue(1e300), "1e+300");
  EXPECT_EQ(FormatMetricValue(std::numeric_limits<double>::infinity()), "+Inf");
  EXPECT_EQ(FormatMetricValue(-std::numeric_limits<double>::infinity()), "-Inf");
  EXPECT_EQ(FormatMetricValue(std::nan("")), "NaN");
}

TEST(MetricsRegistryTest, ConcurrentUpdatesAreAllCounted) {
  MetricsRegistry r;
  Counter c = r.AddCounter("t_total", "T.", {"thread"});
  Histogram h = r.AddHistogram("t_seconds", "T.", {1});
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 10000; ++i) {
        c.Add({t % 2 ? "odd" : "even"});
        h.Observe({}, 0.5);
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(c.Value({"even"}), 20000);
  EXPECT_EQ(c.Value({"odd"}), 20000);
  EXPECT_EQ(h.Count({}), 40000u);
}

// Events as the JobManager records them for a scan of 3 stack frames plus one HDR capture: queued,
// 4 frame events, the end after 12 s of running.
std::vector<v1::JobEvent> ScanEvents(const std::string& id) {
  std::vector<v1::JobEvent> events;
  v1::JobEvent queued;
  queued.set_job_id(id);
  queued.set_state(v1::JOB_STATE_QUEUED);
  queued.set_phase(v1::JOB_PHASE_QUEUED);
  events.push_back(queued);
  for (int i = 0; i < 4; ++i) {
    v1::JobEvent e;
    e.set_job_id(id);
    e.set_state(v1::JOB_STATE_RUNNING);
    e.set_phase(v1::JOB_PHASE_ACQUIRING);
    e.mutable_frame()->set_frame_index(std::min(i, 2));
    e.mutable_frame()->set_stack_frame(i != 1);  // capture 1 is an extra exposure
    e.mutable_frame()->mutable_statistics()->set_mean_grey(100 + 10 * i);
    e.mutable_frame()->mutable_statistics()->set_saturated_percent(i);
    events.push_back(e);
  }
  v1::JobEvent end;
  end.set_job_id(id);
  end.set_state(v1::JOB_STATE_SUCCEEDED);
  end.set_elapsed_seconds(12.0);
  v1::Job& job = *end.mutable_job();
  job.set_job_id(id);
  job.set_kind(v1::JOB_KIND_SCAN);
  job.set_state(v1::JOB_STATE_SUCCEEDED);
  *job.mutable_create_time() = TimeUtil::SecondsToTimestamp(1000);  // whole seconds, as the API has them
  *job.mutable_start_time() = TimeUtil::SecondsToTimestamp(1000);
  *job.mutable_end_time() = TimeUtil::SecondsToTimestamp(1012);
  job.mutable_result()->mutable_depth()->set_engine_seconds(0.04);
  job.mutable_result()->add_artifacts()->set_size_bytes(1000);
  job.mutable_result()->add_artifacts()->set_size_bytes(24);
  events.push_back(end);
  return events;
}

TEST(ServerMetricsTest, ScanEventsCountJobFramesDurationsAndLastScanStatistics) {
  // The clock reads 100 s when the job is queued and 112.25 s at its end: started at 100.25 s.
  double now_s = 100.0;
  ServerMetrics m("9.9.9", [&] { return now_s; });
  const auto events = ScanEvents("scan-1");
  for (size_t i = 0; i < events.size(); ++i) {
    if (i + 1 == events.size()) now_s = 112.25;
    m.OnJobEvent(events[i]);
  }
  ScrapeState st;
  st.rig_state = v1::RIG_STATE_READY;
  st.data_disk_free_bytes = 5000;
  const std::string text = m.Render(st);
  auto has = [&](const std::string& line) {
    EXPECT_NE(text.find("\n" + line + "\n"), std::string::npos) << line << "\n---\n" << text;
  };
  has("inspectd_jobs_total{kind=\"scan\",state=\"succeeded\"} 1");
  has("inspectd_frames_acquired_total 4");
  // Stack frames 0, 2, 3: mean grey (100 + 120 + 130) / 3, saturated (0 + 2 + 3) / 3.
  has("inspectd_last_scan_mean_grey 116.66666666666667");
  has("inspectd_last_scan_saturated_percent 1.6666666666666667");
  has("inspectd_last_scan_frames 3");
  has("inspectd_job_queue_wait_seconds_bucket{kind=\"scan\",le=\"0.1\"} 0");
  has("inspectd_job_queue_wait_seconds_bucket{kind=\"scan\",le=\"0.5\"} 1");
  has("inspectd_job_queue_wait_seconds_sum{kind=\"scan\"} 0.25");
  has("inspectd_job_duration_seconds_bucket{kind=\"scan\",le=\"10\"} 0");
  has("inspectd_job_duration_seconds_bucket{kind=\"scan\",le=\"20\"} 1");
  has("inspectd_job_duration_seconds_sum{kind=\"scan\"} 12");
  has("inspectd_job_duration_seconds_count{kind=\"scan\"} 1");
  has("inspectd_reconstruct_engine_seconds_sum{kind=\"scan\"} 0.04");
  has("inspectd_artifact_bytes_total{kind=\"scan\"} 1024");
  has("inspectd_rig_state{state=\"ready\"} 1");
  has("inspectd_rig_state{state=\"error\"} 0");
  has("inspectd_rig_present 1");
  has("inspectd_data_disk_free_bytes 5000");
  has("inspectd_build_info{version=\"9.9.9\"} 1");
}

TEST(ServerMetricsTest, FailedJobsCountWithoutResultFiguresAndGrpcCallsByCode) {
  ServerMetrics m("1");
  auto events = ScanEvents("scan-2");
  events.back().mutable_job()->set_state(v1::JOB_STATE_FAILED);
  for (const auto& e : events) m.OnJobEvent(e);
  m.OnGrpcCall("/inspection.v1.InspectionService/Scan", 9);
  m.OnGrpcCall("/inspection.v1.InspectionService/Scan", 9);
  m.OnGrpcCall("/grpc.health.v1.Health/Check", 0);
  const std::string text = m.Render(ScrapeState{});
  EXPECT_NE(text.find("inspectd_jobs_total{kind=\"scan\",state=\"failed\"} 1\n"), std::string::npos) << text;
  EXPECT_NE(text.find("inspectd_last_scan_frames 0\n"), std::string::npos) << text;  // only succeeded scans
  EXPECT_NE(text.find("inspectd_artifact_bytes_total"), std::string::npos);
  EXPECT_EQ(text.find("inspectd_artifact_bytes_total{"), std::string::npos) << text;
  EXPECT_NE(text.find("inspectd_grpc_calls_total{method=\"inspection.v1.InspectionService/Scan\","
                      "code=\"FAILED_PRECONDITION\"} 2\n"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("inspectd_grpc_calls_total{method=\"grpc.health.v1.Health/Check\",code=\"OK\"} 1\n"),
            std::string::npos);
  EXPECT_NE(text.find("inspectd_rig_present 0\n"), std::string::npos);
  EXPECT_EQ(text.find("inspectd_rig_state{"), std::string::npos) << "no rig, no state series";
}

}  // namespace
}  // namespace inspection
