// inspectctl reconstruct --images: plain image folders (natural order, z from flags or a CSV, a
// glob) through the CLI against the real server, compared with the scan of the same specimen.
#include <cmath>
#include <functional>

#include "core/io/depth_export.h"
#include "tests/client_cli/cli_fixture.h"

namespace inspection::testing {
namespace {

// A stored scan's frames renamed f1.png, f2.png, ... f10.png ... (the natural-sort trap: a plain
// sort puts f10 before f2) in a plain folder, with their z; returns the scan's --json result.
json ImageFolderFromScan(const fs::path& data_dir, const fs::path& dir, std::vector<double>* z_um,
                         const std::function<json(const std::string&)>& scan) {
  const json result = scan("scan");
  const std::string scan_id = result["job"]["result"]["scan_id"];
  const fs::path stack = ExtractStoredStack(data_dir, scan_id, dir.parent_path() / (scan_id + ".stack"));
  const json manifest = json::parse(ReadAll(stack / "stack.json"));
  fs::create_directories(dir);
  z_um->clear();
  for (size_t i = 0; i < manifest["frames"].size(); ++i) {
    const json& frame = manifest["frames"][i];
    fs::copy_file(stack / frame["file"].get<std::string>(), dir / ("f" + std::to_string(i + 1) + ".png"));
    z_um->push_back(frame["z_um"].get<double>());
  }
  return result;
}

// The largest |a - b| over pixels valid in both; fails when their NaN masks differ.
double MaxDepthDiffUm(const fs::path& a_file, const fs::path& b_file) {
  auto a = ReadDepthTiff(a_file);
  auto b = ReadDepthTiff(b_file);
  EXPECT_TRUE(a.ok() && b.ok());
  if (!a.ok() || !b.ok() || a->size() != b->size()) return 1e9;
  double max_diff_um = 0.0;
  for (int y = 0; y < a->rows; ++y) {
    for (int x = 0; x < a->cols; ++x) {
      const float va = a->at<float>(y, x), vb = b->at<float>(y, x);
      EXPECT_EQ(std::isnan(va), std::isnan(vb)) << x << "," << y;
      if (!std::isnan(va) && !std::isnan(vb)) max_diff_um = std::max(max_diff_um, std::abs(double(va) - double(vb)));
    }
  }
  return max_diff_um;
}

std::vector<std::string> FileNames(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

TEST_F(CliTest, ImageFolderIsOrderedNaturallyWithRegularZAndReconstructsLikeTheScan) {
  StartServer();
  const fs::path images = work_ / "images";
  std::vector<double> z_um;
  const json scan =
      ImageFolderFromScan(data_dir_, images, &z_um, [this](const std::string& name) { return JsonScan(name); });
  const size_t n = z_um.size();
  ASSERT_GE(n, 11u);  // f10 and f11 exist: a byte-wise sort would break the z order
  const double step_um = z_um[1] - z_um[0];
  for (size_t i = 1; i < n; ++i) ASSERT_NEAR(z_um[i] - z_um[i - 1], step_um, 1e-9);  // a regular scan
  std::ofstream(images / "notes.txt") << "not an image";
  const auto names_before = FileNames(images);

  // The temporary stack goes under TMPDIR; it must be gone afterwards.
  const fs::path tmp = work_ / "tmp";
  fs::create_directories(tmp);
  const char* old_tmp = std::getenv("TMPDIR");
  const std::string saved_tmp = old_tmp ? old_tmp : "";
  setenv("TMPDIR", tmp.c_str(), 1);
  CliResult r = Run({"--json", "reconstruct", "--images", images.string(), "--z-start", std::to_string(z_um[0]),
                     "--z-step", std::to_string(step_um), "--pixel-size", "0.74", "--out", (work_ / "rec").string()});
  if (old_tmp)
    setenv("TMPDIR", saved_tmp.c_str(), 1);
  else
    unsetenv("TMPDIR");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");  // --pixel-size given: no note
  EXPECT_TRUE(fs::is_empty(tmp)) << "temporary stack folder left behind";
  EXPECT_EQ(FileNames(images), names_before);  // the user's folder is untouched
  const json rec = JsonLines(r.out).back();
  EXPECT_EQ(rec["job"]["result"]["depth"]["frame_count"].get<size_t>(), n);
  // Same frames, same z in the same order: the scan's depth map.
  EXPECT_LT(MaxDepthDiffUm(work_ / "scan" / "depth.tiff", work_ / "rec" / "depth.tiff"), 1e-3);

  // The manifest the tool builds: natural order, z = start + i * step, no pixel size (unknown scale).
  const fs::path kept = work_ / "kept";
  r = Run({"reconstruct", "--images", images.string(), "--z-step", "2.5", "--z-start", "-10", "--keep-stack",
           kept.string(), "--out", (work_ / "rec2").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "inspectctl: note: no --pixel-size; lateral outputs are in pixels (unknown scale)\n");
  EXPECT_NE(r.out.find("depth: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(" px (lateral scale unknown), "), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("0.000 um/px"), std::string::npos) << r.out;
  // An imported stack gets dense depth by default, and the output says so and how much is inferred.
  EXPECT_NE(r.out.find("depth: dense (default for an imported stack (stack.json records no rig scan)): "),
            std::string::npos)
      << r.out;
  const json manifest = json::parse(ReadAll(kept / "stack.json"));
  EXPECT_FALSE(manifest.contains("pixel_size_um"));
  ASSERT_EQ(manifest["frames"].size(), n);
  for (size_t i = 0; i < n; ++i) {
    EXPECT_EQ(manifest["frames"][i]["file"], "f" + std::to_string(i + 1) + ".png") << i;
    EXPECT_DOUBLE_EQ(manifest["frames"][i]["z_um"].get<double>(), -10.0 + 2.5 * double(i)) << i;
    EXPECT_EQ(ReadAll(kept / ("f" + std::to_string(i + 1) + ".png")),
              ReadAll(images / ("f" + std::to_string(i + 1) + ".png")));
  }
  EXPECT_FALSE(fs::exists(kept / "notes.txt"));
  // Depth follows the z the tool assigned: the scan's depth mapped through z -> -10 + 2.5 (z - z0) / step.
  auto scan_depth = ReadDepthTiff(work_ / "scan" / "depth.tiff");
  DepthExportMeta rec_meta;
  auto rec_depth = ReadDepthTiff(work_ / "rec2" / "depth.tiff", &rec_meta);
  ASSERT_TRUE(scan_depth.ok() && rec_depth.ok());
  EXPECT_EQ(rec_meta.pixel_size_um, 0.0);  // unknown scale: no resolution tags
  double max_diff_um = 0.0;
  for (int y = 0; y < scan_depth->rows; ++y) {
    for (int x = 0; x < scan_depth->cols; ++x) {
      const float a = scan_depth->at<float>(y, x), b = rec_depth->at<float>(y, x);
      ASSERT_EQ(std::isnan(a), std::isnan(b)) << x << "," << y;
      if (std::isnan(a)) continue;
      const double expected = -10.0 + 2.5 * (double(a) - z_um[0]) / step_um;
      max_diff_um = std::max(max_diff_um, std::abs(double(b) - expected));
    }
  }
  EXPECT_LT(max_diff_um, 1e-3);
}

TEST_F(CliTest, ImageFolderZFromACsvAndImagesFromAGlob) {
  StartServer();
  const fs::path images = work_ / "images";
  std::vector<double> z_um;
  ImageFolderFromScan(data_dir_, images, &z_um, [this](const std::string& name) { return JsonScan(name); });
  const size_t n = z_um.size();
  ASSERT_GE(n, 11u);
  // CSV in reversed line order with a header: z is looked up per file, the order stays natural.
  const fs::path csv = work_ / "z.csv";
  {
    std::ofstream out(csv);
    out << "file,z_um\n";
    for (size_t k = 0; k < n; ++k) {
      const size_t i = n - 1 - k;
      out << "f" << i + 1 << ".png," << z_um[i] << "\n";
    }
  }
  const fs::path kept = work_ / "kept_csv";
  CliResult r = Run({"reconstruct", "--images", images.string(), "--z-csv", csv.string(), "--pixel-size", "0.74",
                     "--keep-stack", kept.string(), "--out", (work_ / "rec").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  json manifest = json::parse(ReadAll(kept / "stack.json"));
  EXPECT_EQ(manifest["pixel_size_um"].get<double>(), 0.74);
  ASSERT_EQ(manifest["frames"].size(), n);
  for (size_t i = 0; i < n; ++i) {
    EXPECT_EQ(manifest["frames"][i]["file"], "f" + std::to_string(i + 1) + ".png");
    EXPECT_NEAR(manifest["frames"][i]["z_um"].get<double>(), z_um[i], 1e-4);
  }
  EXPECT_LT(MaxDepthDiffUm(work_ / "scan" / "depth.tiff", work_ / "rec" / "depth.tiff"), 1e-2);

  // A glob picks f1..f9 only ('f?.png'), in natural order; other files do not count.
  std::ofstream(images / "g1.png") << "not part of the pattern";
  const fs::path kept_glob = work_ / "kept_glob";
  r = Run({"reconstruct", "--images", (images / "f?.png").string(), "--z-step", "1", "--keep-stack", kept_glob.string(),
           "--out", (work_ / "rec_glob").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  manifest = json::parse(ReadAll(kept_glob / "stack.json"));
  ASSERT_EQ(manifest["frames"].size(), 9u);
  for (size_t i = 0; i < 9; ++i) {
    EXPECT_EQ(manifest["frames"][i]["file"], "f" + std::to_string(i + 1) + ".png");
    EXPECT_DOUBLE_EQ(manifest["frames"][i]["z_um"].get<double>(), double(i));
  }
}

TEST_F(CliTest, BadImageFolderInputExits2WithOneLineNamingTheFlagAndNoJob) {
  StartServer();
  const fs::path images = work_ / "images", two = work_ / "two";
  fs::create_directories(images);
  fs::create_directories(two);
  for (const char* name : {"a1.png", "a2.PNG", "a10.tif"}) std::ofstream(images / name) << "x";
  for (const char* name : {"b1.png", "b2.jpg"}) std::ofstream(two / name) << "x";
  const fs::path missing_csv = work_ / "missing.csv", backwards_csv = work_ / "backwards.csv";
  std::ofstream(missing_csv) << "a1.png,0\na2.PNG,1\na3.png,2\na10.tif,3\n";
  std::ofstream(backwards_csv) << "a1.png,0\na2.PNG,2\na10.tif,1\n";  // natural order a1, a2, a10
  const std::string out = (work_ / "never").string();
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--images", two.string(), "--z-step", "1"}, "inspectctl: INVALID_ARGUMENT: --images: 2 image(s) in"},
      {{"--images", (images / "*.jpeg").string(), "--z-step", "1"}, "inspectctl: INVALID_ARGUMENT: --images: "},
      {{"--images", images.string(), "--z-csv", missing_csv.string()},
       "inspectctl: INVALID_ARGUMENT: --z-csv: a3.png is not among the images"},
      {{"--images", images.string(), "--z-csv", backwards_csv.string()},
       "inspectctl: INVALID_ARGUMENT: --z-csv: z is not strictly monotonic"},
      {{"--images", images.string(), "--z-step", "0"}, "inspectctl: INVALID_ARGUMENT: --z-step: must be > 0"},
      {{"--images", images.string(), "--z-step", "-1.5"}, "inspectctl: INVALID_ARGUMENT: --z-step: must be > 0"},
      {{"--images", images.string()}, "inspectctl: INVALID_ARGUMENT: --z-step: required with --images"},
      {{"--images", images.string(), "--z-step", "1", "--pixel-size", "0"},
       "inspectctl: INVALID_ARGUMENT: --pixel-size: must be > 0"}};
  for (const auto& [extra, prefix] : cases) {
    std::vector<std::string> args{"reconstruct", "--out", out};
    args.insert(args.end(), extra.begin(), extra.end());
    CliResult r = Run(args);
    EXPECT_EQ(r.exit_code, 2) << prefix;
    EXPECT_EQ(r.err.rfind(prefix, 0), 0u) << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_EQ(r.out, "");
  }
  // Two sources, or image flags without --images: refused by the parser (its usual two lines:
  // the error naming the flags, then the --help hint).
  const std::string sources = "Exactly 1 option from [--stack,--images,--scan-id] is required and 2 were given\n";
  const std::vector<std::pair<std::vector<std::string>, std::string>> parse_cases = {
      {{"--images", images.string(), "--z-step", "1", "--stack", images.string()}, sources},
      {{"--images", images.string(), "--z-step", "1", "--scan-id", "s"}, sources},
      {{"--scan-id", "s", "--z-step", "1"}, "--z-step requires --images\n"},
      {{"--images", images.string(), "--z-step", "1", "--z-csv", missing_csv.string()}, "--z-step excludes --z-csv\n"}};
  for (const auto& [extra, first_line] : parse_cases) {
    std::vector<std::string> args{"reconstruct", "--out", out};
    args.insert(args.end(), extra.begin(), extra.end());
    CliResult r = Run(args);
    EXPECT_EQ(r.exit_code, 2) << first_line;
    EXPECT_EQ(r.err.rfind(first_line, 0), 0u) << r.err;
    EXPECT_EQ(r.out, "");
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_EQ(FileNames(images), (std::vector<std::string>{"a1.png", "a10.tif", "a2.PNG"}));
  v1::ListJobsResponse jobs;
  ASSERT_TRUE(client_->ListJobs(v1::ListJobsRequest(), &jobs).ok());
  EXPECT_EQ(jobs.jobs_size(), 0);
}

}  // namespace
}  // namespace inspection::testing
