// MetricsRegistry: the Prometheus text exposition prometheus-cpp writes (parsed: every family's
// HELP, TYPE and series with their values), and ServerMetrics' job accounting from a synthetic
// event stream.
#include "server/http/metrics_registry.h"

#include <google/protobuf/util/time_util.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "server/http/server_metrics.h"

namespace inspection {
namespace {

using google::protobuf::util::TimeUtil;

// The exposition parsed into its families: HELP and TYPE, then the samples as "name{labels}" ->
// value text. prometheus-cpp writes a histogram's _count and _sum before its buckets; the
// format does not order a family's lines, so the tests compare sets, not line order, within a
// family (and the family order, which the registry keeps as declared).
struct ParsedFamily {
  std::string name, help, type;
  std::map<std::string, std::string> samples;
};

std::vector<ParsedFamily> Parse(const std::string& text) {
  std::vector<ParsedFamily> families;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    if (line.rfind("# HELP ", 0) == 0) {
      const std::string rest = line.substr(7);
      const size_t sp = rest.find(' ');
      families.push_back({rest.substr(0, sp), sp == std::string::npos ? "" : rest.substr(sp + 1), "", {}});
      continue;
    }
    EXPECT_FALSE(families.empty()) << "a sample before any # HELP: " << line;
    if (families.empty()) continue;
    if (line.rfind("# TYPE ", 0) == 0) {
      EXPECT_EQ(line.substr(7, families.back().name.size() + 1), families.back().name + " ") << line;
      families.back().type = line.substr(7 + families.back().name.size() + 1);
      continue;
    }
    const size_t sp = line.rfind(' ');
    EXPECT_NE(sp, std::string::npos) << line;
    EXPECT_EQ(line.rfind(families.back().name, 0), 0u) << "sample outside its family: " << line;
    const bool fresh = families.back().samples.emplace(line.substr(0, sp), line.substr(sp + 1)).second;
    EXPECT_TRUE(fresh) << "duplicate series " << line;
  }
  return families;
}

TEST(MetricsRegistryTest, CounterGaugeAndHistogramRenderExactly) {
  MetricsRegistry r;
  Counter jobs = r.AddCounter("t_jobs_total", "Jobs.", {"kind", "state"});
  Gauge free = r.AddGauge("t_free_bytes", "Free\\space\nnow.");
  Histogram wait = r.AddHistogram("t_wait_seconds", "Wait.", {0.5, 1, 2.5}, {"kind"});
  Counter calls = r.AddCounter("t_calls_total", "Calls.", {"method", "code"});  // names not in sorted order
  jobs.Add({"scan", "succeeded"});
  jobs.Add({"scan", "succeeded"}, 2);
  jobs.Add({"reconstruct", "failed"});
  jobs.Add({"scan", "failed"}, -5);            // counters never go down: ignored (no series either)
  jobs.Add({"scan", "failed"}, std::nan(""));  // nor by NaN
  free.Set({}, 123456789012.0);
  wait.Observe({"scan"}, 0.5);  // on a bound: counts in that bucket (le is <=)
  wait.Observe({"scan"}, 0.75);
  wait.Observe({"scan"}, 7);  // only in +Inf
  calls.Add({"inspection.v1.InspectionService/Scan", "OK"});
  const std::string text = r.Render();
  const std::vector<ParsedFamily> f = Parse(text);
  ASSERT_EQ(f.size(), 4u) << text;
  EXPECT_EQ(f[0].name, "t_jobs_total");
  EXPECT_EQ(f[0].help, "Jobs.");
  EXPECT_EQ(f[0].type, "counter");
  EXPECT_EQ(f[0].samples, (std::map<std::string, std::string>{
                              {"t_jobs_total{kind=\"reconstruct\",state=\"failed\"}", "1"},
                              {"t_jobs_total{kind=\"scan\",state=\"succeeded\"}", "3"}}))
      << text;
  EXPECT_EQ(f[1].name, "t_free_bytes");
  EXPECT_EQ(f[1].help, "Free\\\\space\\nnow.");  // backslash and newline escaped
  EXPECT_EQ(f[1].type, "gauge");
  EXPECT_EQ(f[1].samples, (std::map<std::string, std::string>{{"t_free_bytes", "123456789012"}})) << text;
  EXPECT_EQ(f[2].name, "t_wait_seconds");
  EXPECT_EQ(f[2].type, "histogram");
  EXPECT_EQ(f[2].samples, (std::map<std::string, std::string>{
                              {"t_wait_seconds_bucket{kind=\"scan\",le=\"0.5\"}", "1"},
                              {"t_wait_seconds_bucket{kind=\"scan\",le=\"1\"}", "2"},
                              {"t_wait_seconds_bucket{kind=\"scan\",le=\"2.5\"}", "2"},
                              {"t_wait_seconds_bucket{kind=\"scan\",le=\"+Inf\"}", "3"},
                              {"t_wait_seconds_sum{kind=\"scan\"}", "8.25"},
                              {"t_wait_seconds_count{kind=\"scan\"}", "3"}}))
      << text;
  // Labels in the declared order (prometheus-cpp keeps them sorted by name).
  EXPECT_EQ(f[3].samples, (std::map<std::string, std::string>{
                              {"t_calls_total{method=\"inspection.v1.InspectionService/Scan\",code=\"OK\"}", "1"}}))
      << text;
  EXPECT_EQ(jobs.Value({"scan", "succeeded"}), 3);
  EXPECT_EQ(jobs.Value({"never", "seen"}), 0);
  EXPECT_EQ(wait.Count({"scan"}), 3u);
  EXPECT_EQ(r.Render(), text) << "reading values creates no series";
}

TEST(MetricsRegistryTest, UnlabelledFamiliesShowZeroBeforeTheFirstUpdate) {
  MetricsRegistry r;
  r.AddCounter("t_frames_total", "Frames.");
  r.AddHistogram("t_d_seconds", "D.", {1});
  r.AddGauge("t_state", "State.", {"state"});  // labelled: no series until one is set
  const std::string text = r.Render();
  const std::vector<ParsedFamily> f = Parse(text);
  ASSERT_GE(f.size(), 2u) << text;
  EXPECT_EQ(f[0].samples, (std::map<std::string, std::string>{{"t_frames_total", "0"}})) << text;
  EXPECT_EQ(f[1].samples,
            (std::map<std::string, std::string>{{"t_d_seconds_bucket{le=\"1\"}", "0"},
                                                {"t_d_seconds_bucket{le=\"+Inf\"}", "0"},
                                                {"t_d_seconds_sum", "0"},
                                                {"t_d_seconds_count", "0"}}))
      << text;
  // A labelled family without a series is left out whole (prometheus-cpp writes no HELP or TYPE
  // for it; Prometheus needs neither before the first sample).
  ASSERT_EQ(f.size(), 2u) << text;
  EXPECT_EQ(text.find("t_state"), std::string::npos) << text;
}

TEST(MetricsRegistryTest, SeriesRenderInLabelValueOrder) {
  MetricsRegistry r;
  Counter c = r.AddCounter("t_total", "T.", {"method"});
  for (const char* m : {"m", "c", "x", "a", "q", "b"}) c.Add({m});
  const std::string text = r.Render();
  std::vector<std::string> order;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);)
    if (line.rfind("t_total{", 0) == 0) order.push_back(line);
  EXPECT_EQ(order, (std::vector<std::string>{"t_total{method=\"a\"} 1", "t_total{method=\"b\"} 1",
                                             "t_total{method=\"c\"} 1", "t_total{method=\"m\"} 1",
                                             "t_total{method=\"q\"} 1", "t_total{method=\"x\"} 1"}))
      << text;
}

