// inspectctl as a user runs it: the built binary against the real server on loopback. Checks
// exit codes (docs/inspectctl.md), the one-line error format, result files and the --json output.
#include <cmath>
#include <functional>

#include "common/sha256_file.h"
#include "core/io/depth_export.h"
#include "tests/client_cli/cli_fixture.h"

namespace inspection::testing {
namespace {
TEST_F(CliTest, ScanWritesResultFilesAndPrintsFolderAndDepthSummary) {
  StartServer();
  const fs::path out = work_ / "scan";
  CliResult r = Run({"scan", "--out", out.string(), "--label", "part-7"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");

  v1::Job job;
  ASSERT_TRUE(client_->GetJob(NewestJobId(), &job).ok());
  EXPECT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(job.label(), "part-7");
  // Every artifact but the stack zip, byte for byte.
  int files = 0;
  for (const auto& a : job.result().artifacts()) {
    if (a.kind() == v1::ARTIFACT_KIND_STACK_ZIP) {
      EXPECT_FALSE(fs::exists(out / a.file_name()));
      continue;
    }
    ++files;
    ASSERT_TRUE(fs::exists(out / a.file_name())) << a.file_name();
    EXPECT_EQ(Sha256FileHex(out / a.file_name()), a.sha256()) << a.file_name();
  }
  EXPECT_GE(files, 4);
  for (const char* name : {"depth.tiff", "confidence.tiff", "all_in_focus.png", "depth_preview.png"}) {
    EXPECT_TRUE(fs::exists(out / name)) << name;
  }
  // Non-terminal output: one plain line per event, then the summary.
  EXPECT_NE(r.out.find(job.job_id() + " #1 "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("results: " + fs::absolute(out).string()), std::string::npos) << r.out;
  char valid[64];
  std::snprintf(valid, sizeof valid, "valid %.1f %%", job.result().depth().valid_percent());
  EXPECT_NE(r.out.find(valid), std::string::npos) << r.out;
  ASSERT_TRUE(job.result().depth().has_ground_truth());
  char rmse[64];
  std::snprintf(rmse, sizeof rmse, "RMSE %.3f um", job.result().depth().rmse_um());
  EXPECT_NE(r.out.find(rmse), std::string::npos) << r.out;
  // The uncalibrated server's default illumination, named in the summary.
  EXPECT_EQ(job.result().depth().illumination(), "STD");
  EXPECT_NE(r.out.find("\nillumination: STD\n"), std::string::npos) << r.out;
}

TEST_F(CliTest, PostProcessingFlagsReachTheServerAndItsFiguresArePrinted) {
  StartServer();
  // The saturating cutter under STD leaves pixels without depth (clipped glints).
  ASSERT_EQ(Run({"specimen", "set", "cutter"}).exit_code, 0);
  // --fill: every pixel gets a depth, and the summary says how many were interpolated.
  CliResult r = Run({"scan", "--out", (work_ / "filled").string(), "--fill", "--refine", "guided-filter"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  v1::Job job;
  ASSERT_TRUE(client_->GetJob(NewestJobId(), &job).ok());
  const v1::DepthSummary& d = job.result().depth();
  EXPECT_DOUBLE_EQ(d.valid_percent(), 100.0);
  ASSERT_GT(d.filled_percent(), 1.0);
  char line[128];
  std::snprintf(line, sizeof line, "rejected by the depth consistency check, %.1f %% filled", d.filled_percent());
  EXPECT_NE(r.out.find(line), std::string::npos) << r.out;
  // --no-consistency: nothing is rejected, and nothing is printed about it.
  r = Run({"scan", "--out", (work_ / "plain").string(), "--no-consistency"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_TRUE(client_->GetJob(NewestJobId(), &job).ok());
  EXPECT_EQ(job.result().depth().consistency_rejected_percent(), 0.0);
  EXPECT_EQ(r.out.find("post-processing:"), std::string::npos) << r.out;
  // Bad values: usage (2) in the CLI, INVALID_ARGUMENT (4) naming the field from the server.
  EXPECT_EQ(Run({"scan", "--out", "d", "--refine", "blur"}).exit_code, 2);
  r = Run({"scan", "--out", (work_ / "isff").string(), "--method", "isff-gt", "--fill"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_NE(r.err.find("reconstruction.fill_low_confidence"), std::string::npos) << r.err;
  // --illumination-invariant reaches the engine: under STD the cutter's glints light their
  // defocused halos brighter than the texture beside them; divided by the window's light, the
  // focus measure follows the texture (docs/illumination.md "Bias and the default, re-checked").
  r = Run({"scan", "--out", (work_ / "default").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_TRUE(client_->GetJob(NewestJobId(), &job).ok());
  const v1::DepthSummary plain = job.result().depth();
  r = Run({"scan", "--out", (work_ / "invariant").string(), "--illumination-invariant"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_TRUE(client_->GetJob(NewestJobId(), &job).ok());
  const v1::DepthSummary invariant = job.result().depth();
  std::printf("cutter STD: RMSE %.3f um at %.1f %%; illumination-invariant %.3f um at %.1f %%\n", plain.rmse_um(),
              plain.valid_percent(), invariant.rmse_um(), invariant.valid_percent());
  EXPECT_LT(invariant.rmse_um(), 0.8 * plain.rmse_um());
  r = Run({"scan", "--out", (work_ / "isff2").string(), "--method", "isff-gt", "--illumination-invariant"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_NE(r.err.find("reconstruction.illumination_invariant"), std::string::npos) << r.err;
}

TEST_F(CliTest, JsonScanIsOneEventPerLineThenOneResultObject) {
  StartServer();
  const fs::path out = work_ / "scan";
  CliResult r = Run({"scan", "--out", out.string(), "--json"});  // global option after the command
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto lines = JsonLines(r.out);
  ASSERT_GE(lines.size(), 3u);
  uint64_t sequence = 0;
  int frame_events = 0;
  for (size_t i = 0; i + 1 < lines.size(); ++i) {
    ASSERT_EQ(lines[i]["type"], "event") << lines[i].dump();
    const json& e = lines[i]["event"];
    const uint64_t seq = std::stoull(e["sequence"].get<std::string>());  // uint64 is a JSON string
    EXPECT_EQ(seq, sequence + 1);
    sequence = seq;
    if (e.contains("frame")) ++frame_events;
  }
  const json& result = lines.back();
  ASSERT_EQ(result["type"], "result");
  EXPECT_EQ(result["exit_code"], 0);
  EXPECT_EQ(result["job"]["state"], "JOB_STATE_SUCCEEDED");
  EXPECT_EQ(lines[lines.size() - 2]["event"]["state"], "JOB_STATE_SUCCEEDED");
  EXPECT_EQ(result["job"]["result"]["depth"]["frame_count"].get<int>(), frame_events);
  EXPECT_EQ(result["output_dir"], fs::absolute(out).string());
  const auto files = result["files"].get<std::vector<std::string>>();
  for (const char* name : {"depth.tiff", "confidence.tiff", "all_in_focus.png", "depth_preview.png"}) {
    EXPECT_NE(std::find(files.begin(), files.end(), name), files.end()) << name;
    EXPECT_TRUE(fs::exists(out / name)) << name;
  }
}

TEST_F(CliTest, BadWindowExits4WithOneErrorLineNamingWindowPx) {
  StartServer();
  const fs::path out = work_ / "bad";
  CliResult r = Run({"scan", "--out", out.string(), "--window", "4"});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(r.err.rfind("inspectctl: INVALID_ARGUMENT: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("window_px"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out / "depth.tiff"));

  r = Run({"--json", "scan", "--out", out.string(), "--window", "4"});
  EXPECT_EQ(r.exit_code, 4);
  auto lines = JsonLines(r.out);
  ASSERT_FALSE(lines.empty());
  EXPECT_EQ(lines.back()["type"], "result");
  EXPECT_EQ(lines.back()["exit_code"], 4);
  EXPECT_EQ(lines.back()["error"]["code"], "INVALID_ARGUMENT");
}

TEST_F(CliTest, UnknownIdsAreNotFoundExit4) {
  StartServer();
  for (const auto& args : std::vector<std::vector<std::string>>{
           {"watch", "no-such-job"},
           {"cancel", "no-such-job"},
           {"download", "no-such-id", "--out", (work_ / "x").string()},
           {"reconstruct", "--scan-id", "no-such-scan", "--out", (work_ / "y").string()},
           {"calibration", "show", "no-such-calibration"}}) {
    CliResult r = Run(args);
    EXPECT_EQ(r.exit_code, 4) << args[0];
    EXPECT_EQ(r.err.rfind("inspectctl: NOT_FOUND: ", 0), 0u) << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
  }
  EXPECT_FALSE(fs::exists(work_ / "x"));
}

TEST_F(CliTest, UsageErrorsExit2AndUnreachableServerExits3) {
  StartServer();
  EXPECT_EQ(Run({}).exit_code, 2);
  EXPECT_EQ(Run({"scan"}).exit_code, 2);  // --out missing
  EXPECT_EQ(Run({"scan", "--out", "d", "--focus-measure", "nope"}).exit_code, 2);
  EXPECT_EQ(Run({"scan", "--out", "d", "--export", "jpeg"}).exit_code, 2);
  EXPECT_EQ(Run({"reconstruct", "--out", "d"}).exit_code, 2);  // no source
  EXPECT_EQ(Run({"reconstruct", "--out", "d", "--scan-id", "a", "--stack", work_.string()}).exit_code, 2);
  EXPECT_EQ(Run({"calibrate", "--step", "everything"}).exit_code, 2);
  EXPECT_EQ(Run({"--help"}).exit_code, 0);

  const std::string address = server_->address();
  StopServer();
  CliProcess p({"--server", address, "--connect-timeout", "0.5", "status"}, work_ / "unreachable.txt");
  CliResult r = p.Finish();
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_EQ(r.err.rfind("inspectctl: UNAVAILABLE: ", 0), 0u) << r.err;
}

TEST_F(CliTest, UploadedStackReconstructsLikeTheScanAndABrokenStackFailsBeforeAnyJob) {
  StartServer();
  const json scan = JsonScan("scan");
  const std::string scan_id = scan["job"]["result"]["scan_id"];
  ASSERT_FALSE(scan_id.empty());
  // The stored stack folder is exactly what a user would upload.
  const fs::path stack = work_ / "stack";
  ExtractStoredStack(data_dir_, scan_id, stack);

  const fs::path rec_dir = work_ / "rec";
  CliResult r = Run({"--json", "reconstruct", "--stack", stack.string(), "--out", rec_dir.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json rec = JsonLines(r.out).back();
  EXPECT_EQ(rec["job"]["kind"], "JOB_KIND_RECONSTRUCT");
  // The ground truth went along with the frames, so the error is reported, and it is the scan's.
  ASSERT_TRUE(rec["job"]["result"]["depth"]["has_ground_truth"].get<bool>());
  EXPECT_NEAR(rec["job"]["result"]["depth"]["rmse_um"].get<double>(),
              scan["job"]["result"]["depth"]["rmse_um"].get<double>(), 1e-3);
  auto scan_depth = ReadDepthTiff(work_ / "scan" / "depth.tiff");
  auto rec_depth = ReadDepthTiff(rec_dir / "depth.tiff");
  ASSERT_TRUE(scan_depth.ok() && rec_depth.ok());
  ASSERT_EQ(scan_depth->size(), rec_depth->size());
  double max_diff_um = 0.0;
  for (int y = 0; y < scan_depth->rows; ++y) {
    for (int x = 0; x < scan_depth->cols; ++x) {
      const float a = scan_depth->at<float>(y, x), b = rec_depth->at<float>(y, x);
      ASSERT_EQ(std::isnan(a), std::isnan(b)) << x << "," << y;
      if (!std::isnan(a)) max_diff_um = std::max(max_diff_um, std::abs(double(a) - double(b)));
    }
  }
  EXPECT_LT(max_diff_um, 1e-3);

  // From the stored scan, by id.
  r = Run({"--json", "reconstruct", "--scan-id", scan_id, "--out", (work_ / "rec2").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(work_ / "rec2" / "depth.tiff"));

  // A frame listed in stack.json but missing: named, and no job is created.
  v1::ListJobsResponse before;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &before).ok());
  fs::remove(stack / "frame_0003.png");
  r = Run({"reconstruct", "--stack", stack.string(), "--out", (work_ / "rec3").string()});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.err.rfind("inspectctl: INVALID_ARGUMENT: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("frame_0003.png"), std::string::npos) << r.err;
  v1::ListJobsResponse after;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &after).ok());
  EXPECT_EQ(after.jobs_size(), before.jobs_size());
}

TEST_F(CliTest, DownloadResumesAPartialFileAndRejectsACorruptOne) {
  StartServer();
  const json scan = JsonScan("scan");
  const std::string job_id = scan["job"]["job_id"];
  std::string depth_id;
  for (const auto& a : scan["job"]["result"]["artifacts"]) {
    if (a["kind"] == "ARTIFACT_KIND_DEPTH_TIFF") depth_id = a["artifact_id"];
  }
  ASSERT_FALSE(depth_id.empty());
  const std::string depth_bytes = ReadAll(work_ / "scan" / "depth.tiff");
  ASSERT_GT(depth_bytes.size(), 2000u);

  const fs::path resumed = work_ / "resumed.tiff";
  std::ofstream(resumed.string() + ".part", std::ios::binary) << depth_bytes.substr(0, 1000);
  CliResult r = Run({"download", depth_id, "--out", resumed.string(), "--resume"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(ReadAll(resumed), depth_bytes);
  EXPECT_FALSE(fs::exists(resumed.string() + ".part"));

  const fs::path corrupt = work_ / "corrupt.tiff";
  std::string wrong = depth_bytes.substr(0, 1000);
  wrong[500] = static_cast<char>(wrong[500] ^ 0x5A);
  std::ofstream(corrupt.string() + ".part", std::ios::binary) << wrong;
  r = Run({"download", depth_id, "--out", corrupt.string(), "--resume"});
  EXPECT_EQ(r.exit_code, 6);
  EXPECT_EQ(r.err.rfind("inspectctl: DATA_LOSS: ", 0), 0u) << r.err;
  EXPECT_FALSE(fs::exists(corrupt));
  EXPECT_FALSE(fs::exists(corrupt.string() + ".part"));

  // A job id downloads all its results into a folder, the stack zip only when asked.
  r = Run({"download", job_id, "--out", (work_ / "all").string(), "--include-stack"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(ReadAll(work_ / "all" / "depth.tiff"), depth_bytes);
  EXPECT_TRUE(fs::exists(work_ / "all" / "stack.zip"));
}

TEST_F(CliTest, CtrlCStopsFollowingButTheJobRunsOnAndWatchFetchesIt) {
  control_ = std::make_shared<RigControl>();
  control_->hold_at_frame = 2;
  StartServer();
  auto p = Start({"scan", "--out", (work_ / "never").string()});
  std::string first;
  ASSERT_TRUE(p->ReadLine(&first));  // an event line: the CLI knows the job id now
  const std::string job_id = first.substr(0, first.find(' '));
  ASSERT_TRUE(control_->WaitUntilHolding());
  p->Signal(SIGINT);
  CliResult r = p->Finish();
  EXPECT_EQ(r.exit_code, 130);
  EXPECT_NE(r.err.find("inspectctl watch " + job_id), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(work_ / "never"));

  v1::Job job;
  ASSERT_TRUE(client_->GetJob(job_id, &job).ok());
  EXPECT_EQ(job.state(), v1::JOB_STATE_RUNNING);  // not cancelled by the interrupt
  control_->Release();

  r = Run({"watch", job_id, "--out", (work_ / "watched").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find(job_id + " #1 "), std::string::npos);  // replayed from the first event
  EXPECT_TRUE(fs::exists(work_ / "watched" / "depth.tiff"));
}

TEST_F(CliTest, CancelledJobExits5) {
  control_ = std::make_shared<RigControl>();
  control_->hold_at_frame = 2;
  StartServer();
  auto scan = Start({"scan", "--out", (work_ / "never").string()});
  ASSERT_TRUE(control_->WaitUntilHolding());
  const std::string job_id = NewestJobId();
  CliResult c = Run({"--json", "cancel", job_id});
  EXPECT_EQ(c.exit_code, 0) << c.err;
  EXPECT_EQ(JsonLines(c.out).at(0)["job_id"], job_id);
  control_->Release();
  CliResult r = scan->Finish();
  EXPECT_EQ(r.exit_code, 5);
  EXPECT_EQ(r.err.rfind("inspectctl: CANCELLED: ", 0), 0u) << r.err;
  EXPECT_FALSE(fs::exists(work_ / "never" / "depth.tiff"));
  r = Run({"--json", "watch", job_id});
  EXPECT_EQ(r.exit_code, 5);
  const json result = JsonLines(r.out).back();
  EXPECT_EQ(result["job"]["state"], "JOB_STATE_CANCELLED");
  EXPECT_EQ(result["error"]["code"], "CANCELLED");
  EXPECT_EQ(result["exit_code"], 5);
}

TEST_F(CliTest, StatusJobsAndSpecimenAsJson) {
  StartServer();
  CliResult r = Run({"--json", "status"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  json status = JsonLines(r.out).at(0);
  EXPECT_EQ(status["state"], "RIG_STATE_READY");
  EXPECT_EQ(status["simulated"], true);
  EXPECT_EQ(status["specimen"], "skew5");
  // The rig's optics set the automatic z range's coarse step (20 um on the simulated thesis rig).
  EXPECT_EQ(status["scan_defaults"]["focus_search_step_um"], 20.0) << status.dump();
  r = Run({"status"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("step 5.00 um, exposure "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(" us, focus search step 20.0 um\n"), std::string::npos) << r.out;

  r = Run({"--json", "specimen", "set", "lens"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(JsonLines(r.out).at(0)["current"], "lens");
  EXPECT_EQ(Run({"specimen", "set", "no-such-specimen"}).exit_code, 4);

  const std::string first = JsonScan("a")["job"]["job_id"];
  const std::string second = JsonScan("b")["job"]["job_id"];
  r = Run({"--json", "jobs", "--kind", "scan", "--limit", "1"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  json jobs = JsonLines(r.out).at(0)["jobs"];
  ASSERT_EQ(jobs.size(), 1u);
  EXPECT_EQ(jobs[0]["job_id"], second);  // newest first
  r = Run({"jobs", "--state", "succeeded"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(CountLines(r.out), 2) << r.out;
  EXPECT_NE(r.out.find(first), std::string::npos);
  r = Run({"--json", "jobs", "--kind", "reconstruct"});
  EXPECT_EQ(JsonLines(r.out).at(0)["jobs"].size(), 0u);
}

TEST_F(CliTest, BadArgumentsOfEveryCommandExit2BeforeAnyCall) {
  StartServer();
  for (const auto& args : std::vector<std::vector<std::string>>{
           {"no-such-command"},
           {"status", "extra"},
           {"status", "jobs"},  // one command per call
           {"calibration"},
           {"specimen"},
           {"specimen", "set"},
           {"watch"},
           {"cancel"},
           {"download", "some-id"},                          // --out missing
           {"scan", "--out", "d", "--illumination", "HDR"},  // mode names are lower case
           {"scan", "--out", "d", "--window", "seven"},
           {"scan", "--out", "d", "--lambda", "a"},
           {"reconstruct", "--out", "d", "--stack", (work_ / "no-such-folder").string()},
           {"jobs", "--limit", "0"},
           {"jobs", "--state", "done"}}) {
    CliResult r = Run(args);
    EXPECT_EQ(r.exit_code, 2) << args[0] << " " << r.err;
    EXPECT_EQ(r.out, "") << args[0];
    EXPECT_NE(r.err, "") << args[0];
  }
  CliProcess p({"--server", server_->address(), "--connect-timeout", "0", "status"}, work_ / "timeout.txt");
  EXPECT_EQ(p.Finish().exit_code, 2);
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 0);

  // Help of a command: exit 0, on stdout, lists every option of the command.
  CliResult help = Run({"scan", "--help"});
  EXPECT_EQ(help.exit_code, 0);
  for (const char* option : {"--out", "--z-start", "--illumination", "--lambda", "--target-grey", "--focus-measure",
                             "--window", "--min-confidence", "--export", "--include-stack"}) {
    EXPECT_NE(help.out.find(option), std::string::npos) << option;
  }
}

TEST_F(CliTest, TokenFileIsTrimmedAndSentAndAnUnusableTokenOrCaFileExits2) {
  ServerOptions opt;
  opt.listen_address = "127.0.0.1:0";
  opt.data_dir = data_dir_;
  opt.auth_token = "s3cret";
  opt.simulation = SimOptions();
  auto server = InspectionServer::Start(opt);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  server_ = std::move(*server);

  const fs::path token = work_ / "token", wrong = work_ / "wrong", blank = work_ / "blank";
  std::ofstream(token) << "  s3cret \n";
  std::ofstream(wrong) << "s3cret-not";
  std::ofstream(blank) << " \n\t";
  CliResult r = Run({"--json", "--token-file", token.string(), "status"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(JsonLines(r.out).at(0)["state"], "RIG_STATE_READY");

  for (const auto& args :
       std::vector<std::vector<std::string>>{{"status"}, {"--token-file", wrong.string(), "status"}}) {
    r = Run(args);
    EXPECT_EQ(r.exit_code, 4);
    EXPECT_EQ(r.err.rfind("inspectctl: UNAUTHENTICATED: ", 0), 0u) << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
  }

  const fs::path missing = work_ / "missing";
  const std::vector<std::pair<std::vector<std::string>, std::string>> unusable = {
      {{"--token-file", missing.string(), "status"},
       "inspectctl: INVALID_ARGUMENT: cannot read token file " + missing.string() + "\n"},
      {{"--token-file", blank.string(), "status"},
       "inspectctl: INVALID_ARGUMENT: token file " + blank.string() + " is empty\n"},
      {{"--tls-ca", missing.string(), "status"},
       "inspectctl: INVALID_ARGUMENT: tls_ca_file: cannot read " + missing.string() + "\n"}};
  for (const auto& [args, error_line] : unusable) {
    r = Run(args);
    EXPECT_EQ(r.exit_code, 2) << args[0];
    EXPECT_EQ(r.err, error_line);
    EXPECT_EQ(r.out, "");
  }
}

TEST_F(CliTest, PlainTextOfStatusResetSpecimensAndEmptyLists) {
  StartServer();
  CliResult r = Run({"status"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("state: ready\n", 0), 0u) << r.out;
  for (const char* line : {"\ncalibration: none\n", "\nrunning job: none, queue 0/4\n",
                           "\nsimulated rig, specimen: skew5\n", "\nserver version: "}) {
    EXPECT_NE(r.out.find(line), std::string::npos) << line << "\n" << r.out;
  }
  r = Run({"reset"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("state: ready\n", 0), 0u) << r.out;

  r = Run({"specimen", "list"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("* skew5\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  lens\n"), std::string::npos) << r.out;
  r = Run({"specimen", "set", "lens"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("* lens\n"), std::string::npos) << r.out;

  r = Run({"jobs"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.out, "no jobs\n");
  EXPECT_EQ(Run({"jobs", "-q"}).out, "");
  r = Run({"calibration", "list"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.out, "no calibrations\n");
  r = Run({"--json", "calibration", "list"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(JsonLines(r.out).at(0)["calibrations"], json::array());
}

TEST_F(CliTest, QuietScanPrintsOnlyTheFolderAndARunningJobHasNoResultsToDownload) {
  control_ = std::make_shared<RigControl>();
  control_->hold_at_frame = 2;
  StartServer();
  const fs::path out = work_ / "quiet";
  auto scan = Start({"-q", "scan", "--out", out.string()});
  ASSERT_TRUE(control_->WaitUntilHolding());
  const std::string job_id = NewestJobId();
  CliResult r = Run({"download", job_id, "--out", (work_ / "early").string()});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.err,
            "inspectctl: FAILED_PRECONDITION: job " + job_id + " is running; only a succeeded job has results\n");
  EXPECT_FALSE(fs::exists(work_ / "early"));
  control_->Release();
  r = scan->Finish();
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, fs::absolute(out).string() + "\n");
  EXPECT_EQ(r.err, "");
  EXPECT_TRUE(fs::exists(out / "depth.tiff"));

  // Watching a succeeded job without --out lists its artifacts instead of downloading them.
  r = Run({"watch", job_id});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("job " + job_id + " succeeded (scan "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("artifacts (inspectctl download ID --out FILE):\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("  depth.tiff  "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\ndepth: "), std::string::npos) << r.out;
}

}  // namespace
}  // namespace inspection::testing
