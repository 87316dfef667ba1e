// A stack.json without pixel_size_um through the real server: the reconstruction runs,
// depth stays in the z unit, DepthSummary.pixel_size_um is 0 (unknown scale), the PLY counts
// pixels and says "unknown scale", the x3p has 1-unit increments and says so, the depth TIFF
// carries no resolution; a bad pixel_size_um is INVALID_ARGUMENT naming the field.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>

#include "core/io/depth_export.h"
#include "tests/core/colour_stack_synthetic.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

std::string ReadText(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

class UnknownScaleTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    stack_ = UniqueTempDir("unknown_scale_stack");
    out_ = UniqueTempDir("unknown_scale_out");
    StartServer();
    WriteColourStack(stack_, spec_);
  }
  void TearDown() override {
    fs::remove_all(stack_);
    fs::remove_all(out_);
    ServerTest::TearDown();
  }
  // Rewrites stack.json with pixel_size_um removed (or set to `value` when not null).
  void SetPixelSize(const nlohmann::json& value) {
    nlohmann::json j = nlohmann::json::parse(ReadText(stack_ / "stack.json"));
    if (value.is_null())
      j.erase("pixel_size_um");
    else
      j["pixel_size_um"] = value;
    std::ofstream(stack_ / "stack.json") << j.dump(2);
  }
  ColourStackSpec spec_;
  fs::path stack_, out_;
};

TEST_F(UnknownScaleTest, MissingPixelSizeReconstructsWithUnknownLateralScale) {
  SetPixelSize(nullptr);
  v1::ReconstructStart start;
  start.mutable_options()->add_extra_exports(v1::ARTIFACT_KIND_DEPTH_PLY);
  start.mutable_options()->add_extra_exports(v1::ARTIFACT_KIND_DEPTH_X3P);
  v1::Job job;
  grpc::Status s = client_->ReconstructUpload(stack_, start, nullptr, &job);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(job.result().depth().pixel_size_um(), 0.0);
  EXPECT_EQ(job.result().depth().width(), spec_.size.width);
  std::vector<fs::path> written;
  ASSERT_TRUE(client_->DownloadResults(job, out_, false, &written).ok());

  // Depth in the z unit: each half at its in-focus frame's z.
  DepthExportMeta meta;
  auto depth = ReadDepthTiff(out_ / "depth.tiff", &meta);
  ASSERT_TRUE(depth.ok());
  EXPECT_EQ(meta.pixel_size_um, 0.0);  // no resolution tags
  const int y = spec_.size.height / 2;
  EXPECT_NEAR(depth->at<float>(y, spec_.size.width / 4), TrueDepthUm(spec_, 0), 0.5 * spec_.z_step_um);
  EXPECT_NEAR(depth->at<float>(y, 3 * spec_.size.width / 4), TrueDepthUm(spec_, spec_.size.width - 1),
              0.5 * spec_.z_step_um);

  const std::string ply = ReadText(out_ / "depth.ply");
  const std::string header = ply.substr(0, ply.find("end_header"));
  EXPECT_NE(header.find("comment unknown scale"), std::string::npos) << header;
  EXPECT_EQ(header.find("pixel_size_um 0"), std::string::npos) << header;
  // The x3p's increments and comment: tests/core/io/depth_export_test.cc (here: it was written).
  EXPECT_GT(fs::file_size(out_ / "depth.x3p"), 0u);
}

TEST_F(UnknownScaleTest, BadPixelSizeIsInvalidArgumentNamingTheField) {
  for (const nlohmann::json& bad : {nlohmann::json(0.0), nlohmann::json(-0.5), nlohmann::json("0.74")}) {
    SetPixelSize(bad);
    v1::Job job;
    grpc::Status s = client_->ReconstructUpload(stack_, v1::ReconstructStart(), nullptr, &job);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << bad.dump();
    EXPECT_NE(s.error_message().find("pixel_size_um"), std::string::npos) << s.error_message();
  }
}

}  // namespace
}  // namespace inspection::testing
