// inspectctl reconstruct --images with photographers' formats, end to end against the real
// server: 16-bit TIFF and PNG at full precision (a texture that lives below one 8-bit grey level,
// which the same stack at 8 bits loses), camera RAW (DNG frames developed by LibRaw, colour kept
// in the all-in-focus image), JPEG frames turned by their EXIF orientation, folders mixing
// formats, bit depths or sizes refused naming the file, and an upload cut off half-way leaving
// nothing stored.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "core/io/depth_export.h"
#include "inspection/v1/inspection.grpc.pb.h"
#include "tests/client_cli/cli_fixture.h"
#include "tests/core/io/dng_writer.h"

namespace inspection::testing {
namespace {

// Four vertical bands of constant depth; frames z = 0, 2, ..., 30 um.
constexpr int kWidth = 192, kHeight = 96, kBands = 4, kFrames = 16;
constexpr double kZStepUm = 2.0;
const double kBandDepthUm[kBands] = {6.0, 12.0, 18.0, 24.0};

double TruthAt(int x) { return kBandDepthUm[x * kBands / kWidth]; }

// A fixed random texture in [-1, 1] (CV_32F).
cv::Mat Texture(uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat t(kHeight, kWidth, CV_32F);
  rng.fill(t, cv::RNG::UNIFORM, -1.0, 1.0);
  cv::GaussianBlur(t, t, cv::Size(0, 0), 0.6);
  double lo = 0, hi = 0;
  cv::minMaxLoc(t, &lo, &hi);
  return t / std::max(std::abs(lo), std::abs(hi));
}

// The texture as frame k sees it: each band defocused by its distance from focus (values stay in [-1, 1]).
cv::Mat Defocused(const cv::Mat& texture, int k) {
  cv::Mat out(texture.size(), CV_32F);
  const double z = k * kZStepUm;
  for (int b = 0; b < kBands; ++b) {
    cv::Mat blurred;
    cv::GaussianBlur(texture, blurred, cv::Size(0, 0), 0.4 + 0.5 * std::abs(z - kBandDepthUm[b]));
    const cv::Range cols(b * kWidth / kBands, (b + 1) * kWidth / kBands);
    blurred.colRange(cols).copyTo(out.colRange(cols));
  }
  return out;
}

// 16-bit grey frame: 128 * 257 (the middle of 8-bit grey level 128) +- 115, i.e. +-0.45 of one
// 8-bit level: narrowed to 8 bits every pixel of every frame is exactly 128.
cv::Mat LowContrast16(const cv::Mat& defocused) {
  cv::Mat out;
  defocused.convertTo(out, CV_16U, 115.0, 128.0 * 257.0);
  return out;
}

std::string FrameName(int k, const char* ext) {
  char name[32];
  std::snprintf(name, sizeof name, "f%02d.%s", k + 1, ext);
  return name;
}

// Mean and largest |depth - truth| inside the bands (3 px from band edges and 8 px from the
// border excluded: the focus window straddles two depths there), and the share of finite pixels.
struct DepthError {
  double mean_abs_um = 1e9, max_abs_um = 1e9, finite_fraction = 0.0;
  cv::Size size;
};

DepthError CompareWithTruth(const fs::path& depth_file, bool rotated_cw = false) {
  DepthError e;
  auto depth = ReadDepthTiff(depth_file);
  EXPECT_TRUE(depth.ok()) << depth_file;
  if (!depth.ok()) return e;
  e.size = depth->size();
  double sum = 0, max_abs = 0;
  int n = 0, finite = 0;
  for (int y = 0; y < depth->rows; ++y) {
    for (int x = 0; x < depth->cols; ++x) {
      const float d = depth->at<float>(y, x);
      if (std::isfinite(d)) ++finite;
      const int u = rotated_cw ? y : x, v = rotated_cw ? depth->cols - 1 - x : y;  // original column, row
      const int in_band = u % (kWidth / kBands);
      if (in_band < 3 || in_band >= kWidth / kBands - 3 || u < 8 || u >= kWidth - 8 || v < 8 || v >= kHeight - 8) {
        continue;
      }
      const double err = std::isfinite(d) ? std::abs(double(d) - TruthAt(u)) : 1e9;
      sum += err;
      max_abs = std::max(max_abs, err);
      ++n;
    }
  }
  e.mean_abs_um = n ? sum / n : 1e9;
  e.max_abs_um = max_abs;
  e.finite_fraction = double(finite) / double(depth->total());
  // The figures of the docs (docs/import-stacks.md), printed with the test's output.
  std::printf("%s: mean |error| %.3f um, max %.3f um, finite %.1f %% of %dx%d px\n",
              depth_file.parent_path().filename().c_str(), e.mean_abs_um, e.max_abs_um, 100.0 * e.finite_fraction,
              depth->cols, depth->rows);
  return e;
}

class CliFormatsTest : public CliTest {
 protected:
  json Reconstruct(const fs::path& images, const std::string& out, int expect_exit = 0) {
    CliResult r = Run({"--json", "reconstruct", "--images", images.string(), "--z-step", "2", "--pixel-size", "1",
                       "--out", (work_ / out).string()});
    EXPECT_EQ(r.exit_code, expect_exit) << r.err << r.out;
    last_err_ = r.err;
    auto lines = JsonLines(r.out);
    return lines.empty() ? json::object() : lines.back();
  }
  std::string last_err_;
};

TEST_F(CliFormatsTest, SixteenBitTiffAndPngKeepATextureBelowOneEightBitLevel) {
  StartServer();
  const cv::Mat texture = Texture(35);
  const fs::path tiff = work_ / "tiff16", png = work_ / "png16", png8 = work_ / "png8";
  for (const auto& d : {tiff, png, png8}) fs::create_directories(d);
  for (int k = 0; k < kFrames; ++k) {
    const cv::Mat f16 = LowContrast16(Defocused(texture, k));
    ASSERT_TRUE(cv::imwrite((tiff / FrameName(k, "tif")).string(), f16));
    ASSERT_TRUE(cv::imwrite((png / FrameName(k, "png")).string(), f16));
    cv::Mat f8;
    f16.convertTo(f8, CV_8U, 1.0 / 257.0);
    ASSERT_TRUE(cv::imwrite((png8 / FrameName(k, "png")).string(), f8));
    if (k == 0) {  // what the 8-bit path sees: one grey level, no texture
      double lo = 0, hi = 0;
      cv::minMaxLoc(f8, &lo, &hi);
      ASSERT_EQ(lo, 128.0);
      ASSERT_EQ(hi, 128.0);
    }
  }
  for (const auto& [dir, name] : {std::pair{tiff, "rec_tiff"}, std::pair{png, "rec_png"}}) {
    const json rec = Reconstruct(dir, name);
    ASSERT_FALSE(rec.empty()) << last_err_;
    EXPECT_EQ(rec["job"]["result"]["depth"]["frame_count"].get<int>(), kFrames) << rec.dump();
    const DepthError e = CompareWithTruth(work_ / name / "depth.tiff");
    EXPECT_EQ(e.size, cv::Size(kWidth, kHeight));
    EXPECT_LT(e.mean_abs_um, 0.5) << name;  // a quarter of the z step
    EXPECT_LT(e.max_abs_um, 2.0) << name;
    // The all-in-focus image keeps the 16 bits.
    const cv::Mat aif = cv::imread((work_ / name / "all_in_focus.png").string(), cv::IMREAD_UNCHANGED);
    EXPECT_EQ(aif.type(), CV_16UC1) << name;
  }
  // The same stack narrowed to 8 bits: nothing is left to measure.
  const json rec8 = Reconstruct(png8, "rec_png8");
  const DepthError e8 = CompareWithTruth(work_ / "rec_png8" / "depth.tiff");
  EXPECT_GT(e8.mean_abs_um, 3.0) << rec8.dump();
}

TEST_F(CliFormatsTest, CameraRawFramesAreDevelopedAndTheAllInFocusImageKeepsTheirColour) {
  StartServer();
  const cv::Mat texture = Texture(36);
  const fs::path raw = work_ / "raw";
  fs::create_directories(raw);
  for (int k = 0; k < kFrames; ++k) {
    const cv::Mat t = Defocused(texture, k);
    // A reddish specimen (12-bit raw values): R 2400 +- 600, G 1600 +- 400, B 800 +- 200.
    std::vector<cv::Mat> bgr(3);
    t.convertTo(bgr[0], CV_16U, 200.0, 800.0);
    t.convertTo(bgr[1], CV_16U, 400.0, 1600.0);
    t.convertTo(bgr[2], CV_16U, 600.0, 2400.0);
    cv::Mat colour;
    cv::merge(bgr, colour);
    ASSERT_TRUE(WriteCfaDng((raw / FrameName(k, "dng")).string(), BayerRggbOf(colour)));
  }
  const json rec = Reconstruct(raw, "rec_raw");
  ASSERT_FALSE(rec.empty()) << last_err_;
  const DepthError e = CompareWithTruth(work_ / "rec_raw" / "depth.tiff");
  EXPECT_LT(e.mean_abs_um, 0.5);
  EXPECT_LT(e.max_abs_um, 2.0);
  const cv::Mat aif = cv::imread((work_ / "rec_raw" / "all_in_focus.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(aif.type(), CV_16UC3);
  // Linear development: the channel means keep the raw 2400 : 1600 : 800 (in 16 bits).
  const cv::Scalar mean = cv::mean(aif(cv::Rect(8, 8, kWidth - 16, kHeight - 16)));
  EXPECT_NEAR(mean[2], 2400 * 65535.0 / 4095.0, 0.03 * 65535);
  EXPECT_NEAR(mean[1], 1600 * 65535.0 / 4095.0, 0.03 * 65535);
  EXPECT_NEAR(mean[0], 800 * 65535.0 / 4095.0, 0.03 * 65535);
}

// A JPEG with an EXIF APP1 segment whose one IFD entry is Orientation, inserted after APP0.
std::string JpegWithOrientation(const cv::Mat& image, uint16_t orientation) {
  std::vector<uchar> jpeg;
  EXPECT_TRUE(cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, 97}));
  std::string bytes(jpeg.begin(), jpeg.end());
  const std::string tiff = std::string("II\x2a\x00\x08\x00\x00\x00\x01\x00\x12\x01\x03\x00\x01\x00\x00\x00", 18) +
                           char(orientation & 0xff) + char(orientation >> 8) + std::string(6, '\0');
  const std::string payload = std::string("Exif\0\0", 6) + tiff;
  const size_t length = payload.size() + 2;
  const std::string app1 = std::string("\xff\xe1", 2) + char(length >> 8) + char(length & 0xff) + payload;
  size_t at = 2;
  if (uchar(bytes[2]) == 0xff && uchar(bytes[3]) == 0xe0) at = 4 + (size_t(uchar(bytes[4])) << 8 | uchar(bytes[5]));
  bytes.insert(at, app1);
  return bytes;
}

TEST_F(CliFormatsTest, JpegFramesFollowTheirExifOrientation) {
  StartServer();
  const cv::Mat texture = Texture(37);
  const fs::path jpg = work_ / "jpg";
  fs::create_directories(jpg);
  for (int k = 0; k < kFrames; ++k) {
    cv::Mat grey;
    Defocused(texture, k).convertTo(grey, CV_8U, 90.0, 128.0);
    cv::Mat colour;
    cv::cvtColor(grey, colour, cv::COLOR_GRAY2BGR);
    std::ofstream(jpg / FrameName(k, "jpg"), std::ios::binary) << JpegWithOrientation(colour, 6);
  }
  const json rec = Reconstruct(jpg, "rec_jpg");
  ASSERT_FALSE(rec.empty()) << last_err_;
  // Orientation 6: the camera was turned; the frames are shown 90 degrees clockwise, bands across rows.
  const DepthError e = CompareWithTruth(work_ / "rec_jpg" / "depth.tiff", /*rotated_cw=*/true);
  EXPECT_EQ(e.size, cv::Size(kHeight, kWidth));
  EXPECT_LT(e.mean_abs_um, 0.5);
  EXPECT_LT(e.max_abs_um, 2.0);
}

TEST_F(CliFormatsTest, MixedFormatsBitDepthsOrSizesAreInvalidArgumentNamingTheFileAndNoJob) {
  StartServer();
  const cv::Mat texture = Texture(38);
  auto folder = [&](const std::string& name, const std::function<void(const fs::path&, int)>& odd_one) {
    const fs::path dir = work_ / name;
    fs::create_directories(dir);
    for (int k = 0; k < 5; ++k) {
      if (k == 2) {
        odd_one(dir, k);
      } else {
        EXPECT_TRUE(cv::imwrite((dir / FrameName(k, "png")).string(), LowContrast16(Defocused(texture, k))));
      }
    }
    return dir;
  };
  const fs::path depth = folder("depth", [&](const fs::path& dir, int k) {
    cv::Mat f8;
    LowContrast16(Defocused(texture, k)).convertTo(f8, CV_8U, 1.0 / 257.0);
    EXPECT_TRUE(cv::imwrite((dir / FrameName(k, "png")).string(), f8));
  });
  const fs::path size = folder("size", [&](const fs::path& dir, int k) {
    EXPECT_TRUE(
        cv::imwrite((dir / FrameName(k, "png")).string(), LowContrast16(Defocused(texture, k)).colRange(0, 190)));
  });
  const fs::path format = folder("format", [&](const fs::path& dir, int k) {
    EXPECT_TRUE(cv::imwrite((dir / FrameName(k, "tif")).string(), LowContrast16(Defocused(texture, k))));
  });
  Reconstruct(depth, "never", 4);
  EXPECT_EQ(last_err_, "inspectctl: INVALID_ARGUMENT: frame 2 (f03.png): bit depth 8 differs from frame 0 (16)\n");
  Reconstruct(size, "never", 4);
  EXPECT_EQ(last_err_, "inspectctl: INVALID_ARGUMENT: frame 2 (f03.png): size 190x96 differs from frame 0 (192x96)\n");
  // A mixed folder is refused before the upload, naming the file.
  Reconstruct(format, "never", 2);
  EXPECT_EQ(last_err_,
            "inspectctl: INVALID_ARGUMENT: --images: f03.tif is TIFF but f01.png is PNG; the frames of a stack share "
            "one format\n");
  // A stack folder that mixes them is refused by the server, naming the file.
  std::ofstream(format / "stack.json") << R"({"frames": [{"file": "f01.png", "z_um": 0}, {"file": "f02.png", "z_um": 2},
      {"file": "f03.tif", "z_um": 4}, {"file": "f04.png", "z_um": 6}, {"file": "f05.png", "z_um": 8}]})";
  CliResult r = Run({"reconstruct", "--stack", format.string(), "--out", (work_ / "never").string()});
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_EQ(r.err,
            "inspectctl: INVALID_ARGUMENT: stack.json: frames[2].file 'f03.tif' is TIFF but frames[0].file 'f01.png' "
            "is PNG; the frames of a stack share one format\n");
  EXPECT_FALSE(fs::exists(work_ / "never"));
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 0);
  EXPECT_TRUE(fs::is_empty(data_dir_ / "uploads"));
}

