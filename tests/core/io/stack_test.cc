// Stack folder format: manifest parsing and frame validation name the field or frame at fault.
#include "core/io/stack.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>

#include "core/io/colour.h"
#include "core/sff/sff_engine.h"
#include "core/sff/stack_reconstruct.h"
#include "tests/core/sff_synthetic.h"

namespace inspection {
namespace {
namespace fs = std::filesystem;

class StackTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("stack_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  StackManifest WriteFrames(int n, cv::Size size = {32, 24}) {
    StackManifest m;
    m.pixel_size_um = 0.74;
    for (int i = 0; i < n; ++i) {
      const std::string name = "frame_" + std::to_string(i) + ".png";
      cv::imwrite((dir_ / name).string(), cv::Mat(size, CV_8UC1, cv::Scalar(10 * i)));
      m.frames.push_back({name, 5.0 * i, 1000.0, "uniform:128"});
    }
    EXPECT_TRUE(WriteStackManifest(dir_, m).ok());
    return m;
  }

  fs::path dir_;
};

TEST_F(StackTest, RoundTripsManifest) {
  WriteFrames(4);
  auto m = ReadStackManifest(dir_);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_DOUBLE_EQ(m->pixel_size_um, 0.74);
  ASSERT_EQ(m->frames.size(), 4u);
  EXPECT_DOUBLE_EQ(m->frames[3].z_um, 15.0);
  EXPECT_EQ(m->frames[2].pattern, "uniform:128");
  EXPECT_TRUE(ValidateStackFrames(dir_, *m).ok());
  auto f = LoadStackFrame(dir_, *m, 2);
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f->at<uint8_t>(0, 0), 20);
}

TEST_F(StackTest, MissingManifestIsInvalidArgument) {
  auto m = ReadStackManifest(dir_);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(m.status().message().find("stack.json is missing"), std::string::npos);
}

TEST_F(StackTest, NonMonotonicZNamesTheFrame) {
  auto m = ParseStackManifest(R"({"pixel_size_um":1,"frames":[
      {"file":"a.png","z_um":0},{"file":"b.png","z_um":5},{"file":"c.png","z_um":3}]})");
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(m.status().message().find("frames[2].z_um"), std::string::npos) << m.status().message();
}

TEST_F(StackTest, DuplicateZNamesTheFrame) {
  auto m = ParseStackManifest(R"({"pixel_size_um":1,"frames":[
      {"file":"a.png","z_um":0},{"file":"b.png","z_um":0},{"file":"c.png","z_um":3}]})");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("frames[1].z_um"), std::string::npos) << m.status().message();
}

TEST_F(StackTest, RejectsPathEscapingTheFolder) {
  auto m = ParseStackManifest(R"({"pixel_size_um":1,"frames":[
      {"file":"../a.png","z_um":0},{"file":"b.png","z_um":1},{"file":"c.png","z_um":3}]})");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("frames[0].file"), std::string::npos);
}

TEST_F(StackTest, MissingPixelSizeIsUnknownScaleAndBadOneNamesTheField) {
  const std::string frames =
      R"("frames":[{"file":"a.png","z_um":0},{"file":"b.png","z_um":1},{"file":"c.png","z_um":2}])";
  auto m = ParseStackManifest("{" + frames + "}");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->pixel_size_um, 0.0);  // unknown
  for (const std::string bad : {R"("pixel_size_um":0,)", R"("pixel_size_um":-1,)", R"("pixel_size_um":"x",)"}) {
    auto b = ParseStackManifest("{" + bad + frames + "}");
    ASSERT_FALSE(b.ok()) << bad;
    EXPECT_NE(b.status().message().find("pixel_size_um"), std::string::npos) << b.status().ToString();
  }
  // Written back without the field, read back as unknown again.
  StackManifest w = *m;
  ASSERT_TRUE(WriteStackManifest(dir_, w).ok());
  std::ifstream in(dir_ / "stack.json");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text.find("pixel_size_um"), std::string::npos) << text;
  auto back = ParseStackManifest(text);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->pixel_size_um, 0.0);
}

