// InspectionClient against a scripted fake of inspection.v1 (no rig, no storage): what the
// client puts on the wire (upload order, chunk sizes, bearer token, resume offsets) and how it
// treats what comes back (terminal job, stream status, sha256 integrity).
#include "client_cli/inspection_client.h"

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <map>
#include <mutex>
#include <random>

#include "common/sha256_file.h"

namespace inspection::client {
namespace {

namespace fs = std::filesystem;

constexpr int64_t kMiB = int64_t{1} << 20;

std::string Blob(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::string s(n, '\0');
  for (auto& c : s) c = static_cast<char>(rng() & 0xFF);
  return s;
}

std::string ReadFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void WriteFile(const fs::path& p, const std::string& bytes) {
  std::ofstream out(p, std::ios::binary);
  out << bytes;
}

// Records what clients send and answers from fixed artifacts.
class FakeService final : public v1::InspectionService::Service {
 public:
  struct ReceivedFile {
    std::string bytes;
    std::vector<int64_t> chunk_sizes;
    bool saw_last = false;
  };

  std::mutex mu;
  int reconstruct_calls = 0;
  v1::ReconstructStart start;
  std::vector<std::string> file_order;
  std::map<std::string, ReceivedFile> files;
  std::vector<std::string> authorization;
  std::vector<int64_t> download_offsets;
  std::map<std::string, std::string> artifacts;  // id -> bytes
  std::string wrong_sha_artifact;                // served with a sha256 of other bytes

  grpc::Status Reconstruct(grpc::ServerContext* ctx,
                           grpc::ServerReaderWriter<v1::JobEvent, v1::ReconstructRequest>* stream) override {
    std::lock_guard<std::mutex> lock(mu);
    ++reconstruct_calls;
    Note(ctx);
    v1::ReconstructRequest req;
    if (!stream->Read(&req) || !req.has_start()) return {grpc::StatusCode::INVALID_ARGUMENT, "start first"};
    start = req.start();
    while (stream->Read(&req)) {
      if (!req.has_file_chunk()) return {grpc::StatusCode::INVALID_ARGUMENT, "file_chunk expected"};
      const auto& c = req.file_chunk();
      if (files.count(c.path()) == 0) file_order.push_back(c.path());
      ReceivedFile& f = files[c.path()];
      if (c.offset() != static_cast<int64_t>(f.bytes.size())) return {grpc::StatusCode::INVALID_ARGUMENT, "offset"};
      f.bytes += c.data();
      f.chunk_sizes.push_back(static_cast<int64_t>(c.data().size()));
      f.saw_last = f.saw_last || c.last();
    }
    v1::JobEvent running;
    running.set_job_id("job-r");
    running.set_sequence(1);
    running.set_state(v1::JOB_STATE_RUNNING);
    stream->Write(running);
    v1::JobEvent done;
    done.set_job_id("job-r");
    done.set_sequence(2);
    done.set_state(v1::JOB_STATE_SUCCEEDED);
    done.mutable_job()->set_job_id("job-r");
    done.mutable_job()->set_state(v1::JOB_STATE_SUCCEEDED);
    done.mutable_job()->set_label(start.label());
    stream->Write(done);
    return grpc::Status::OK;
  }

