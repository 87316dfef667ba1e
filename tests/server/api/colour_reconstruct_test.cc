// Colour stacks through the real server: an uploaded colour stack (8-bit PNG, 16-bit
// TIFF) publishes a 3-channel all_in_focus.png whose colours are the in-focus frame's where the
// depth is right; a grey frame in a colour stack is INVALID_ARGUMENT naming it; grey stacks
// still give a 1-channel all_in_focus.png.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "core/io/depth_export.h"
#include "tests/core/colour_stack_synthetic.h"
#include "tests/server/server_fixture.h"

namespace inspection::testing {
namespace {
namespace fs = std::filesystem;

class ColourReconstructTest : public ServerTest {
 protected:
  void SetUp() override {
    ServerTest::SetUp();
    stack_ = UniqueTempDir("colour_stack");
    out_ = UniqueTempDir("colour_out");
    StartServer();
  }
  void TearDown() override {
    fs::remove_all(stack_);
    fs::remove_all(out_);
    ServerTest::TearDown();
  }
  // Uploads stack_, downloads the results into out_.
  void ReconstructAndDownload() {
    v1::Job job;
    grpc::Status s = client_->ReconstructUpload(stack_, v1::ReconstructStart(), nullptr, &job);
    ASSERT_TRUE(s.ok()) << s.error_message();
    ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED);
    std::vector<fs::path> written;
    ASSERT_TRUE(client_->DownloadResults(job, out_, false, &written).ok());
  }
  void ExpectColourAllInFocus(const ColourStackSpec& spec) {
    const cv::Mat aif = cv::imread((out_ / "all_in_focus.png").string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(aif.empty());
    EXPECT_EQ(aif.channels(), 3);
    EXPECT_EQ(aif.depth(), spec.sixteen_bit ? CV_16U : CV_8U);
    auto depth = ReadDepthTiff(out_ / "depth.tiff");
    ASSERT_TRUE(depth.ok());
    const cv::Mat tex = ColourTexture(spec);
    ASSERT_EQ(aif.size(), tex.size());
    // Where the depth is right (within half a z step), the colour is the in-focus frame's.
    const int border = 7;  // focus window: away from the image border and the depth step
    int right_depth = 0, total = 0;
    double abs_diff_sum = 0.0, colourfulness_sum = 0.0;
    for (int y = border; y < tex.rows - border; ++y) {
      for (int x = border; x < tex.cols - border; ++x) {
        if (std::abs(x - tex.cols / 2) < border) continue;
        ++total;
        const float d = depth->at<float>(y, x);
        if (!(std::abs(d - TrueDepthUm(spec, x)) <= 0.5 * spec.z_step_um)) continue;
        ++right_depth;
        cv::Vec3d got, want;
        for (int c = 0; c < 3; ++c) {
          got[c] = spec.sixteen_bit ? aif.at<cv::Vec3w>(y, x)[c] : aif.at<cv::Vec3b>(y, x)[c];
          want[c] = spec.sixteen_bit ? tex.at<cv::Vec3w>(y, x)[c] : tex.at<cv::Vec3b>(y, x)[c];
          abs_diff_sum += std::abs(got[c] - want[c]);
        }
        colourfulness_sum += std::abs(got[2] - got[1]) + std::abs(got[1] - got[0]);
      }
    }
    const double full_scale = spec.sixteen_bit ? 65535.0 : 255.0;
    const double mean_abs_diff = abs_diff_sum / (3.0 * std::max(right_depth, 1)) / full_scale;
    const double colourfulness = colourfulness_sum / (2.0 * std::max(right_depth, 1)) / full_scale;
    std::printf(
        "colour upload (%d-bit): depth right at %d of %d px, mean |colour - in-focus colour| %.5f of full "
        "scale, mean channel spread %.3f of full scale\n",
        spec.sixteen_bit ? 16 : 8, right_depth, total, mean_abs_diff, colourfulness);
    EXPECT_GT(double(right_depth) / total, 0.95);
    EXPECT_LT(mean_abs_diff, 0.005);
    EXPECT_GT(colourfulness, 0.2);  // independent random channels: |R - G| ~ 1/3 of full scale
  }
  fs::path stack_, out_;
};

TEST_F(ColourReconstructTest, EightBitPngColourStackKeepsColourInAllInFocus) {
  ColourStackSpec spec;
  WriteColourStack(stack_, spec);
  ReconstructAndDownload();
  ExpectColourAllInFocus(spec);
}

TEST_F(ColourReconstructTest, SixteenBitTiffColourStackKeepsColourInAllInFocus) {
  ColourStackSpec spec;
  spec.sixteen_bit = true;
  WriteColourStack(stack_, spec);
  ReconstructAndDownload();
  ExpectColourAllInFocus(spec);
}

TEST_F(ColourReconstructTest, GreyFrameInColourStackIsInvalidArgumentNamingTheFrame) {
  ColourStackSpec spec;
  WriteColourStack(stack_, spec, /*grey_frame=*/5);
  v1::Job job;
  grpc::Status s = client_->ReconstructUpload(stack_, v1::ReconstructStart(), nullptr, &job);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("frame 5 (f5.png)"), std::string::npos) << s.error_message();
  EXPECT_NE(s.error_message().find("grey"), std::string::npos) << s.error_message();
}

TEST_F(ColourReconstructTest, GreyStackStillGivesOneChannelAllInFocus) {
  ColourStackSpec spec;
  WriteColourStack(stack_, spec);
  // The same stack as luminance frames.
  auto m = ReadStackManifest(stack_);
  ASSERT_TRUE(m.ok());
  for (size_t i = 0; i < m->frames.size(); ++i) {
    auto grey = LoadStackFrame(stack_, *m, i);
    ASSERT_TRUE(grey.ok());
    cv::imwrite((stack_ / m->frames[i].file).string(), *grey);
  }
  ReconstructAndDownload();
  const cv::Mat aif = cv::imread((out_ / "all_in_focus.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(aif.empty());
  EXPECT_EQ(aif.type(), CV_8UC1);
}

}  // namespace
}  // namespace inspection::testing
