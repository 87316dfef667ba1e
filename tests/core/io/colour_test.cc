// Colour frames: BT.709 luminance in fixed point against the double formula, and the streaming
// colour all-in-focus composer against the SFF engine's own choice of frame.
#include "core/io/colour.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/sff/all_in_focus.h"
#include "core/sff/sff_engine.h"
#include "tests/core/sff_synthetic.h"

namespace inspection {
namespace {

double Bt709(double b, double g, double r) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }

TEST(ColourTest, LuminanceOfPrimariesAndGrey8Bit) {
  cv::Mat bgr(1, 5, CV_8UC3);
  bgr.at<cv::Vec3b>(0, 0) = {0, 0, 255};      // red: 0.2126 * 255 = 54.2
  bgr.at<cv::Vec3b>(0, 1) = {0, 255, 0};      // green: 182.4
  bgr.at<cv::Vec3b>(0, 2) = {255, 0, 0};      // blue: 18.4
  bgr.at<cv::Vec3b>(0, 3) = {77, 77, 77};     // grey maps to itself
  bgr.at<cv::Vec3b>(0, 4) = {255, 255, 255};  // and never overflows
  auto y = LuminanceOf(bgr);
  ASSERT_TRUE(y.ok()) << y.status().ToString();
  ASSERT_EQ(y->type(), CV_8UC1);
  EXPECT_EQ(y->at<uint8_t>(0, 0), 54);
  EXPECT_EQ(y->at<uint8_t>(0, 1), 182);
  EXPECT_EQ(y->at<uint8_t>(0, 2), 18);
  EXPECT_EQ(y->at<uint8_t>(0, 3), 77);
  EXPECT_EQ(y->at<uint8_t>(0, 4), 255);
}

TEST(ColourTest, LuminanceMatchesTheFormulaFor8And16Bit) {
  std::mt19937 rng(3);
  cv::Mat c8(17, 23, CV_8UC3), c16(17, 23, CV_16UC3);
  for (int y = 0; y < c8.rows; ++y)
    for (int x = 0; x < c8.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        c8.at<cv::Vec3b>(y, x)[c] = uint8_t(rng() % 256);
        c16.at<cv::Vec3w>(y, x)[c] = uint16_t(rng() % 65536);
      }
  auto y8 = LuminanceOf(c8);
  auto y16 = LuminanceOf(c16);
  ASSERT_TRUE(y8.ok() && y16.ok());
  ASSERT_EQ(y16->type(), CV_16UC1);
  for (int y = 0; y < c8.rows; ++y)
    for (int x = 0; x < c8.cols; ++x) {
      const cv::Vec3b p = c8.at<cv::Vec3b>(y, x);
      EXPECT_LE(std::abs(y8->at<uint8_t>(y, x) - Bt709(p[0], p[1], p[2])), 0.51) << x << "," << y;
      const cv::Vec3w q = c16.at<cv::Vec3w>(y, x);
      // Fixed-point weights differ from the exact ones by < 0.3 / 65536: < 0.7 code values at 16 bit.
      EXPECT_LE(std::abs(y16->at<uint16_t>(y, x) - Bt709(q[0], q[1], q[2])), 1.2) << x << "," << y;
    }
  // Grey frames are returned as they are, sharing the pixels.
  cv::Mat g(4, 4, CV_16UC1, cv::Scalar(1234));
  auto same = LuminanceOf(g);
  ASSERT_TRUE(same.ok());
  EXPECT_EQ(same->data, g.data);
  EXPECT_EQ(LuminanceOf(cv::Mat(4, 4, CV_8UC4)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(LuminanceOf(cv::Mat(4, 4, CV_32FC3)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(LuminanceOf(cv::Mat()).status().code(), StatusCode::kInvalidArgument);
}

// A colour stack whose frames have the synthetic grey frames as luminance plus a per-frame hue
// (a tint that shifts from frame to frame), so the colour tells which frame a pixel came from.
struct ColourStack {
  std::vector<cv::Mat> colour, grey;
  std::vector<double> z_um;
};

ColourStack TintedStack(const testing::SyntheticStack& s) {
  ColourStack out;
  out.z_um = s.z_um;
  for (size_t k = 0; k < s.frames.size(); ++k) {
    cv::Mat c(s.frames[k].size(), CV_8UC3);
    for (int y = 0; y < c.rows; ++y)
      for (int x = 0; x < c.cols; ++x) {
        const int v = s.frames[k].at<uint8_t>(y, x);
        // Blue carries the frame index; green compensates so the luminance stays close to v.
        const int b = int(k) * 9 % 250;
        const int r = v;
        const int g = std::clamp(int(std::lround((v - 0.2126 * r - 0.0722 * b) / 0.7152)), 0, 255);
        c.at<cv::Vec3b>(y, x) = {uint8_t(b), uint8_t(g), uint8_t(r)};
      }
    out.colour.push_back(c);
    out.grey.push_back(LuminanceOf(c).value());
  }
  return out;
}

TEST(AllInFocusTest, FocusScoreReproducesTheEnginesChoiceInColour) {
  const cv::Size size(48, 40);
  std::vector<double> z;
  for (int k = 0; k < 15; ++k) z.push_back(2.0 * k);
  const auto synthetic = testing::TiltedPlaneStack(size, z, 8.0, 0.25, 0.1);
  const ColourStack cs = TintedStack(synthetic);

  for (FocusMeasure fm : {FocusMeasure::kTenengrad, FocusMeasure::kSumModifiedLaplacian}) {
    SffOptions o;
    o.focus_measure = fm;
    auto engine = SffEngine::Create(o, size, CV_8UC1);
    ASSERT_TRUE(engine.ok());
    auto composer = AllInFocusComposer::Create(size, CV_8UC3);
    ASSERT_TRUE(composer.ok());
    for (size_t k = 0; k < cs.colour.size(); ++k) {
      ASSERT_TRUE((*engine)->PushFrame(cs.grey[k], z[k]).ok());
      cv::Mat score;
      ASSERT_TRUE(FocusScore(cs.grey[k], fm, o.window_px, &score).ok());
      ASSERT_TRUE(composer->PushFrame(cs.colour[k], score).ok());
    }
    auto r = (*engine)->Finish();
    ASSERT_TRUE(r.ok());
    // The composed colour image's luminance is the engine's grey all-in-focus image, pixel for
    // pixel: the same frame was chosen everywhere.
    const cv::Mat lum = LuminanceOf(composer->all_in_focus()).value();
    EXPECT_EQ(cv::norm(lum, r->all_in_focus, cv::NORM_INF), 0.0) << FocusMeasureName(fm);
    // And the colour is that of the chosen frame (blue channel = tint of the frame index), which
    // for a tilted plane follows the height: frame index ~ (8 + 0.25 x + 0.1 y) / 2.
    const cv::Mat& idx = composer->frame_index();
    int near = 0;
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const int k = idx.at<int32_t>(y, x);
        EXPECT_EQ(composer->all_in_focus().at<cv::Vec3b>(y, x), cs.colour[k].at<cv::Vec3b>(y, x));
        near += std::abs(k - (8.0 + 0.25 * x + 0.1 * y) / 2.0) <= 1.0;
      }
    EXPECT_GT(near, 0.95 * size.area()) << FocusMeasureName(fm);
  }
}

TEST(AllInFocusTest, DepthProximityTakesTheNearestFrame16Bit) {
  // Three 16-bit colour frames at z = 0, 10, 20; depth 9 -> frame 1, 16 -> frame 2, NaN -> frame 0.
  const cv::Size size(3, 1);
  cv::Mat depth(size, CV_32F);
  depth.at<float>(0, 0) = 9.f;
  depth.at<float>(0, 1) = 16.f;
  depth.at<float>(0, 2) = std::nanf("");
  auto c = AllInFocusComposer::Create(size, CV_16UC3);
  ASSERT_TRUE(c.ok());
  for (int k = 0; k < 3; ++k) {
    cv::Mat score;
    ASSERT_TRUE(DepthProximityScore(depth, 10.0 * k, &score).ok());
    ASSERT_TRUE(c->PushFrame(cv::Mat(size, CV_16UC3, cv::Scalar(1000 * k, 40000, 7)), score).ok());
  }
  EXPECT_EQ(c->all_in_focus().at<cv::Vec3w>(0, 0)[0], 1000);
  EXPECT_EQ(c->all_in_focus().at<cv::Vec3w>(0, 1)[0], 2000);
  EXPECT_EQ(c->all_in_focus().at<cv::Vec3w>(0, 2)[0], 0);
  EXPECT_EQ(c->frame_index().at<int32_t>(0, 1), 2);
  EXPECT_EQ(c->state_bytes(), 3u * (4 + 4 + 6));
}

TEST(AllInFocusTest, FirstOfEqualMaximaWinsAndMismatchesAreNamed) {
  auto c = AllInFocusComposer::Create({2, 2}, CV_8UC1);
  ASSERT_TRUE(c.ok());
  const cv::Mat flat(2, 2, CV_32F, cv::Scalar(5.f));
  ASSERT_TRUE(c->PushFrame(cv::Mat(2, 2, CV_8UC1, cv::Scalar(1)), flat).ok());
  ASSERT_TRUE(c->PushFrame(cv::Mat(2, 2, CV_8UC1, cv::Scalar(2)), flat).ok());
  EXPECT_EQ(c->all_in_focus().at<uint8_t>(1, 1), 1);
  Status st = c->PushFrame(cv::Mat(2, 2, CV_8UC3), flat);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("frame 2"), std::string::npos) << st.message();
  st = c->PushFrame(cv::Mat(2, 2, CV_8UC1), cv::Mat(2, 2, CV_32SC1, cv::Scalar(9)));
  EXPECT_NE(st.message().find("score type"), std::string::npos) << st.message();
  st = c->PushFrame(cv::Mat(3, 2, CV_8UC1), cv::Mat(3, 2, CV_32F));
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(AllInFocusComposer::Create({2, 2}, CV_32FC3).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(c->frames_pushed(), 2);

  // A NaN score never wins, also on the first frame: the next finite score takes the pixel.
  auto n = AllInFocusComposer::Create({1, 1}, CV_8UC1);
  ASSERT_TRUE(n.ok());
  ASSERT_TRUE(
      n->PushFrame(cv::Mat(1, 1, CV_8UC1, cv::Scalar(1)), cv::Mat(1, 1, CV_32F, cv::Scalar(std::nan("")))).ok());
  ASSERT_TRUE(n->PushFrame(cv::Mat(1, 1, CV_8UC1, cv::Scalar(2)), cv::Mat(1, 1, CV_32F, cv::Scalar(-3.f))).ok());
  EXPECT_EQ(n->all_in_focus().at<uint8_t>(0, 0), 2);
}

}  // namespace
}  // namespace inspection
