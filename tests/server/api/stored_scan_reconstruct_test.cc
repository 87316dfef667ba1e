// Reconstructing a stored scan (ReconstructStart.scan_id; server/storage/stored_stack.h): the
// frames are read from the scan's stack.zip into memory and decoded there. The results are bit
// for bit those of the stack extracted to disk (the sequential path reads it as every
// reconstruction did before) for SFF and ISFF; no frame file is written under uploads/, also when
// a dropped frame is decoded again; a corrupt frame gives the error the extraction gave; the
// free-space reserve refuses up front; nothing is left on disk either way.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <set>

#include "core/io/stack.h"
#include "core/io/stack_frame_decoder.h"
#include "server/storage/data_store.h"
#include "server/storage/stored_stack.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

// Every regular file below `dir`, relative to it.
std::set<std::string> FilesUnder(const fs::path& dir) {
  std::set<std::string> out;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_regular_file()) out.insert(fs::relative(it->path(), dir).generic_string());
  }
  return out;
}

bool SamePixels(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && a.isContinuous() && b.isContinuous() &&
         std::memcmp(a.data, b.data, a.total() * a.elemSize()) == 0;
}

std::string ReadFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

class StoredScanReconstructTest : public ServerTest {
 protected:
  // The integral SFF tests' rig: small, and the projector lights the field.
  SimulatedRigOptions SimOptions() override { return IsffRig(); }

  // The file of frame `index` in an extracted stack folder.
  static std::string FrameFile(const fs::path& folder, int index) {
    auto m = ReadStackManifest(folder);
    EXPECT_TRUE(m.ok()) << m.status().ToString();
    return m.ok() && index < int(m->frames.size()) ? m->frames[size_t(index)].file : std::string();
  }

  // Reconstructs the stored scan on the parallel path, then on the sequential one: each is refused
  // with `code`, creates no job and leaves nothing under uploads/. Returns both messages.
  std::vector<std::string> RefusedOnBothPaths(const std::string& scan_id, grpc::StatusCode code) {
    const int jobs = JobCount();
    std::vector<std::string> messages;
    for (bool sequential : {false, true}) {
      Restart(sequential);
      v1::Job job;
      const grpc::Status s = Reconstruct(scan_id, v1::RECONSTRUCTION_METHOD_SFF, &job);
      EXPECT_EQ(s.error_code(), code) << s.error_message();
      messages.push_back(s.error_message());
      EXPECT_EQ(FilesUnder(data_dir_ / "uploads"), std::set<std::string>{});
      EXPECT_EQ(JobCount(), jobs);
    }
    return messages;
  }

  // A scan; for ISFF (uniform illumination, as the integral methods need) calibrated first.
  std::string ScanStack(bool for_isff) {
    v1::ScanRequest req;
    if (for_isff) {
      v1::CalibrateRequest cal_req;
      cal_req.add_steps(v1::CALIBRATION_STEP_INTEGRAL_PSF);
      v1::Job cal;
      EXPECT_TRUE(client_->Calibrate(cal_req, nullptr, &cal).ok());
      EXPECT_EQ(cal.state(), v1::JOB_STATE_SUCCEEDED) << cal.error_message();
      req.mutable_reconstruction()->set_method(v1::RECONSTRUCTION_METHOD_ISFF);
    }
    v1::Job scan;
    EXPECT_TRUE(client_->Scan(req, nullptr, &scan).ok());
    EXPECT_EQ(scan.state(), v1::JOB_STATE_SUCCEEDED) << scan.error_message();
    return scan.job_id();
  }

  // The server restarted with the parallel pipeline (frames from the archive, in memory) or the
  // sequential one (the stack extracted and read from disk).
  void Restart(bool sequential) {
    StopServer();
    pipeline_.sequential = sequential;
    StartServer();
  }

  grpc::Status Reconstruct(const std::string& scan_id, v1::ReconstructionMethod method, v1::Job* job) {
    v1::ReconstructStart start;
    start.set_scan_id(scan_id);
    start.mutable_options()->set_method(method);
    return client_->ReconstructStored(start, nullptr, job);
  }