// stack.json "alignment": written with every figure and transform, read back bit for bit
// (JSON numbers round-trip doubles); a manifest without it reads as before (no record).
TEST_F(StackTest, AlignmentRecordRoundTrips) {
  StackManifest m = WriteFrames(3);
  auto plain = ReadStackManifest(dir_);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_FALSE(plain->alignment.has_value());

  StackAlignmentRecord r;
  r.alignment = "estimate";
  r.method = "chain";
  r.still = false;
  r.reference_frame = 1;
  r.max_scale_change_percent = 1.2345678901234;
  r.max_shift_px = 3.25;
  r.seen_by_every_frame_percent = 97.5;
  r.max_corner_displacement_px = 4.0625;
  r.fallback_reason = "";
  for (int i = 0; i < 3; ++i) {
    StackFrameTransform t;
    t.frame = i;
    t.scale = 1.0 + 0.01 * (i - 1) + 1e-9;
    t.rotation_deg = -0.1 * i;
    t.shift_x_px = 2.5 * (i - 1);
    t.shift_y_px = -1.0 / 3.0 * i;
    t.affine = {t.scale, 1e-4 * i, t.shift_x_px, -1e-4 * i, t.scale, t.shift_y_px};
    r.frames.push_back(t);
  }
  m.alignment = r;
  ASSERT_TRUE(WriteStackManifest(dir_, m).ok());
  auto back = ReadStackManifest(dir_);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_TRUE(back->alignment.has_value());
  const StackAlignmentRecord& b = *back->alignment;
  EXPECT_EQ(b.alignment, "estimate");
  EXPECT_EQ(b.method, "chain");
  EXPECT_FALSE(b.still);
  EXPECT_EQ(b.reference_frame, 1);
  EXPECT_EQ(b.max_scale_change_percent, r.max_scale_change_percent);
  EXPECT_EQ(b.max_shift_px, 3.25);
  EXPECT_EQ(b.seen_by_every_frame_percent, 97.5);
  EXPECT_EQ(b.max_corner_displacement_px, 4.0625);
  EXPECT_TRUE(b.fallback_reason.empty());
  ASSERT_EQ(b.frames.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(b.frames[i].frame, int(i));
    EXPECT_EQ(b.frames[i].scale, r.frames[i].scale);
    EXPECT_EQ(b.frames[i].rotation_deg, r.frames[i].rotation_deg);
    EXPECT_EQ(b.frames[i].shift_x_px, r.frames[i].shift_x_px);
    EXPECT_EQ(b.frames[i].shift_y_px, r.frames[i].shift_y_px);
    EXPECT_EQ(b.frames[i].affine, r.frames[i].affine);
  }

  // A still stack: the transforms stay recorded (what was measured), still says they were not applied.
  r.still = true;
  r.alignment = "none";
  r.method = "";
  r.frames.clear();
  r.fallback_reason = "no frame pair could be registered";
  m.alignment = r;
  ASSERT_TRUE(WriteStackManifest(dir_, m).ok());
  back = ReadStackManifest(dir_);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->alignment->alignment, "none");
  EXPECT_TRUE(back->alignment->still);
  EXPECT_EQ(back->alignment->fallback_reason, "no frame pair could be registered");
  EXPECT_TRUE(back->alignment->frames.empty());
}