TEST(MetricsRegistryTest, LabelValuesAreEscaped) {
  MetricsRegistry r;
  Counter c = r.AddCounter("t_total", "T.", {"method"});
  c.Add({"a\"b\\c\nd"});
  EXPECT_NE(r.Render().find("t_total{method=\"a\\\"b\\\\c\\nd\"} 1\n"), std::string::npos) << r.Render();
}

TEST(MetricsRegistryTest, ValuesAsPrometheusCppWritesThem) {
  // prometheus-cpp writes doubles with 16 significant digits (max_digits10 - 1), whole numbers
  // without a fraction, the specials as +Inf, -Inf and Nan (Prometheus parses these case-blind).
  MetricsRegistry r;
  Gauge g = r.AddGauge("t_v", "V.", {"case"});
  const std::vector<std::pair<double, std::string>> cases = {{0, "0"},
                                                             {-3, "-3"},
                                                             {0.1, "0.1"},
                                                             {2.5e-7, "2.5e-07"},
                                                             {1.0 / 3.0, "0.3333333333333333"},
                                                             {350.0 / 3.0, "116.6666666666667"},
                                                             {1e300, "1e+300"},
                                                             {9007199254740992.0, "9007199254740992"},
                                                             {std::numeric_limits<double>::infinity(), "+Inf"},
                                                             {-std::numeric_limits<double>::infinity(), "-Inf"},
                                                             {std::nan(""), "Nan"}};
  for (size_t i = 0; i < cases.size(); ++i) g.Set({std::string(1, char('a' + i))}, cases[i].first);
  const std::vector<ParsedFamily> f = Parse(r.Render());
  ASSERT_EQ(f.size(), 1u);
  for (size_t i = 0; i < cases.size(); ++i) {
    const std::string key = "t_v{case=\"" + std::string(1, char('a' + i)) + "\"}";
    ASSERT_TRUE(f[0].samples.count(key)) << key;
    EXPECT_EQ(f[0].samples.at(key), cases[i].second) << cases[i].first;
  }
}