  // depth, confidence and all-in-focus as downloaded.
  std::vector<cv::Mat> Results(const v1::Job& job) {
    const fs::path out = UniqueTempDir("results_" + job.job_id());
    std::vector<fs::path> written;
    EXPECT_TRUE(client_->DownloadResults(job, out, false, &written).ok());
    std::vector<cv::Mat> images;
    for (const char* f : {"depth.tiff", "confidence.tiff", "all_in_focus.png"}) {
      images.push_back(cv::imread((out / f).string(), cv::IMREAD_UNCHANGED));
      EXPECT_FALSE(images.back().empty()) << f;
    }
    fs::remove_all(out);
    return images;
  }

  fs::path StackZip(const std::string& scan_id) { return data_dir_ / "artifacts" / scan_id / "stack.zip"; }

  int JobCount() {
    v1::ListJobsResponse jobs;
    EXPECT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
    return jobs.jobs_size();
  }
};

TEST_F(StoredScanReconstructTest, SffAndIsffFromTheArchiveMatchTheExtractedStackBitForBit) {
  StartServer();
  const std::string scan_id = ScanStack(true);
  for (v1::ReconstructionMethod method : {v1::RECONSTRUCTION_METHOD_SFF, v1::RECONSTRUCTION_METHOD_ISFF}) {
    std::vector<std::vector<cv::Mat>> results;
    for (bool sequential : {false, true}) {
      Restart(sequential);
      v1::Job job;
      const grpc::Status s = Reconstruct(scan_id, method, &job);
      ASSERT_TRUE(s.ok()) << s.error_message();
      ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
      EXPECT_EQ(job.result().depth().method(), method);
      EXPECT_TRUE(job.result().depth().has_ground_truth());  // read from the job's small folder
      EXPECT_GT(job.result().depth().valid_percent(), 50.0);
      results.push_back(Results(job));
      EXPECT_EQ(FilesUnder(data_dir_ / "uploads"), std::set<std::string>{});  // went with the job
    }
    for (size_t k = 0; k < 3; ++k) EXPECT_TRUE(SamePixels(results[0][k], results[1][k])) << method << " image " << k;
  }
}

// What a reconstruction job holds while it runs: the open archive and a folder with stack.json
// and the ground truth only. Every frame decodes from the archive to the pixels of its extracted
// file, also when the decoder drops it (a budget of 0 bytes) and the consumer decodes it again.
TEST_F(StoredScanReconstructTest, AnOpenStoredStackHoldsNoFrameFilesAndDecodesFromTheArchive) {
  StartServer();
  const std::string scan_id = ScanStack(false);
  StopServer();
  const fs::path extracted = ExtractStoredStack(data_dir_, scan_id, UniqueTempDir("extracted"));
  auto store = DataStore::Open(data_dir_);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  {
    auto stored = OpenStoredStack(**store, scan_id);
    ASSERT_TRUE(stored.ok()) << stored.status().ToString();
    ASSERT_TRUE(stored->decode);
    const StackManifest& m = stored->manifest;
    ASSERT_GE(m.frames.size(), 3u);
    const std::set<std::string> small_files{kStackManifestName, kGroundTruthDepthName};
    EXPECT_EQ(FilesUnder(stored->dir), small_files);
    EXPECT_EQ(FilesUnder((*store)->uploads_dir()).size(), 2u);  // nothing else under uploads/

    StackFrameDecoderOptions o;
    o.threads = 3;
    o.max_kept_bytes = 0;  // every frame checked and dropped: Frame decodes it again
    StackFrameDecoder decoder(stored->dir, m, o, stored->decode);
    ASSERT_TRUE(decoder.Finish().ok());
    EXPECT_EQ(decoder.peak_kept_bytes(), 0);
    // The re-decodes below read the archive the stack holds open, not a path.
    ASSERT_TRUE(fs::remove(StackZip(scan_id)));
    for (size_t i = 0; i < m.frames.size(); ++i) {
      auto from_archive = decoder.Frame(int(i));
      ASSERT_TRUE(from_archive.ok()) << from_archive.status().ToString();
      auto from_file = DecodeStackFrame(extracted, m, i);
      ASSERT_TRUE(from_file.ok());
      EXPECT_TRUE(SamePixels(*from_archive, *from_file)) << "frame " << i;
    }
    EXPECT_EQ(decoder.decoded_frames(), 2 * int(m.frames.size()));
    EXPECT_EQ(FilesUnder(stored->dir), small_files);
  }
  EXPECT_EQ(FilesUnder((*store)->uploads_dir()), std::set<std::string>{});
  fs::remove_all(extracted);
}