// The files of the server's data directory that hold uploads, stored stacks or results. The
// server may be removing an upload folder meanwhile (the previous upload's, failed): an entry that
// is gone by the time it is looked at is not stored, so the walk skips it instead of throwing.
std::vector<std::string> StoredStackFiles(const fs::path& data_dir) {
  std::error_code ec;
  for (int attempt = 0; attempt < 1000; ++attempt) {
    std::vector<std::string> files;
    ec.clear();
    for (auto it = fs::recursive_directory_iterator(data_dir, fs::directory_options::skip_permission_denied, ec);
         !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
      std::error_code entry_ec;
      if (!it->is_regular_file(entry_ec) || entry_ec) continue;
      // Lexically: fs::relative resolves the path on disk, which fails once the file is gone.
      const std::string rel = it->path().lexically_relative(data_dir).string();
      for (const char* folder : {"uploads/", "scans/", "tmp/", "artifacts/"}) {
        if (rel.rfind(folder, 0) == 0) files.push_back(rel);
      }
    }
    // A folder removed under the walk ends it early: walk again rather than report a part.
    if (!ec) return files;
  }
  ADD_FAILURE() << "cannot list " << data_dir << ": " << ec.message();
  return {};
}

TEST_F(CliFormatsTest, AnUploadCutOffHalfWayLeavesNothingStored) {
  StartServer();
  const cv::Mat texture = Texture(39);
  std::vector<std::string> frames;
  for (int k = 0; k < 5; ++k) {
    std::vector<uchar> png;
    ASSERT_TRUE(cv::imencode(".png", LowContrast16(Defocused(texture, k)), png));
    frames.emplace_back(png.begin(), png.end());
  }
  const std::string manifest = R"({"frames": [{"file": "f01.png", "z_um": 0}, {"file": "f02.png", "z_um": 2},
      {"file": "f03.png", "z_um": 4}, {"file": "f04.png", "z_um": 6}, {"file": "f05.png", "z_um": 8}]})";
  int64_t total = int64_t(manifest.size());
  for (const auto& f : frames) total += int64_t(f.size());

  auto channel = grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials());
  auto stub = v1::InspectionService::NewStub(channel);
  // Two ways an upload stops half-way: the client ends its stream (WritesDone) in the middle of a
  // frame, or it goes away (the call is cancelled, as when inspectctl is killed).
  for (const bool cancel : {false, true}) {
    grpc::ClientContext ctx;
    auto stream = stub->Reconstruct(&ctx);
    v1::ReconstructRequest msg;
    msg.mutable_start()->mutable_upload()->set_file_count(6);
    msg.mutable_start()->mutable_upload()->set_total_bytes(total);
    ASSERT_TRUE(stream->Write(msg));
    auto send = [&](const std::string& path, const std::string& data, int64_t offset, bool last) {
      v1::ReconstructRequest chunk;
      chunk.mutable_file_chunk()->set_path(path);
      chunk.mutable_file_chunk()->set_offset(offset);
      chunk.mutable_file_chunk()->set_data(data);
      chunk.mutable_file_chunk()->set_last(last);
      return stream->Write(chunk);
    };
    ASSERT_TRUE(send("stack.json", manifest, 0, true));
    ASSERT_TRUE(send("f01.png", frames[0], 0, true));
    ASSERT_TRUE(send("f02.png", frames[1], 0, true));
    ASSERT_TRUE(send("f03.png", frames[2].substr(0, frames[2].size() / 2), 0, false));
    if (cancel) {
      // The server has what was sent when the upload folder holds f03.png's first half.
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
      auto has_half = [&] {
        for (const auto& f : StoredStackFiles(data_dir_)) {
          if (f.size() > 8 && f.compare(f.size() - 8, 8, "/f03.png") == 0 &&
              [&] {
                std::error_code size_ec;
                return fs::file_size(data_dir_ / f, size_ec) == frames[2].size() / 2 && !size_ec;
              }()) {
            return true;
          }
        }
        return false;
      };
      while (!has_half() && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(5));  // polling, with a deadline
      ASSERT_TRUE(has_half());
      ctx.TryCancel();
    } else {
      stream->WritesDone();
    }
    v1::JobEvent event;
    while (stream->Read(&event)) {
    }
    const grpc::Status status = stream->Finish();
    if (cancel) {
      EXPECT_EQ(status.error_code(), grpc::StatusCode::CANCELLED) << status.error_message();
    } else {
      EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
      EXPECT_EQ(status.error_message(), "file 'f03.png' ended without a chunk marked last");
    }
    // Nothing half-stored: the upload folder goes with the call (polled: the handler may still be
    // unwinding when the client sees the cancellation).
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (!StoredStackFiles(data_dir_).empty() && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));  // polling, with a deadline
    }
    EXPECT_EQ(StoredStackFiles(data_dir_), std::vector<std::string>{}) << (cancel ? "cancelled" : "ended");
  }
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 0);
}

}  // namespace
}  // namespace inspection::testing