TEST_F(StackTest, BadAlignmentRecordNamesTheField) {
  const std::string frames =
      R"("frames":[{"file":"a.png","z_um":0},{"file":"b.png","z_um":1},{"file":"c.png","z_um":2}])";
  const std::string t0 = R"({"frame":0,"scale":1,"rotation_deg":0,"shift_x_px":0,"shift_y_px":0,"affine":[1,0,0,0,1,0]})";
  const std::string t1 = R"({"frame":1,"scale":1,"rotation_deg":0,"shift_x_px":0,"shift_y_px":0,"affine":[1,0,0,0,1,0]})";
  const std::string t2 = R"({"frame":2,"scale":1,"rotation_deg":0,"shift_x_px":0,"shift_y_px":0,"affine":[1,0,0,0,1,0]})";
  auto ok = ParseStackManifest("{" + frames + R"(,"alignment":{"alignment":"calibrated","method":"model","frames":[)" +
                               t0 + "," + t1 + "," + t2 + "]}}");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->alignment->frames.size(), 3u);
  const std::pair<std::string, std::string> cases[] = {
      {R"("alignment":[])", "alignment must be an object"},
      {R"("alignment":{})", "alignment.alignment is missing"},
      {R"("alignment":{"alignment":"warp"})", "alignment.alignment 'warp'"},
      {R"("alignment":{"alignment":"none","method":"affine"})", "alignment.method 'affine'"},
      {R"("alignment":{"alignment":"none","still":1})", "alignment.still"},
      {R"("alignment":{"alignment":"none","reference_frame":3})", "alignment.reference_frame 3"},
      {R"("alignment":{"alignment":"none","max_shift_px":-1})", "alignment.max_shift_px must be >= 0"},
      {R"("alignment":{"alignment":"estimate","frames":[)" + t0 + "," + t1 + "]}", "alignment.frames has 2 transforms for 3 frames"},
      {R"("alignment":{"alignment":"estimate","frames":[)" + t0 + "," + t2 + "," + t1 + "]}",
       "alignment.frames[1].frame must be 1"},
      {R"("alignment":{"alignment":"estimate","frames":[)" + t0 + "," + t1 + R"(,{"frame":2,"scale":0})" + "]}",
       "alignment.frames[2].scale must be > 0"},
      {R"("alignment":{"alignment":"estimate","frames":[)" + t0 + "," + t1 +
           R"(,{"frame":2,"scale":1,"rotation_deg":0,"shift_x_px":0,"shift_y_px":0,"affine":[1,0,0,0,1]})" + "]}",
       "alignment.frames[2].affine must be an array of 6"},
      {R"("alignment":{"alignment":"estimate","frames":[)" + t0 + "," + t1 +
           R"(,{"frame":2,"scale":1,"rotation_deg":0,"shift_x_px":0,"shift_y_px":0,"affine":[1,0,0,0,1,"x"]})" + "]}",
       "alignment.frames[2].affine[5]"},
  };
  for (const auto& [json, expected] : cases) {
    auto m = ParseStackManifest("{" + frames + "," + json + "}");
    ASSERT_FALSE(m.ok()) << json;
    EXPECT_EQ(m.status().code(), StatusCode::kInvalidArgument) << json;
    EXPECT_NE(m.status().message().find("stack.json: " + expected), std::string::npos)
        << json << " -> " << m.status().ToString();
  }
}

TEST_F(StackTest, FewerThanThreeFramesIsRejected) {
  auto m = ParseStackManifest(R"({"pixel_size_um":1,"frames":[{"file":"a.png","z_um":0},{"file":"b.png","z_um":1}]})");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("at least 3"), std::string::npos);
}

TEST_F(StackTest, FramesOfDifferentSizesNameTheFrame) {
  StackManifest m = WriteFrames(4);
  cv::imwrite((dir_ / m.frames[2].file).string(), cv::Mat(cv::Size(16, 16), CV_8UC1, cv::Scalar(1)));
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("frame 2 (frame_2.png): size 16x16 differs from frame 0 (32x24)"), std::string::npos)
      << s.message();
}

TEST_F(StackTest, MixedBitDepthNamesTheFrame) {
  StackManifest m = WriteFrames(3);
  cv::imwrite((dir_ / m.frames[1].file).string(), cv::Mat(cv::Size(32, 24), CV_16UC1, cv::Scalar(1000)));
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame 1 (frame_1.png): bit depth 16"), std::string::npos) << s.message();
}

TEST_F(StackTest, UnreadableFrameNamesTheFrame) {
  StackManifest m = WriteFrames(3);
  std::ofstream(dir_ / m.frames[1].file) << "not an image";
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame 1 (frame_1.png): cannot decode"), std::string::npos) << s.message();
}