// A frame entry whose bytes no longer match the archive's CRC: DATA_LOSS naming the scan and the
// entry, the very message the extraction gave; no job, nothing left.
TEST_F(StoredScanReconstructTest, ACorruptFrameEntryIsDataLossNamingItAsBefore) {
  StartServer();
  const std::string scan_id = ScanStack(false);
  const fs::path extracted = ExtractStoredStack(data_dir_, scan_id, UniqueTempDir("extracted"));
  const std::string file = FrameFile(extracted, 3);
  // Stored uncompressed: the frame's bytes are in the archive as they are in the file.
  std::string zip = ReadFile(StackZip(scan_id));
  const std::string frame = ReadFile(extracted / file);
  const size_t at = zip.find(frame);
  ASSERT_NE(at, std::string::npos);
  zip[at + frame.size() / 2] ^= 0x5a;
  std::ofstream(StackZip(scan_id), std::ios::binary | std::ios::trunc) << zip;
  fs::remove_all(extracted);

  const std::vector<std::string> messages = RefusedOnBothPaths(scan_id, grpc::StatusCode::DATA_LOSS);
  EXPECT_EQ(messages[0], "scan " + scan_id + ": stored stack: entry '" + file + "' is corrupt");
  EXPECT_EQ(messages[0], messages[1]);
}

// An archive entry that is intact but not an image: INVALID_ARGUMENT naming the frame, as the
// decode from its extracted file says it.
TEST_F(StoredScanReconstructTest, AFrameThatIsNoImageIsInvalidArgumentNamingItAsBefore) {
  StartServer();
  const std::string scan_id = ScanStack(false);
  const fs::path extracted = ExtractStoredStack(data_dir_, scan_id, UniqueTempDir("extracted"));
  const std::string file = FrameFile(extracted, 3);
  std::ofstream(extracted / file, std::ios::binary | std::ios::trunc) << "not an image";
  ASSERT_TRUE(ZipFolder(extracted, StackZip(scan_id)).ok());
  fs::remove_all(extracted);

  const std::vector<std::string> messages = RefusedOnBothPaths(scan_id, grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(messages[0], "frame 3 (" + file + "): cannot decode image (expected PNG, TIFF or JPEG)");
  EXPECT_EQ(messages[0], messages[1]);
}

// Below the free-space reserve a stored scan is not opened at all: RESOURCE_EXHAUSTED up front.
TEST_F(StoredScanReconstructTest, BelowTheFreeSpaceReserveNothingIsOpened) {
  StartServer();
  const std::string scan_id = ScanStack(false);
  StopServer();
  ServerOptions opt;
  opt.listen_address = "127.0.0.1:0";
  opt.data_dir = data_dir_;
  opt.simulation = SimOptions();
  opt.min_free_mb = int64_t(1) << 40;  // more than any disk
  auto server = InspectionServer::Start(opt);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  server_ = std::move(*server);
  client_ = NewClient();
  const int jobs = JobCount();
  v1::Job job;
  const grpc::Status s = Reconstruct(scan_id, v1::RECONSTRUCTION_METHOD_SFF, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_NE(s.error_message().find("below the reserve"), std::string::npos) << s.error_message();
  EXPECT_EQ(FilesUnder(data_dir_ / "uploads"), std::set<std::string>{});
  EXPECT_EQ(JobCount(), jobs);
}

}  // namespace
}  // namespace inspection::testing