  grpc::Status WatchJob(grpc::ServerContext* ctx, const v1::WatchJobRequest* req,
                        grpc::ServerWriter<v1::JobEvent>* writer) override {
    Note(ctx);
    if (req->job_id() != "job-failed") return {grpc::StatusCode::NOT_FOUND, "job " + req->job_id()};
    v1::JobEvent e;
    e.set_job_id("job-failed");
    e.set_sequence(1);
    e.set_state(v1::JOB_STATE_RUNNING);
    writer->Write(e);
    e.set_sequence(2);
    e.set_state(v1::JOB_STATE_FAILED);
    e.mutable_job()->set_job_id("job-failed");
    e.mutable_job()->set_state(v1::JOB_STATE_FAILED);
    e.mutable_job()->set_error_code(static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
    e.mutable_job()->set_error_message("window_px 4 must be odd");
    writer->Write(e);
    return {grpc::StatusCode::INVALID_ARGUMENT, "window_px 4 must be odd"};
  }

  grpc::Status DownloadArtifact(grpc::ServerContext* ctx, const v1::DownloadArtifactRequest* req,
                                grpc::ServerWriter<v1::ArtifactChunk>* writer) override {
    std::string bytes;
    std::string sha;
    {
      std::lock_guard<std::mutex> lock(mu);
      Note(ctx);
      download_offsets.push_back(req->offset());
      auto it = artifacts.find(req->artifact_id());
      if (it == artifacts.end()) return {grpc::StatusCode::NOT_FOUND, "artifact " + req->artifact_id()};
      bytes = it->second;
      sha = Sha256Of(req->artifact_id() == wrong_sha_artifact ? bytes + "x" : bytes);
    }
    const int64_t size = static_cast<int64_t>(bytes.size());
    if (req->offset() > size) return {grpc::StatusCode::OUT_OF_RANGE, "offset beyond end"};
    const int64_t end = req->limit() > 0 ? std::min(size, req->offset() + req->limit()) : size;
    for (int64_t off = req->offset(); off < end; off += kMiB) {
      v1::ArtifactChunk c;
      c.set_artifact_id(req->artifact_id());
      c.set_offset(off);
      c.set_data(bytes.substr(static_cast<size_t>(off), static_cast<size_t>(std::min(kMiB, end - off))));
      c.set_total_size(size);
      c.set_sha256(sha);
      writer->Write(c);
    }
    return grpc::Status::OK;
  }

 private:
  static std::string Sha256Of(const std::string& bytes) {
    const fs::path tmp = fs::temp_directory_path() / ("fake_sha_" + std::to_string(::getpid()));
    WriteFile(tmp, bytes);
    std::string hex = Sha256FileHex(tmp).value_or("");
    fs::remove(tmp);
    return hex;
  }
  void Note(grpc::ServerContext* ctx) {
    auto range = ctx->client_metadata().equal_range("authorization");
    for (auto it = range.first; it != range.second; ++it)
      authorization.emplace_back(it->second.data(), it->second.size());
  }
};

class InspectionClientTest : public ::testing::Test {
 protected:
  void SetUp() override {
    grpc::ServerBuilder builder;
    int port = 0;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
    builder.RegisterService(&fake_);
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    ASSERT_GT(port, 0);
    options_.target = "127.0.0.1:" + std::to_string(port);
    options_.auth_token = "secret-token";
    dir_ = fs::temp_directory_path() / ("client_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    server_->Shutdown();
    fs::remove_all(dir_);
  }

  // A stack folder whose second frame needs two chunks (the fake does not decode images).
  fs::path WriteStack() {
    const fs::path stack = dir_ / "stack";
    fs::create_directories(stack / "sub");
    WriteFile(stack / "stack.json",
              R"({"format":"inspection-stack","version":1,"pixel_size_um":0.74,"bit_depth":8,)"
              R"("frames":[{"file":"f0.png","z_um":0},{"file":"sub/f1.png","z_um":5},{"file":"f2.png","z_um":10}]})");
    WriteFile(stack / "f0.png", Blob(1000, 1));
    WriteFile(stack / "sub/f1.png", Blob(static_cast<size_t>(kMiB + kMiB / 2), 2));
    WriteFile(stack / "f2.png", "");
    WriteFile(stack / "unlisted.png", Blob(10, 3));
    WriteFile(stack / "ground_truth_depth.tiff", Blob(20, 4));
    return stack;
  }

  FakeService fake_;
  std::unique_ptr<grpc::Server> server_;
  ClientOptions options_;
  fs::path dir_;
};

TEST_F(InspectionClientTest, UploadSendsManifestListedFramesAndGroundTruthInChunksOfAtMostOneMiB) {
  const fs::path stack = WriteStack();
  InspectionClient client(options_);
  ASSERT_TRUE(client.WaitConnected().ok());
  v1::ReconstructStart start;
  start.set_label("part-42");
  start.set_scan_id("to-be-replaced");
  std::vector<uint64_t> sequences;
  int64_t last_done = -1, last_total = -1;
  v1::Job job;
  grpc::Status s = client.ReconstructUpload(
      stack, start, [&](const v1::JobEvent& e) { sequences.push_back(e.sequence()); }, &job,
      [&](int64_t done, int64_t total) {
        last_done = done;
        last_total = total;
      });
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(sequences, (std::vector<uint64_t>{1, 2}));
  EXPECT_EQ(job.job_id(), "job-r");
  EXPECT_EQ(job.label(), "part-42");

  std::lock_guard<std::mutex> lock(fake_.mu);
  ASSERT_TRUE(fake_.start.has_upload());
  const int64_t manifest_size = static_cast<int64_t>(fs::file_size(stack / "stack.json"));
  const int64_t total = manifest_size + 1000 + kMiB + kMiB / 2 + 0 + 20;
  EXPECT_EQ(fake_.start.upload().file_count(), 5);
  EXPECT_EQ(fake_.start.upload().total_bytes(), total);
  EXPECT_EQ(last_done, total);
  EXPECT_EQ(last_total, total);
  EXPECT_EQ(fake_.file_order,
            (std::vector<std::string>{"stack.json", "f0.png", "sub/f1.png", "f2.png", "ground_truth_depth.tiff"}));
  EXPECT_EQ(fake_.files["sub/f1.png"].chunk_sizes, (std::vector<int64_t>{kMiB, kMiB / 2}));
  EXPECT_EQ(fake_.files["sub/f1.png"].bytes, ReadFile(stack / "sub/f1.png"));
  EXPECT_EQ(fake_.files["stack.json"].bytes, ReadFile(stack / "stack.json"));
  EXPECT_EQ(fake_.files["f2.png"].chunk_sizes, (std::vector<int64_t>{0}));
  for (const auto& [name, f] : fake_.files) EXPECT_TRUE(f.saw_last) << name;
  ASSERT_FALSE(fake_.authorization.empty());
  EXPECT_EQ(fake_.authorization[0], "Bearer secret-token");
}

TEST_F(InspectionClientTest, UploadWithoutReadableManifestOrFrameFailsBeforeAnyCall) {
  InspectionClient client(options_);
  v1::Job job;
  grpc::Status s = client.ReconstructUpload(dir_ / "nowhere", {}, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("stack.json"), std::string::npos) << s.error_message();

  const fs::path stack = WriteStack();
  fs::remove(stack / "sub/f1.png");
  s = client.ReconstructUpload(stack, {}, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("frame 1 (sub/f1.png)"), std::string::npos) << s.error_message();

  WriteFile(stack / "stack.json", R"({"frames":[{"file":"../escape.png"}]})");
  s = client.ReconstructUpload(stack, {}, {}, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("frames[0].file"), std::string::npos) << s.error_message();

  std::lock_guard<std::mutex> lock(fake_.mu);
  EXPECT_EQ(fake_.reconstruct_calls, 0);
}

TEST_F(InspectionClientTest, WatchReturnsTerminalJobAndTheStreamsError) {
  InspectionClient client(options_);
  int events = 0;
  v1::Job job;
  grpc::Status s = client.Watch(
      "job-failed", [&](const v1::JobEvent&) { ++events; }, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(s.error_message(), "window_px 4 must be odd");
  EXPECT_EQ(events, 2);
  EXPECT_EQ(job.state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(job.job_id(), "job-failed");

  v1::Job untouched;
  s = client.Watch("nope", {}, &untouched);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(untouched.job_id().empty());
}

TEST_F(InspectionClientTest, DownloadWritesVerifiedFileAndResumesFromPart) {
  const std::string bytes = Blob(static_cast<size_t>(2 * kMiB + 123), 7);
  {
    std::lock_guard<std::mutex> lock(fake_.mu);
    fake_.artifacts["a1"] = bytes;
  }
  InspectionClient client(options_);
  const fs::path dest = dir_ / "out" / "depth.tiff";
  int64_t last_done = 0;
  ASSERT_TRUE(client.DownloadArtifact("a1", dest, false, [&](int64_t done, int64_t) { last_done = done; }).ok());
  EXPECT_EQ(ReadFile(dest), bytes);
  EXPECT_EQ(last_done, static_cast<int64_t>(bytes.size()));
  EXPECT_FALSE(fs::exists(dest.string() + ".part"));

  // A partial download continues from the .part's size.
  const fs::path dest2 = dir_ / "resumed.tiff";
  WriteFile(dest2.string() + ".part", bytes.substr(0, 1000));
  ASSERT_TRUE(client.DownloadArtifact("a1", dest2, true).ok());
  EXPECT_EQ(ReadFile(dest2), bytes);

  // A complete .part: nothing left to stream, still verified.
  const fs::path dest3 = dir_ / "complete.tiff";
  WriteFile(dest3.string() + ".part", bytes);
  ASSERT_TRUE(client.DownloadArtifact("a1", dest3, true).ok());
  EXPECT_EQ(ReadFile(dest3), bytes);

  // A .part longer than the artifact starts over.
  const fs::path dest4 = dir_ / "stale.tiff";
  WriteFile(dest4.string() + ".part", bytes + "garbage");
  ASSERT_TRUE(client.DownloadArtifact("a1", dest4, true).ok());
  EXPECT_EQ(ReadFile(dest4), bytes);

  std::lock_guard<std::mutex> lock(fake_.mu);
  EXPECT_EQ(fake_.download_offsets, (std::vector<int64_t>{0, 1000, static_cast<int64_t>(bytes.size()), 0,
                                                          static_cast<int64_t>(bytes.size()) + 7, 0}));
}

TEST_F(InspectionClientTest, DownloadIntegrityFailureIsDataLossAndRemovesThePart) {
  const std::string bytes = Blob(5000, 9);
  {
    std::lock_guard<std::mutex> lock(fake_.mu);
    fake_.artifacts["a1"] = bytes;
    fake_.artifacts["bad"] = bytes;
    fake_.wrong_sha_artifact = "bad";
  }
  InspectionClient client(options_);
  const fs::path dest = dir_ / "bad.tiff";
  grpc::Status s = client.DownloadArtifact("bad", dest, false);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::DATA_LOSS);
  EXPECT_FALSE(fs::exists(dest));
  EXPECT_FALSE(fs::exists(dest.string() + ".part"));

  // A corrupted .part resumed against correct bytes fails the whole-file check.
  const fs::path dest2 = dir_ / "corrupt.tiff";
  std::string wrong_prefix = bytes.substr(0, 100);
  wrong_prefix[50] = static_cast<char>(wrong_prefix[50] ^ 0x01);
  WriteFile(dest2.string() + ".part", wrong_prefix);
  s = client.DownloadArtifact("a1", dest2, true);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::DATA_LOSS);
  EXPECT_FALSE(fs::exists(dest2));
  EXPECT_FALSE(fs::exists(dest2.string() + ".part"));

  s = client.DownloadArtifact("missing", dir_ / "m.tiff", false);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(InspectionClientTest, DownloadResultsSkipsStackZipUnlessAsked) {
  {
    std::lock_guard<std::mutex> lock(fake_.mu);
    fake_.artifacts["d"] = "depth-bytes";
    fake_.artifacts["z"] = "zip-bytes";
  }
  v1::Job job;
  job.set_job_id("j");
  job.set_state(v1::JOB_STATE_SUCCEEDED);
  auto* a = job.mutable_result()->add_artifacts();
  a->set_artifact_id("d");
  a->set_kind(v1::ARTIFACT_KIND_DEPTH_TIFF);
  a->set_file_name("../depth.tiff");  // never written outside the folder
  a = job.mutable_result()->add_artifacts();
  a->set_artifact_id("z");
  a->set_kind(v1::ARTIFACT_KIND_STACK_ZIP);
  a->set_file_name("stack.zip");

  InspectionClient client(options_);
  std::vector<fs::path> written;
  ASSERT_TRUE(client.DownloadResults(job, dir_ / "r", false, &written).ok());
  EXPECT_EQ(written, (std::vector<fs::path>{dir_ / "r" / "depth.tiff"}));
  EXPECT_EQ(ReadFile(dir_ / "r" / "depth.tiff"), "depth-bytes");
  EXPECT_FALSE(fs::exists(dir_ / "r" / "stack.zip"));

  written.clear();
  ASSERT_TRUE(client.DownloadResults(job, dir_ / "r2", true, &written).ok());
  EXPECT_EQ(written.size(), 2u);
  EXPECT_EQ(ReadFile(dir_ / "r2" / "stack.zip"), "zip-bytes");

  job.set_state(v1::JOB_STATE_FAILED);
  EXPECT_EQ(client.DownloadResults(job, dir_ / "r3", false, &written).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
}

TEST_F(InspectionClientTest, UnreadableCaFileFailsEveryCallAndUnreachableServerIsUnavailable) {
  ClientOptions tls = options_;
  tls.tls_ca_file = (dir_ / "missing-ca.pem").string();
  InspectionClient bad(tls);
  EXPECT_EQ(bad.WaitConnected().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  v1::RigStatus status;
  EXPECT_EQ(bad.GetRigStatus(&status).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  // The fake shut down: its port refuses connections.
  ClientOptions gone = options_;
  server_->Shutdown();
  gone.connect_timeout_seconds = 0.2;
  InspectionClient client(gone);
  EXPECT_EQ(client.WaitConnected().error_code(), grpc::StatusCode::UNAVAILABLE);
}

}  // namespace
}  // namespace inspection::client