// Colour frames: 8-bit PNG, 16-bit TIFF and JPEG are read; focus is measured on the luminance
// and the colour stays available.
TEST_F(StackTest, ColourFramesGiveLuminanceAndKeepColour) {
  StackManifest m;
  m.pixel_size_um = 1.0;
  const cv::Vec3b bgr8(30, 200, 90);         // Y = 0.2126 * 90 + 0.7152 * 200 + 0.0722 * 30 = 164.4
  const cv::Vec3w bgr16(3000, 50000, 9000);  // Y = 0.2126 * 9000 + 0.7152 * 50000 + 0.0722 * 3000 = 37890.0
  cv::imwrite((dir_ / "a.png").string(), cv::Mat(8, 6, CV_8UC3, cv::Scalar(bgr8)));
  cv::imwrite((dir_ / "b.tiff").string(), cv::Mat(8, 6, CV_16UC3, cv::Scalar(bgr16)));
  cv::imwrite((dir_ / "c.jpg").string(), cv::Mat(8, 6, CV_8UC3, cv::Scalar(bgr8)));
  m.frames = {{"a.png", 0.0, 0.0, ""}, {"b.tiff", 1.0, 0.0, ""}, {"c.jpg", 2.0, 0.0, ""}};

  auto a = LoadStackFrameImage(dir_, m, 0);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(a->is_colour());
  EXPECT_EQ(a->colour.type(), CV_8UC3);
  EXPECT_EQ(a->colour.at<cv::Vec3b>(3, 2), bgr8);
  EXPECT_EQ(a->grey.type(), CV_8UC1);
  EXPECT_EQ(a->grey.at<uint8_t>(3, 2), 164);
  auto a_grey = LoadStackFrame(dir_, m, 0);
  ASSERT_TRUE(a_grey.ok());
  EXPECT_EQ(a_grey->at<uint8_t>(3, 2), 164);

  auto b = LoadStackFrameImage(dir_, m, 1);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  EXPECT_EQ(b->colour.type(), CV_16UC3);
  EXPECT_EQ(b->colour.at<cv::Vec3w>(0, 0), bgr16);
  EXPECT_EQ(b->grey.type(), CV_16UC1);
  EXPECT_EQ(b->grey.at<uint16_t>(0, 0), 37890);

  // JPEG is lossy, but a flat colour survives within a few code values.
  auto c = LoadStackFrameImage(dir_, m, 2);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(c->colour.type(), CV_8UC3);
  EXPECT_NEAR(c->grey.at<uint8_t>(4, 3), 164, 3);

  // Grey frames: exactly as stored, no colour.
  StackManifest g = WriteFrames(3);
  auto f = LoadStackFrameImage(dir_, g, 1);
  ASSERT_TRUE(f.ok());
  EXPECT_FALSE(f->is_colour());
  EXPECT_EQ(f->grey.type(), CV_8UC1);
  EXPECT_EQ(f->grey.at<uint8_t>(0, 0), 10);
}

TEST_F(StackTest, MixedGreyAndColourNamesTheFrame) {
  StackManifest m = WriteFrames(4);
  ASSERT_TRUE(ValidateStackFrames(dir_, m).ok());
  cv::imwrite((dir_ / m.frames[2].file).string(), cv::Mat(cv::Size(32, 24), CV_8UC3, cv::Scalar(1, 2, 3)));
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("frame 2 (frame_2.png): colour (3 channels) differs from frame 0 (grey)"),
            std::string::npos)
      << s.message();
}

TEST_F(StackTest, MixedColourBitDepthsNameTheFrame) {
  StackManifest m;
  m.pixel_size_um = 1.0;
  for (int i = 0; i < 3; ++i) {
    const std::string name = "f" + std::to_string(i) + (i == 1 ? ".tiff" : ".png");
    if (i == 1)
      cv::imwrite((dir_ / name).string(), cv::Mat(5, 5, CV_16UC3, cv::Scalar(1, 2, 3)));
    else
      cv::imwrite((dir_ / name).string(), cv::Mat(5, 5, CV_8UC3, cv::Scalar(1, 2, 3)));
    m.frames.push_back({name, double(i), 0.0, ""});
  }
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("frame 1 (f1.tiff): bit depth 16 differs from frame 0 (8)"), std::string::npos)
      << s.message();
}