TEST(MetricsRegistryTest, BadNamesAbortAtDeclaration) {
  EXPECT_DEATH(MetricsRegistry().AddCounter("1bad", "B."), "invalid metric name \"1bad\"");
  EXPECT_DEATH(MetricsRegistry().AddGauge("t_ok", "B.", {"le"}), "invalid label name \"le\" of t_ok");
  EXPECT_DEATH(MetricsRegistry().AddGauge("t_ok", "B.", {"__reserved"}), "invalid label name \"__reserved\"");
  EXPECT_DEATH(MetricsRegistry().AddHistogram("t_h", "B.", {1, 1}), "bucket bounds of t_h must increase");
  EXPECT_DEATH(
      {
        MetricsRegistry twice;
        twice.AddCounter("t_c", "C.");
        twice.AddGauge("t_c", "C.");
      },
      "metric t_c declared twice");
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
  has("inspectd_last_scan_mean_grey 116.6666666666667");
  has("inspectd_last_scan_saturated_percent 1.666666666666667");
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
  // A labelled family without a series is not written at all (prometheus-cpp leaves out its HELP
  // and TYPE too): no artifact bytes for a failed job.
  EXPECT_EQ(text.find("inspectd_artifact_bytes_total"), std::string::npos) << text;
  EXPECT_NE(text.find("inspectd_grpc_calls_total{method=\"inspection.v1.InspectionService/Scan\","
                      "code=\"FAILED_PRECONDITION\"} 2\n"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("inspectd_grpc_calls_total{method=\"grpc.health.v1.Health/Check\",code=\"OK\"} 1\n"),
            std::string::npos);
  EXPECT_NE(text.find("inspectd_rig_present 0\n"), std::string::npos);
  EXPECT_EQ(text.find("inspectd_rig_state{"), std::string::npos) << "no rig, no state series";
}

TEST(ServerMetricsTest, VerificationStateAndTheLastFullRecordsCharacteristicsAreGauges) {
  ServerMetrics m("9.9.9", [] { return 0.0; });
  ScrapeState st;
  st.rig_state = v1::RIG_STATE_READY;
  st.verification_state = v1::VERIFICATION_STATE_FAILED;
  st.verified_characteristics["alpha_z"] = {1.00109, 0.00177};
  st.verified_characteristics["N_M"] = {0.0786, 0.0072};
  st.full_verification_age_days = 2.5;
  const std::string text = m.Render(st);
  auto has = [&](const std::string& line) {
    EXPECT_NE(text.find("\n" + line + "\n"), std::string::npos) << line << "\n---\n" << text;
  };
  has("inspectd_verification_state{state=\"failed\"} 1");
  has("inspectd_verification_state{state=\"verified\"} 0");
  has("inspectd_verification_state{state=\"due\"} 0");
  has("inspectd_verification_characteristic{characteristic=\"alpha_z\"} 1.00109");
  has("inspectd_verification_characteristic_expanded_uncertainty{characteristic=\"N_M\"} 0.0072");
  has("inspectd_verification_full_age_days 2.5");
  // A recalibration: no full verification under the new calibration. The old record's values
  // and age go (no stale numbers), the state says due; a later full record shows again.
  ScrapeState recalibrated;
  recalibrated.rig_state = v1::RIG_STATE_READY;
  recalibrated.verification_state = v1::VERIFICATION_STATE_DUE;
  const std::string after = m.Render(recalibrated);
  EXPECT_NE(after.find("\ninspectd_verification_state{state=\"due\"} 1\n"), std::string::npos) << after;
  EXPECT_EQ(after.find("inspectd_verification_characteristic{"), std::string::npos) << after;
  EXPECT_EQ(after.find("inspectd_verification_characteristic_expanded_uncertainty{"), std::string::npos) << after;
  EXPECT_EQ(after.find("\ninspectd_verification_full_age_days "), std::string::npos) << after;
  recalibrated.verified_characteristics["alpha_z"] = {1.25, 0.0018};  // exact in binary: printed as is
  recalibrated.full_verification_age_days = 0.1;
  const std::string again = m.Render(recalibrated);
  EXPECT_NE(again.find("\ninspectd_verification_characteristic{characteristic=\"alpha_z\"} 1.25\n"), std::string::npos)
      << again;
  EXPECT_EQ(again.find("characteristic=\"N_M\""), std::string::npos) << again;
  EXPECT_NE(again.find("\ninspectd_verification_full_age_days 0.1\n"), std::string::npos) << again;
  // Without a rig (or records) no state series at all.
  ServerMetrics none("9.9.9", [] { return 0.0; });
  EXPECT_EQ(none.Render(ScrapeState{}).find("inspectd_verification_state{"), std::string::npos);
}

}  // namespace
}  // namespace inspection