TEST_F(StackTest, FourChannelFrameNamesTheFrame) {
  StackManifest m = WriteFrames(3);
  cv::imwrite((dir_ / m.frames[1].file).string(), cv::Mat(cv::Size(32, 24), CV_8UC4, cv::Scalar(1, 2, 3, 255)));
  Status s = ValidateStackFrames(dir_, m);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("frame 1 (frame_1.png): has 4 channels"), std::string::npos) << s.message();
  EXPECT_EQ(LoadStackFrameImage(dir_, m, 1).status().code(), StatusCode::kInvalidArgument);
}

// A colour stack reconstructs to the same depth map as the grey stack of its luminance.
TEST_F(StackTest, ColourStackReconstructsLikeItsLuminance) {
  const cv::Size size(40, 32);
  const auto synthetic = testing::TiltedPlaneStack(size, testing::UniformZ(12, 0.0, 2.0), 6.0, 0.3, 0.1);
  StackManifest colour, grey;
  colour.pixel_size_um = grey.pixel_size_um = 1.0;
  for (size_t k = 0; k < synthetic.frames.size(); ++k) {
    // A colour frame whose channels differ (so the weights matter) and its luminance.
    cv::Mat c;
    cv::Mat chans[3] = {255 - synthetic.frames[k], synthetic.frames[k], synthetic.frames[k] / 2};
    cv::merge(chans, 3, c);
    const std::string cname = "c" + std::to_string(k) + ".png", gname = "g" + std::to_string(k) + ".png";
    cv::imwrite((dir_ / cname).string(), c);
    cv::imwrite((dir_ / gname).string(), LuminanceOf(c).value());
    colour.frames.push_back({cname, synthetic.z_um[k], 0.0, ""});
    grey.frames.push_back({gname, synthetic.z_um[k], 0.0, ""});
  }
  ASSERT_TRUE(ValidateStackFrames(dir_, colour).ok());
  const fs::path cdir = dir_ / "colour", gdir = dir_ / "grey";
  fs::create_directories(cdir);
  fs::create_directories(gdir);
  for (size_t k = 0; k < colour.frames.size(); ++k) {
    fs::rename(dir_ / colour.frames[k].file, cdir / colour.frames[k].file);
    fs::rename(dir_ / grey.frames[k].file, gdir / grey.frames[k].file);
  }
  ASSERT_TRUE(WriteStackManifest(cdir, colour).ok());
  ASSERT_TRUE(WriteStackManifest(gdir, grey).ok());
  const std::atomic<bool> no_cancel{false};
  auto reconstruct = [&](const fs::path& d) -> StatusOr<DepthResult> {
    auto manifest = ReadStackManifest(d);
    if (!manifest.ok()) return manifest.status();
    return ReconstructStackFolder(d, *manifest, SffOptions{}, nullptr, no_cancel);
  };
  auto rc = reconstruct(cdir);
  auto rg = reconstruct(gdir);
  ASSERT_TRUE(rc.ok()) << rc.status().ToString();
  ASSERT_TRUE(rg.ok()) << rg.status().ToString();
  EXPECT_GT(rc->valid_fraction, 0.9);
  ASSERT_EQ(rc->depth_um.size(), rg->depth_um.size());
  EXPECT_EQ(std::memcmp(rc->depth_um.data, rg->depth_um.data, rc->depth_um.total() * sizeof(float)), 0);
  // The all-in-focus image keeps the colour; its luminance is the grey stack's all-in-focus.
  ASSERT_EQ(rc->all_in_focus.type(), CV_8UC3);
  EXPECT_EQ(cv::norm(LuminanceOf(rc->all_in_focus).value(), rg->all_in_focus, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace inspection
